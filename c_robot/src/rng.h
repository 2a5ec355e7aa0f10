/* The generator of docs/kernel.md (bestofn_swarm/wire/rng.py): SplitMix64 and the draws on it. */
#ifndef CR_RNG_H
#define CR_RNG_H
#include <stdint.h>

typedef struct {
    uint64_t state;
} Stream;

void stream_seed(Stream *s, uint64_t seed);
uint64_t stream_next_u64(Stream *s);
double stream_random(Stream *s);
double stream_uniform(Stream *s, double low, double high);
uint64_t stream_randrange(Stream *s, uint64_t stop); /* stop >= 1 */
double stream_expovariate(Stream *s, double rate);
double stream_normal(Stream *s);
void stream_fork(Stream *s, Stream *out);
void stream_shuffle(Stream *s, int64_t *items, int count);
/* seed_of(run_seed, parts...) for the robot's stream: "<run_seed>:robot:<id>" */
uint64_t seed_of_text(const char *text);
uint64_t seed_of_robot(uint64_t run_seed, unsigned robot);
#endif
