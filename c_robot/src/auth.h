/* Run keys (docs/protocol.md "Authentication"; bestofn_swarm/wire/auth.py). */
#ifndef CR_AUTH_H
#define CR_AUTH_H
#include <stddef.h>
#include <stdint.h>

#define AUTH_TAG_BYTES 16
#define AUTH_NONCE_BYTES 16

void auth_derive_key(const uint8_t secret[32], const char *identity, uint8_t key[32]);
/* the 16-byte tag of (key expression, metadata, payload) */
void auth_tag(const uint8_t key[32], const char *key_expr, const uint8_t *metadata,
              size_t metadata_size, const uint8_t *payload, size_t payload_size,
              uint8_t tag[16]);
/* the attachment tag ‖ metadata into out (cap bytes); its size, or -1 */
long auth_seal(const uint8_t key[32], const char *key_expr, const uint8_t *payload,
               size_t payload_size, const uint8_t *metadata, size_t metadata_size,
               uint8_t *out, size_t cap);
/* checks the attachment's tag; the metadata (after the tag) via *metadata; 0 or -1 */
int auth_open(const uint8_t key[32], const char *key_expr, const uint8_t *payload,
              size_t payload_size, const uint8_t *attachment, size_t attachment_size,
              const uint8_t **metadata, size_t *metadata_size);
/* is_identity of bestofn_swarm/wire/names.py */
int is_identity(const char *text, size_t len);
#endif
