#include "rng.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "numeric.h"
#include "sha256.h"

#define GAMMA 0x9E3779B97F4A7C15ULL
#define MIX1 0xBF58476D1CE4E5B9ULL
#define MIX2 0x94D049BB133111EBULL

void stream_seed(Stream *s, uint64_t seed) { s->state = seed; }

uint64_t stream_next_u64(Stream *s) {
    s->state += GAMMA;
    uint64_t z = s->state;
    z = (z ^ (z >> 30)) * MIX1;
    z = (z ^ (z >> 27)) * MIX2;
    return z ^ (z >> 31);
}

double stream_random(Stream *s) { return (double)(stream_next_u64(s) >> 11) * 0x1p-53; }

double stream_uniform(Stream *s, double low, double high) {
    return low + (high - low) * stream_random(s);
}

uint64_t stream_randrange(Stream *s, uint64_t stop) {
    if (stop < 1) return 0;
    uint64_t v = stop - 1;
    int bits = 0;
    while (v) {
        bits++;
        v >>= 1;
    }
    if (bits == 0) return 0;
    for (;;) {
        uint64_t value = stream_next_u64(s) >> (64 - bits);
        if (value < stop) return value;
    }
}

double stream_expovariate(Stream *s, double rate) {
    return -nk_log(1.0 - stream_random(s)) / rate;
}

double stream_normal(Stream *s) {
    double u = stream_random(s);
    double v = stream_random(s);
    return sqrt(-2.0 * nk_log(1.0 - u)) * nk_cos(NK_TWO_PI * v);
}

void stream_fork(Stream *s, Stream *out) { out->state = stream_next_u64(s); }

void stream_shuffle(Stream *s, int64_t *items, int count) {
    for (int i = count - 1; i > 0; i--) {
        int j = (int)stream_randrange(s, (uint64_t)i + 1);
        int64_t t = items[i];
        items[i] = items[j];
        items[j] = t;
    }
}

uint64_t seed_of_text(const char *text) {
    uint8_t digest[32];
    sha256(text, strlen(text), digest);
    uint64_t seed = 0;
    for (int i = 7; i >= 0; i--) seed = seed << 8 | digest[i];
    return seed;
}

/* n in decimal at out; the end (by hand: newlib-nano's printf has no %llu) */
static char *decimal(uint64_t n, char *out) {
    char digits[20];
    int count = 0;
    do {
        digits[count++] = (char)('0' + n % 10);
        n /= 10;
    } while (n);
    while (count) *out++ = digits[--count];
    return out;
}

uint64_t seed_of_robot(uint64_t run_seed, unsigned robot) {
    char text[64];
    char *end = decimal(run_seed, text);
    memcpy(end, ":robot:", 7);
    *decimal(robot, end + 7) = 0;
    return seed_of_text(text);
}
