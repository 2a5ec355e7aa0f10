#include "link.h"

#include <string.h>

#include "aead.h"
#include "sha256.h"

const char *const refusal_names[R_COUNT] = {"",        "malformed", "oversize",   "corrupt",
                                            "forged",  "replayed",  "unexpected", "rate"};

void link_key(const uint8_t robot_key[32], uint8_t out[32]) {
    hmac_sha256(robot_key, 32, "bestofn-link", 12, out);
}

void session_key(const uint8_t key[32], const uint8_t robot_nonce[8],
                 const uint8_t bridge_nonce[8], uint8_t out[32]) {
    uint8_t data[20 + 16];
    memcpy(data, "bestofn-link-session", 20);
    memcpy(data + 20, robot_nonce, 8);
    memcpy(data + 28, bridge_nonce, 8);
    hmac_sha256(key, 32, data, sizeof data, out);
}

static void put_u32(uint8_t *p, uint32_t v) {
    p[0] = (uint8_t)(v >> 24); p[1] = (uint8_t)(v >> 16); p[2] = (uint8_t)(v >> 8); p[3] = (uint8_t)v;
}

static void put_u64(uint8_t *p, uint64_t v) {
    for (int i = 0; i < 8; i++) p[i] = (uint8_t)(v >> (56 - 8 * i));
}

static uint64_t get_u64(const uint8_t *p) {
    uint64_t v = 0;
    for (int i = 0; i < 8; i++) v = v << 8 | p[i];
    return v;
}

static void header_bytes(const Frame *f, uint8_t h[33]) {
    h[0] = 'B'; h[1] = 'L'; h[2] = 1; h[3] = (uint8_t)f->type;
    h[4] = (uint8_t)((f->from_bridge ? 1 : 0) | (f->encrypted ? 2 : 0));
    put_u32(h + 5, f->robot);
    memcpy(h + 9, f->robot_nonce, 8);
    memcpy(h + 17, f->bridge_nonce, 8);
    put_u64(h + 25, f->seq);
}

static void cipher_nonce(int from_bridge, uint64_t seq, uint8_t nonce[12]) {
    put_u32(nonce, from_bridge ? 1u : 0u);
    put_u64(nonce + 4, seq);
}

long link_seal(const Frame *f, const uint8_t key[32], const uint8_t *cipher_key, uint8_t *out,
               size_t cap) {
    if (f->body_size > LINK_MAX_BODY_BYTES) return -R_OVERSIZE;
    size_t total = LINK_HEADER_BYTES + f->body_size + LINK_TAG_BYTES;
    if (total > cap) return -R_OVERSIZE;
    header_bytes(f, out);
    if (f->encrypted) {
        uint8_t nonce[12];
        cipher_nonce(f->from_bridge, f->seq, nonce);
        aead_seal(cipher_key, nonce, out, LINK_HEADER_BYTES, f->body, f->body_size,
                  out + LINK_HEADER_BYTES);
    } else {
        if (f->body_size) memmove(out + LINK_HEADER_BYTES, f->body, f->body_size);
        uint8_t mac[32];
        hmac_sha256(key, 32, out, LINK_HEADER_BYTES + f->body_size, mac);
        memcpy(out + LINK_HEADER_BYTES + f->body_size, mac, LINK_TAG_BYTES);
    }
    return (long)total;
}

int link_read_header(const uint8_t *data, size_t size, Frame *f) {
    if (size > LINK_MAX_FRAME_BYTES) return R_OVERSIZE;
    if (size < LINK_MIN_FRAME_BYTES) return R_MALFORMED;
    if (data[0] != 'B' || data[1] != 'L') return R_MALFORMED;
    if (data[2] != 1) return R_MALFORMED;
    if (data[3] < 1 || data[3] > 6) return R_MALFORMED;
    if (data[4] & ~3) return R_MALFORMED;
    uint32_t robot = (uint32_t)data[5] << 24 | (uint32_t)data[6] << 16 | (uint32_t)data[7] << 8 | data[8];
    if (robot >= 100000) return R_MALFORMED;
    f->type = data[3];
    f->from_bridge = data[4] & 1;
    f->encrypted = (data[4] & 2) != 0;
    f->robot = robot;
    memcpy(f->robot_nonce, data + 9, 8);
    memcpy(f->bridge_nonce, data + 17, 8);
    f->seq = get_u64(data + 25);
    f->body = NULL;
    f->body_size = 0;
    return R_NONE;
}

