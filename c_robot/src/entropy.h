/* Random bytes for the link's nonces (8-byte session nonces, 16-byte query nonces), from
   the platform's source of entropy. They must never repeat: the bridge refuses a hello
   nonce it has seen, and a repeated query nonce would let an old answer pass. So there is
   no fallback: a platform without a source, or a source that fails, is an error the robot
   stops on (docs/porting.md, "On a microcontroller"). */
#ifndef CR_ENTROPY_H
#define CR_ENTROPY_H
#include <stddef.h>
#include <stdint.h>

/* 0 and size random bytes in out, or -1 (no source, or it failed) */
int entropy_bytes(uint8_t *out, size_t size);
#endif
