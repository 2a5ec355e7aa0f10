/* ChaCha20-Poly1305 (RFC 8439). */
#ifndef CR_AEAD_H
#define CR_AEAD_H
#include <stddef.h>
#include <stdint.h>

/* out gets the ciphertext (size bytes) then the 16-byte tag. */
void aead_seal(const uint8_t key[32], const uint8_t nonce[12], const uint8_t *ad, size_t ad_size,
               const uint8_t *plain, size_t size, uint8_t *out);
/* in: ciphertext and tag (size = ciphertext bytes + 16); plain gets size - 16 bytes.
   Returns 0 when the tag checks out, -1 otherwise (plain is then undefined). */
int aead_open(const uint8_t key[32], const uint8_t nonce[12], const uint8_t *ad, size_t ad_size,
              const uint8_t *in, size_t size, uint8_t *plain);
#endif