int link_open(const uint8_t *data, size_t size, const uint8_t key[32],
              const uint8_t *cipher_key, uint8_t *plain, Frame *f) {
    int refusal = link_read_header(data, size, f);
    if (refusal) return refusal;
    if (f->encrypted) {
        if (cipher_key == NULL) return R_UNEXPECTED;
        uint8_t nonce[12];
        cipher_nonce(f->from_bridge, f->seq, nonce);
        size_t n = size - LINK_HEADER_BYTES;
        if (aead_open(cipher_key, nonce, data, LINK_HEADER_BYTES, data + LINK_HEADER_BYTES, n,
                      plain) != 0)
            return R_FORGED;
        f->body = plain;
        f->body_size = n - LINK_TAG_BYTES;
    } else {
        uint8_t mac[32];
        hmac_sha256(key, 32, data, size - LINK_TAG_BYTES, mac);
        if (!equal_ct(mac, data + size - LINK_TAG_BYTES, LINK_TAG_BYTES)) return R_FORGED;
        f->body = data + LINK_HEADER_BYTES;
        f->body_size = size - LINK_HEADER_BYTES - LINK_TAG_BYTES;
    }
    return R_NONE;
}

static int zero_nonce(const uint8_t n[8]) {
    for (int i = 0; i < 8; i++)
        if (n[i]) return 0;
    return 1;
}

int link_check_body(const Frame *f) {
    if (f->type == F_HELLO && (f->body_size || f->seq || !zero_nonce(f->bridge_nonce)))
        return R_MALFORMED;
    if (f->type == F_WELCOME && f->seq) return R_MALFORMED;
    if ((f->type == F_PING || f->type == F_PONG) && f->body_size != LINK_PING_BODY_BYTES)
        return R_MALFORMED;
    if (f->type == F_BYE && (f->body_size != 1 || f->body[0] < 1 || f->body[0] > 3))
        return R_MALFORMED;
    if ((f->type == F_DATA || f->type == F_PING || f->type == F_PONG || f->type == F_BYE) && !f->seq)
        return R_MALFORMED;
    if ((f->type == F_HELLO && f->from_bridge) || (f->type == F_WELCOME && !f->from_bridge))
        return R_UNEXPECTED;
    return R_NONE;
}


long link_encode_data(int kind, const uint8_t *payload, size_t payload_size,
                      const uint8_t *attachment, size_t attachment_size, uint8_t *out,
                      size_t cap) {
    if (attachment_size > LINK_MAX_ATTACHMENT_BYTES) return -R_OVERSIZE;
    size_t total = 3 + attachment_size + payload_size;
    if (total > LINK_MAX_BODY_BYTES || total > cap) return -R_OVERSIZE;
    out[0] = (uint8_t)kind;
    out[1] = (uint8_t)(attachment_size >> 8);
    out[2] = (uint8_t)attachment_size;
    if (attachment_size) memcpy(out + 3, attachment, attachment_size);
    if (payload_size) memcpy(out + 3 + attachment_size, payload, payload_size);
    return (long)total;
}

int link_decode_data(const uint8_t *body, size_t size, int *kind, const uint8_t **payload,
                     size_t *payload_size, const uint8_t **attachment,
                     size_t *attachment_size) {
    if (size < 3) return R_MALFORMED;
    if (!kind_known(body[0])) return R_MALFORMED;
    size_t length = (size_t)body[1] << 8 | body[2];
    if (length > LINK_MAX_ATTACHMENT_BYTES) return R_MALFORMED;
    if (size < 3 + length) return R_MALFORMED;
    *kind = body[0];
    *attachment = length ? body + 3 : NULL;
    *attachment_size = length;
    *payload = body + 3 + length;
    *payload_size = size - 3 - length;
    return R_NONE;
}

int replay_refuses(const ReplayWindow *w, uint64_t seq) {
    if (seq > w->highest) return 0;
    uint64_t behind = w->highest - seq;
    if (behind >= LINK_REPLAY_WINDOW) return 1;
    if (w->seen >> behind & 1) return 1;
    return 0;
}

void replay_take(ReplayWindow *w, uint64_t seq) {
    if (seq > w->highest) {
        uint64_t shift = seq - w->highest;
        w->seen = shift >= 64 ? 1 : (w->seen << shift) | 1;
        w->highest = seq;
    } else {
        w->seen |= (uint64_t)1 << (w->highest - seq);
    }
}

static uint32_t crc_table[256];
static int crc_ready;

uint32_t crc32_of(const uint8_t *data, size_t size) {
    if (!crc_ready) {
        for (uint32_t i = 0; i < 256; i++) {
            uint32_t c = i;
            for (int k = 0; k < 8; k++) c = c & 1 ? 0xEDB88320u ^ (c >> 1) : c >> 1;
            crc_table[i] = c;
        }
        crc_ready = 1;
    }
    uint32_t c = 0xFFFFFFFFu;
    for (size_t i = 0; i < size; i++) c = crc_table[(c ^ data[i]) & 0xFF] ^ (c >> 8);
    return c ^ 0xFFFFFFFFu;
}

