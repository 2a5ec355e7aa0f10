#include "inflate.h"

#include <string.h>

/* The compressed bytes, span after span (a PNG's IDAT chunks, read where they are). */
typedef struct {
    const uint8_t *in;
    size_t size, pos; /* the span being read */
    NextSpan next;
    void *ctx;
    uint32_t bits;
    int count;
    int error;
} Bits;

/* the next byte, or 0 and error set at the end */
static uint8_t byte(Bits *b) {
    while (b->pos >= b->size) {
        if (b->next == NULL || !b->next(b->ctx, &b->in, &b->size)) {
            b->error = 1;
            return 0;
        }
        b->pos = 0;
    }
    return b->in[b->pos++];
}

static int need(Bits *b, int n) {
    while (b->count < n) {
        uint8_t next = byte(b);
        if (b->error) return 0;
        b->bits |= (uint32_t)next << b->count;
        b->count += 8;
    }
    return 1;
}

static uint32_t take(Bits *b, int n) {
    if (n == 0) return 0;
    if (!need(b, n)) return 0;
    uint32_t v = b->bits & ((1u << n) - 1);
    b->bits >>= n;
    b->count -= n;
    return v;
}

/* Canonical Huffman code: counts per length and symbols in code order (puff's way). */
typedef struct {
    uint16_t count[16];
    uint16_t symbol[320];
} Huffman;

static int build(Huffman *h, const uint8_t *lengths, int n) {
    memset(h->count, 0, sizeof h->count);
    for (int i = 0; i < n; i++) h->count[lengths[i]]++;
    if (h->count[0] == n) return 0; /* no codes: usable only if never read */
    int left = 1;
    for (int len = 1; len < 16; len++) {
        left <<= 1;
        left -= h->count[len];
        if (left < 0) return -1; /* over-subscribed */
    }
    uint16_t offs[16];
    offs[1] = 0;
    for (int len = 1; len < 15; len++) offs[len + 1] = (uint16_t)(offs[len] + h->count[len]);
    for (int i = 0; i < n; i++)
        if (lengths[i]) h->symbol[offs[lengths[i]]++] = (uint16_t)i;
    return left; /* > 0: incomplete */
}

static int decode(Bits *b, const Huffman *h) {
    int code = 0, first = 0, index = 0;
    for (int len = 1; len < 16; len++) {
        code |= (int)take(b, 1);
        if (b->error) return -1;
        int count = h->count[len];
        if (code - count < first) return h->symbol[index + (code - first)];
        index += count;
        first += count;
        first <<= 1;
        code <<= 1;
    }
    return -1;
}

static const uint16_t len_base[29] = {3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 15, 17, 19, 23, 27, 31,
                                      35, 43, 51, 59, 67, 83, 99, 115, 131, 163, 195, 227, 258};
static const uint8_t len_extra[29] = {0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2,
                                      3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0};
static const uint16_t dist_base[30] = {1, 2, 3, 4, 5, 7, 9, 13, 17, 25, 33, 49, 65, 97, 129,
                                       193, 257, 385, 513, 769, 1025, 1537, 2049, 3073, 4097,
                                       6145, 8193, 12289, 16385, 24577};
static const uint8_t dist_extra[30] = {0, 0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6,
                                       6, 7, 7, 8, 8, 9, 9, 10, 10, 11, 11, 12, 12, 13, 13};

static int codes(Bits *b, const Huffman *lencode, const Huffman *distcode, uint8_t *out,
                 size_t cap, size_t *o) {
    for (;;) {
        int symbol = decode(b, lencode);
        if (symbol < 0) return -1;
        if (symbol < 256) {
            if (*o >= cap) return -1;
            out[(*o)++] = (uint8_t)symbol;
        } else if (symbol == 256) {
            return 0;
        } else {
            symbol -= 257;
            if (symbol >= 29) return -1;
            size_t length = len_base[symbol] + take(b, len_extra[symbol]);
            int d = decode(b, distcode);
            if (d < 0 || d >= 30) return -1;
            size_t dist = dist_base[d] + take(b, dist_extra[d]);
            if (b->error) return -1;
            if (dist > *o) return -1;
            if (*o + length > cap) return -1;
            for (size_t i = 0; i < length; i++, (*o)++) out[*o] = out[*o - dist];
        }
    }
}

static int fixed(Bits *b, uint8_t *out, size_t cap, size_t *o) {
    static Huffman lencode, distcode;
    static int ready;
    if (!ready) {
        uint8_t lengths[288];
        int i = 0;
        for (; i < 144; i++) lengths[i] = 8;
        for (; i < 256; i++) lengths[i] = 9;
        for (; i < 280; i++) lengths[i] = 7;
        for (; i < 288; i++) lengths[i] = 8;
        build(&lencode, lengths, 288);
        for (i = 0; i < 30; i++) lengths[i] = 5;
        build(&distcode, lengths, 30);
        ready = 1;
    }
    return codes(b, &lencode, &distcode, out, cap, o);
}

