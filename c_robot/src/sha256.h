#ifndef CR_SHA256_H
#define CR_SHA256_H
#include <stddef.h>
#include <stdint.h>

typedef struct {
    uint32_t h[8];
    uint64_t length; /* bytes taken in */
    uint8_t block[64];
    size_t used;
} Sha256;

void sha256_init(Sha256 *ctx);
void sha256_update(Sha256 *ctx, const void *data, size_t size);
void sha256_final(Sha256 *ctx, uint8_t digest[32]);
void sha256(const void *data, size_t size, uint8_t digest[32]);

/* HMAC-SHA256, in pieces: init with the key, update, final. */
typedef struct {
    Sha256 inner;
    Sha256 outer;
} HmacSha256;

void hmac_init(HmacSha256 *ctx, const uint8_t *key, size_t key_size);
void hmac_update(HmacSha256 *ctx, const void *data, size_t size);
void hmac_final(HmacSha256 *ctx, uint8_t mac[32]);
void hmac_sha256(const uint8_t *key, size_t key_size, const void *data, size_t size,
                 uint8_t mac[32]);
/* Constant-time comparison: 1 when equal. */
int equal_ct(const uint8_t *a, const uint8_t *b, size_t size);
#endif
