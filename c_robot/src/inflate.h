/* inflate (RFC 1951) and the zlib wrapper (RFC 1950), into a caller's buffer. */
#ifndef CR_INFLATE_H
#define CR_INFLATE_H
#include <stddef.h>
#include <stdint.h>

/* raw DEFLATE: returns the bytes written, or -1 (corrupt, truncated or too long) */
long inflate_raw(const uint8_t *in, size_t in_size, uint8_t *out, size_t out_cap,
                 size_t *consumed);
/* zlib stream: header, DEFLATE data and the Adler-32 checked */
long inflate_zlib(const uint8_t *in, size_t in_size, uint8_t *out, size_t out_cap);
#endif
