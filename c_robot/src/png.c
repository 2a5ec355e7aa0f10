#include "png.h"

#include <string.h>

#include "inflate.h"
#include "link.h" /* crc32_of */

/* the frame inflated (its rows, each after its filter byte), unfiltered in place, then
   turned into BGR pixels in place: the image is this buffer */
static uint8_t raw[PNG_RAW_BYTES];

static uint32_t be32(const uint8_t *p) {
    return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
}

static int paeth(int a, int b, int c) {
    int p = a + b - c;
    int pa = p > a ? p - a : a - p, pb = p > b ? p - b : b - p, pc = p > c ? p - c : c - p;
    if (pa <= pb && pa <= pc) return a;
    if (pb <= pc) return b;
    return c;
}

/* the IDAT chunks' bodies, one after another where they are in the PNG (inflate reads them
   so: never copied together) */
typedef struct {
    const uint8_t *data;
    size_t pos; /* the next chunk, the chunks checked already */
} Chunks;

static int next_idat(void *ctx, const uint8_t **body, size_t *size) {
    Chunks *chunks = ctx;
    for (;;) {
        const uint8_t *chunk = chunks->data + chunks->pos;
        uint32_t length = be32(chunk);
        chunks->pos += 12 + length;
        if (!memcmp(chunk + 4, "IEND", 4)) return 0;
        if (!memcmp(chunk + 4, "IDAT", 4)) {
            *body = chunk + 8;
            *size = length;
            return 1;
        }
    }
}

int png_decode(const uint8_t *data, size_t size, Image *image, const char **why) {
    static const uint8_t signature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    *why = "corrupt PNG";
    if (size == 0) { *why = "empty camera frame"; return -1; }
    if (size > MAX_FRAME_BYTES) { *why = "camera frame over the byte limit"; return -1; }
    if (size < 8 || memcmp(data, signature, 8) != 0) {
        *why = "camera frame is not PNG";
        return -1;
    }
    if (size < 24 || memcmp(data + 12, "IHDR", 4) != 0) {
        *why = "truncated or malformed PNG header";
        return -1;
    }
    uint32_t width = be32(data + 16), height = be32(data + 20);
    if (width == 0 || height == 0) { *why = "empty image"; return -1; }
    if ((uint64_t)width * height > MAX_FRAME_PIXELS) {
        *why = "camera frame has more pixels than the limit";
        return -1;
    }
    size_t pos = 8;
    int depth = 0, colour = 0, seen_ihdr = 0, seen_iend = 0;
    while (!seen_iend) {
        if (pos + 12 > size) return -1;
        uint32_t length = be32(data + pos);
        const uint8_t *type = data + pos + 4;
        if (length > size - pos - 12) return -1;
        const uint8_t *body = data + pos + 8;
        int critical = !(type[0] & 0x20);
        if (critical && crc32_of(type, length + 4) != be32(body + length)) {
            *why = "PNG chunk CRC error";
            return -1;
        }
        if (!seen_ihdr) {
            if (memcmp(type, "IHDR", 4) != 0 || length != 13) return -1;
            depth = body[8];
            colour = body[9];
            if (depth != 8 || (colour != 0 && colour != 2 && colour != 6) || body[10] != 0 ||
                body[11] != 0 || body[12] != 0) {
                *why = "PNG of a kind a camera frame is not (8-bit, not interlaced)";
                return -1;
            }
            seen_ihdr = 1;
        } else if (!memcmp(type, "IEND", 4)) {
            seen_iend = 1;
        } else if (!memcmp(type, "IHDR", 4)) {
            return -1;
        }
        pos += 12 + length;
    }
    int channels = colour == 0 ? 1 : colour == 2 ? 3 : 4;
    size_t stride = (size_t)width * (size_t)channels;
    size_t expected = (stride + 1) * height;
    Chunks chunks = {data, 8};
    long n = inflate_zlib_spans(next_idat, &chunks, raw, sizeof raw);
    if (n < 0 || (size_t)n < expected) {
        *why = "PNG data is corrupt or truncated";
        return -1;
    }
    /* unfilter in place: row r's bytes at raw + r * (stride + 1) + 1 */
    for (uint32_t r = 0; r < height; r++) {
        uint8_t *row = raw + (size_t)r * (stride + 1);
        uint8_t filter = row[0];
        uint8_t *cur = row + 1;
        const uint8_t *prev = r ? raw + (size_t)(r - 1) * (stride + 1) + 1 : NULL;
        if (filter > 4) return -1;
        for (size_t i = 0; i < stride; i++) {
            int a = i >= (size_t)channels ? cur[i - (size_t)channels] : 0;
            int b = prev ? prev[i] : 0;
            int c = prev && i >= (size_t)channels ? prev[i - (size_t)channels] : 0;
            int x = cur[i];
            switch (filter) {
            case 1: x += a; break;
            case 2: x += b; break;
            case 3: x += (a + b) >> 1; break;
            case 4: x += paeth(a, b, c); break;
            default: break;
            }
            cur[i] = (uint8_t)x;
        }
    }
    /* to BGR in place: pixel k's 3 bytes at 3k, its PNG bytes at row r's 1 + c * channels,
       at or after 3k + 1 for 3 or 4 channels (forwards, each pixel read before it is
       written), and before 3k for grey (backwards) */
    size_t pixels = (size_t)width * height;
    if (channels == 1) {
        for (size_t k = pixels; k-- > 0;) {
            uint8_t grey = raw[(k / width) * (stride + 1) + 1 + k % width];
            raw[3 * k] = raw[3 * k + 1] = raw[3 * k + 2] = grey;
        }
    } else { /* RGB(A) -> BGR; alpha dropped, as OpenCV's IMREAD_COLOR */
        for (size_t k = 0; k < pixels; k++) {
            const uint8_t *px = raw + (k / width) * (stride + 1) + 1 + (k % width) * (size_t)channels;
            uint8_t red = px[0], green = px[1], blue = px[2];
            raw[3 * k] = blue;
            raw[3 * k + 1] = green;
            raw[3 * k + 2] = red;
        }
    }
    image->width = (int)width;
    image->height = (int)height;
    image->bgr = raw;
    return 0;
}
