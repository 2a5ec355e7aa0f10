/* Link frames (docs/protocol.md "The link to a robot outside the emulator"; bestofn_swarm/link/core/codec.py). */
#ifndef CR_LINK_H
#define CR_LINK_H
#include <stddef.h>
#include <stdint.h>

#include "limits.h"
#include "kinds.h" /* enum DataKind: generated from the table of message kinds */

#define LINK_HEADER_BYTES 33
#define LINK_TAG_BYTES 16
#define LINK_NONCE_BYTES 8
#define LINK_MAX_FRAME_BYTES 65507
#define LINK_MAX_BODY_BYTES (LINK_MAX_FRAME_BYTES - LINK_HEADER_BYTES - LINK_TAG_BYTES)
#define LINK_MIN_FRAME_BYTES (LINK_HEADER_BYTES + LINK_TAG_BYTES)
#define LINK_MAX_ATTACHMENT_BYTES 1024
#define LINK_MAX_ENCODED_BYTES \
    (LINK_MAX_FRAME_BYTES + 4 + (LINK_MAX_FRAME_BYTES + 4 + 253) / 254)
/* the serial encoding of the largest frame this build holds (limits.h LINK_FRAME_CAP) */
#define LINK_ENCODED_CAP (LINK_FRAME_CAP + 4 + (LINK_FRAME_CAP + 4 + 253) / 254)
#define LINK_REPLAY_WINDOW 64
#define LINK_PING_BODY_BYTES 8

enum FrameType { F_HELLO = 1, F_WELCOME = 2, F_DATA = 3, F_PING = 4, F_PONG = 5, F_BYE = 6 };
enum ByeReason { BYE_RUN_ENDED = 1, BYE_GOING_AWAY = 2, BYE_REPLACED = 3 };
enum Refusal {
    R_NONE = 0, R_MALFORMED, R_OVERSIZE, R_CORRUPT, R_FORGED, R_REPLAYED, R_UNEXPECTED,
    R_RATE, R_COUNT
};
extern const char *const refusal_names[R_COUNT];

typedef struct {
    int type;
    int from_bridge;
    int encrypted;
    uint32_t robot;
    uint8_t robot_nonce[8];
    uint8_t bridge_nonce[8];
    uint64_t seq;
    const uint8_t *body; /* opened: points into the caller's buffer */
    size_t body_size;
} Frame;

void link_key(const uint8_t robot_key[32], uint8_t out[32]);
void session_key(const uint8_t link_key[32], const uint8_t robot_nonce[8],
                 const uint8_t bridge_nonce[8], uint8_t out[32]);
/* frame -> bytes (out must hold body + 49; the body may already be in place, at
   out + LINK_HEADER_BYTES); returns the size, or -R_OVERSIZE */
long link_seal(const Frame *f, const uint8_t key[32], const uint8_t *cipher_key, uint8_t *out,
               size_t cap);
/* the header only (form); R_NONE or the refusal */
int link_read_header(const uint8_t *data, size_t size, Frame *f);
/* check the tag (or decrypt into plain, which holds size bytes, and may be the body's own
   place, data + LINK_HEADER_BYTES: decrypted in place); f->body then points at the body
   (in data, or in plain when encrypted) */
int link_open(const uint8_t *data, size_t size, const uint8_t key[32],
              const uint8_t *cipher_key, uint8_t *plain, Frame *f);
int link_check_body(const Frame *f);
/* DATA bodies */
long link_encode_data(int kind, const uint8_t *payload, size_t payload_size,
                      const uint8_t *attachment, size_t attachment_size, uint8_t *out,
                      size_t cap);
int link_decode_data(const uint8_t *body, size_t size, int *kind, const uint8_t **payload,
                     size_t *payload_size, const uint8_t **attachment,
                     size_t *attachment_size);

typedef struct {
    uint64_t highest;
    uint64_t seen;
} ReplayWindow;
int replay_refuses(const ReplayWindow *w, uint64_t seq); /* 1: refused */
void replay_take(ReplayWindow *w, uint64_t seq);

uint32_t crc32_of(const uint8_t *data, size_t size);
/* COBS(frame ‖ CRC) 0x00: the size written, or -1 */
long serial_encode(const uint8_t *frame, size_t size, uint8_t *out, size_t cap);
/* the same bytes, each handed to emit as it is made (a UART needs no buffer for them) */
typedef void (*EmitFn)(void *ctx, const uint8_t *bytes, size_t size);
void serial_encode_each(const uint8_t *frame, size_t size, EmitFn emit, void *ctx);
/* one zero-delimited chunk (no zero) -> frame; the frame size, or -refusal. out may be
   chunk itself: decoded in place. */
long serial_decode(const uint8_t *chunk, size_t size, uint8_t *out, size_t cap);

/* Cuts a byte stream at zeros (bestofn_swarm/link/core/codec.py Deframer), each frame decoded in
   its own buffer. */
typedef struct {
    uint8_t buffer[LINK_ENCODED_CAP + 1];
    size_t used;
    int overflowed;
} Deframer;
/* Feed bytes; for each frame or refusal found, call back (frame, size) or (NULL, refusal).
   The frame is the deframer's own buffer, which the callback may change (decrypt in place)
   until it returns. */
typedef void (*DeframeFn)(void *ctx, uint8_t *frame, size_t size, int refusal);
void deframer_feed(Deframer *d, const uint8_t *data, size_t size, DeframeFn fn, void *ctx);
/* whether a frame is under way: bytes of it fed, its zero not yet */
int deframer_receiving(const Deframer *d);
#endif
