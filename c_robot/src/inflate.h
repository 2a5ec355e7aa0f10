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
/* the same, its bytes read span after span where they are (a PNG's IDAT chunks, never
   copied together): next gives the next span (1), or says there is none (0) */
typedef int (*NextSpan)(void *ctx, const uint8_t **data, size_t *size);
long inflate_zlib_spans(NextSpan next, void *ctx, uint8_t *out, size_t out_cap);
#endif