static int dynamic(Bits *b, uint8_t *out, size_t cap, size_t *o) {
    static const uint8_t order[19] = {16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15};
    uint8_t lengths[320];
    Huffman lencode, distcode;
    int nlen = (int)take(b, 5) + 257;
    int ndist = (int)take(b, 5) + 1;
    int ncode = (int)take(b, 4) + 4;
    if (b->error || nlen > 286 || ndist > 30) return -1;
    int index;
    for (index = 0; index < ncode; index++) lengths[order[index]] = (uint8_t)take(b, 3);
    for (; index < 19; index++) lengths[order[index]] = 0;
    if (b->error) return -1;
    if (build(&lencode, lengths, 19) != 0) return -1; /* must be complete */
    index = 0;
    while (index < nlen + ndist) {
        int symbol = decode(b, &lencode);
        if (symbol < 0) return -1;
        if (symbol < 16) {
            lengths[index++] = (uint8_t)symbol;
        } else {
            uint8_t len = 0;
            int repeat;
            if (symbol == 16) {
                if (index == 0) return -1;
                len = lengths[index - 1];
                repeat = 3 + (int)take(b, 2);
            } else if (symbol == 17) {
                repeat = 3 + (int)take(b, 3);
            } else {
                repeat = 11 + (int)take(b, 7);
            }
            if (b->error || index + repeat > nlen + ndist) return -1;
            while (repeat--) lengths[index++] = len;
        }
    }
    if (lengths[256] == 0) return -1;
    int err = build(&lencode, lengths, nlen);
    if (err < 0 || (err > 0 && nlen - lencode.count[0] != 1)) return -1;
    err = build(&distcode, lengths + nlen, ndist);
    if (err < 0 || (err > 0 && ndist - distcode.count[0] != 1)) return -1;
    return codes(b, &lencode, &distcode, out, cap, o);
}

/* the DEFLATE blocks: the bytes written, or -1; then b is at a byte boundary (the rest of
   the last byte is padding) */
static long blocks(Bits *b, uint8_t *out, size_t out_cap) {
    size_t o = 0;
    int last;
    do {
        last = (int)take(b, 1);
        int type = (int)take(b, 2);
        if (b->error) return -1;
        int err;
        if (type == 0) {
            b->bits = 0; /* to a byte boundary */
            b->count = 0;
            uint8_t head[4];
            for (int i = 0; i < 4; i++) head[i] = byte(b);
            if (b->error) return -1;
            unsigned len = head[0] | (unsigned)head[1] << 8;
            unsigned nlen = head[2] | (unsigned)head[3] << 8;
            if (len != (~nlen & 0xFFFF)) return -1;
            if (o + len > out_cap) return -1;
            for (unsigned i = 0; i < len; i++) out[o++] = byte(b);
            if (b->error) return -1;
            err = 0;
        } else if (type == 1) {
            err = fixed(b, out, out_cap, &o);
        } else if (type == 2) {
            err = dynamic(b, out, out_cap, &o);
        } else {
            return -1;
        }
        if (err) return -1;
    } while (!last);
    b->bits = 0;
    b->count = 0;
    return (long)o;
}

long inflate_raw(const uint8_t *in, size_t in_size, uint8_t *out, size_t out_cap,
                 size_t *consumed) {
    Bits b = {in, in_size, 0, NULL, NULL, 0, 0, 0};
    long n = blocks(&b, out, out_cap);
    if (n >= 0 && consumed) *consumed = b.pos;
    return n;
}

long inflate_zlib_spans(NextSpan next, void *ctx, uint8_t *out, size_t out_cap) {
    Bits b = {NULL, 0, 0, next, ctx, 0, 0, 0};
    uint8_t cmf = byte(&b), flg = byte(&b);
    if (b.error) return -1;
    if ((cmf & 0x0F) != 8 || (cmf >> 4) > 7) return -1;
    if (((unsigned)cmf << 8 | flg) % 31 != 0) return -1;
    if (flg & 0x20) return -1; /* a preset dictionary */
    long n = blocks(&b, out, out_cap);
    if (n < 0) return -1;
    uint32_t want = 0;
    for (int i = 0; i < 4; i++) want = want << 8 | byte(&b);
    if (b.error) return -1;
    uint32_t a = 1, b2 = 0;
    for (long i = 0; i < n; i++) {
        a = (a + out[i]) % 65521;
        b2 = (b2 + a) % 65521;
    }
    if ((b2 << 16 | a) != want) return -1;
    return n;
}

typedef struct {
    const uint8_t *in;
    size_t size;
    int given;
} OneSpan;

static int one_span(void *ctx, const uint8_t **data, size_t *size) {
    OneSpan *span = ctx;
    if (span->given) return 0;
    span->given = 1;
    *data = span->in;
    *size = span->size;
    return 1;
}

long inflate_zlib(const uint8_t *in, size_t in_size, uint8_t *out, size_t out_cap) {
    if (in_size < 6) return -1;
    OneSpan span = {in, in_size, 0};
    return inflate_zlib_spans(one_span, &span, out, out_cap);
}