/* COBS of frame then its 4 CRC bytes, then a zero. */
long serial_encode(const uint8_t *frame, size_t size, uint8_t *out, size_t cap) {
    uint32_t crc = crc32_of(frame, size);
    uint8_t tail[4] = {(uint8_t)(crc >> 24), (uint8_t)(crc >> 16), (uint8_t)(crc >> 8), (uint8_t)crc};
    size_t total = size + 4;
    size_t need = total + total / 254 + 2;
    if (need > cap) return -1;
    size_t o = 1, code_at = 0;
    uint8_t code = 1;
    for (size_t i = 0; i < total; i++) {
        uint8_t b = i < size ? frame[i] : tail[i - size];
        if (b == 0) {
            out[code_at] = code;
            code_at = o++;
            code = 1;
        } else {
            out[o++] = b;
            code++;
            if (code == 0xFF) {
                out[code_at] = code;
                code_at = o++;
                code = 1;
            }
        }
    }
    out[code_at] = code;
    out[o++] = 0;
    return (long)o;
}

/* the COBS blocks of frame ‖ CRC: each run of up to 254 bytes without a zero, after its
   code (the run's length + 1); the same bytes as serial_encode */
void serial_encode_each(const uint8_t *frame, size_t size, EmitFn emit, void *ctx) {
    uint32_t crc = crc32_of(frame, size);
    uint8_t tail[4] = {(uint8_t)(crc >> 24), (uint8_t)(crc >> 16), (uint8_t)(crc >> 8), (uint8_t)crc};
    size_t total = size + 4, i = 0;
    uint8_t block[255];
    for (;;) {
        uint8_t run = 0;
        while (i < total && run < 254) {
            uint8_t b = i < size ? frame[i] : tail[i - size];
            if (b == 0) break;
            block[1 + run++] = b;
            i++;
        }
        block[0] = (uint8_t)(run + 1);
        emit(ctx, block, (size_t)run + 1);
        if (run == 254) continue; /* a full run: a new code follows, even at the end */
        if (i == total) break;
        i++; /* the zero the code stands for */
    }
    static const uint8_t zero = 0;
    emit(ctx, &zero, 1);
}

long serial_decode(const uint8_t *chunk, size_t size, uint8_t *out, size_t cap) {
    if (size > LINK_MAX_ENCODED_BYTES) return -R_OVERSIZE;
    /* COBS decoding as the cobs package does it (a zero in the input, or a code that
       runs past the end, is an error). In place, out never passes chunk: each code
       byte read before its run leaves one byte to spare. */
    size_t o = 0, i = 0;
    while (i < size) {
        uint8_t code = chunk[i];
        if (code == 0) return -R_CORRUPT;
        i++;
        size_t end = i + code - 1;
        if (end > size) return -R_CORRUPT;
        for (; i < end; i++) {
            if (chunk[i] == 0) return -R_CORRUPT;
            if (o >= cap) return -R_OVERSIZE;
            out[o++] = chunk[i];
        }
        if (code < 0xFF && i < size) {
            if (o >= cap) return -R_OVERSIZE;
            out[o++] = 0;
        }
    }
    if (o < 4) return -R_CORRUPT;
    size_t n = o - 4;
    uint32_t crc = crc32_of(out, n);
    uint32_t got = (uint32_t)out[n] << 24 | (uint32_t)out[n + 1] << 16 | (uint32_t)out[n + 2] << 8 | out[n + 3];
    if (crc != got) return -R_CORRUPT;
    return (long)n;
}

int deframer_receiving(const Deframer *d) { return d->used > 0 || d->overflowed; }

void deframer_feed(Deframer *d, const uint8_t *data, size_t size, DeframeFn fn, void *ctx) {
    size_t start = 0;
    while (1) {
        const uint8_t *zero = start < size ? memchr(data + start, 0, size - start) : NULL;
        size_t end = zero ? (size_t)(zero - data) : size;
        size_t piece = end - start;
        if (!d->overflowed) {
            if (d->used + piece > LINK_ENCODED_CAP) {
                d->overflowed = 1;
                d->used = 0;
            } else {
                memcpy(d->buffer + d->used, data + start, piece);
                d->used += piece;
            }
        }
        if (!zero) return;
        if (d->overflowed) {
            fn(ctx, NULL, 0, R_OVERSIZE);
        } else if (d->used) {
            long n = serial_decode(d->buffer, d->used, d->buffer, sizeof d->buffer);
            if (n < 0) fn(ctx, NULL, 0, (int)-n);
            else fn(ctx, d->buffer, (size_t)n, R_NONE);
        }
        d->used = 0;
        d->overflowed = 0;
        start = end + 1;
    }
}
