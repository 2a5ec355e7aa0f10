/* The controller vectors (tests/vectors/controller.json, docs/controller.md): tracks of
   real runs, one robot each from its first step; every tick's reading, radio messages and
   frame go into controller_step, and its command, broadcast, phase, opinion and status must
   be the track's, bit for bit. A track stops at its first difference, which is printed. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "controller.h"
#include "jdom.h"
#include "png.h"
#include "rng.h"
#include "tests.h"

/* --- a JSON value back to text (numbers as written in the file) ---------------------- */

typedef struct {
    char *data;
    size_t size, cap;
    int overflow;
} Text;

static void put(Text *t, const char *s, size_t n) {
    if (t->size + n + 1 > t->cap) {
        t->overflow = 1;
        return;
    }
    memcpy(t->data + t->size, s, n);
    t->size += n;
    t->data[t->size] = '\0';
}

static void put_string(Text *t, const char *s, size_t n) {
    put(t, "\"", 1);
    for (size_t i = 0; i < n; i++) {
        if (s[i] == '"' || s[i] == '\\') put(t, "\\", 1);
        put(t, s + i, 1);
    }
    put(t, "\"", 1);
}

static void to_text(Text *t, const JNode *n) {
    switch (n->type) {
    case J_NULL: put(t, "null", 4); break;
    case J_BOOL: n->boolean ? put(t, "true", 4) : put(t, "false", 5); break;
    case J_NUM: put(t, n->str, strlen(n->str)); break;
    case J_STR: put_string(t, n->str, n->str_len); break;
    case J_ARR:
    case J_OBJ:
        put(t, n->type == J_ARR ? "[" : "{", 1);
        for (size_t i = 0; i < n->count; i++) {
            if (i) put(t, ",", 1);
            if (n->type == J_OBJ) {
                put_string(t, n->keys[i], strlen(n->keys[i]));
                put(t, ":", 1);
            }
            to_text(t, n->items[i]);
        }
        put(t, n->type == J_ARR ? "]" : "}", 1);
        break;
    }
}

/* A message of a track as text, and a camera frame's PNG bytes: the host's room for any,
   less on the board (make test-m4), where the vectors' few kilobytes fit. */
#ifndef TEXT_BYTES
#define TEXT_BYTES (256 * 1024)
#endif
#ifndef TRACK_FRAME_BYTES
#define TRACK_FRAME_BYTES MAX_FRAME_BYTES /* the robot's own limit of a frame */
#endif

static const char *text_of(const JNode *n, char *buffer, size_t *size) {
    Text t = {buffer, 0, TEXT_BYTES, 0};
    buffer[0] = '\0';
    to_text(&t, n);
    *size = t.size;
    return t.overflow ? NULL : buffer;
}

/* --- base64 (the frames) ------------------------------------------------------------- */

static long base64_decode(const char *in, unsigned char *out, size_t cap) {
    static const char alphabet[] =
        "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    size_t n = 0;
    unsigned value = 0;
    int bits = 0;
    for (const char *p = in; *p && *p != '='; p++) {
        const char *at = strchr(alphabet, *p);
        if (at == NULL) return -1;
        value = (value << 6) | (unsigned)(at - alphabet);
        bits += 6;
        if (bits >= 8) {
            bits -= 8;
            if (n >= cap) return -1;
            out[n++] = (unsigned char)((value >> bits) & 0xFF);
        }
    }
    return (long)n;
}

/* --- comparing ----------------------------------------------------------------------- */

static int same_double(double got, const JNode *want) {
    if (want == NULL || want->type != J_NUM) return 0;
    double w = want->num;
    return !memcmp(&got, &w, 8);
}

static int same_integer(int64_t got, const JNode *want) {
    return want != NULL && want->type == J_NUM && want->is_int && want->integer == got;
}

static int same_opinion(const double *got, int n, const JNode *want) {
    if (want == NULL || want->type != J_ARR || (int)want->count != n) return 0;
    for (int i = 0; i < n; i++)
        if (!same_double(got[i], want->items[i])) return 0;
    return 1;
}

static int nullable_integer(int has, int64_t got, const JNode *want) {
    if (want == NULL) return 0;
    return has ? same_integer(got, want) : want->type == J_NULL;
}

static int nullable_double(int has, double got, const JNode *want) {
    if (want == NULL) return 0;
    return has ? same_double(got, want) : want->type == J_NULL;
}

/* the first status field that differs, or NULL */
static const char *status_differs(const StatusOut *s, const JNode *want) {
    if (strcmp(s->phase, jdom_str(want, "phase")) != 0) return "status.phase";
    if (!same_integer(s->trips, jdom_get(want, "trips"))) return "status.trips";
    if (!same_opinion(s->opinion, s->n, jdom_get(want, "opinion"))) return "status.opinion";
    if (!same_integer(s->pool_size, jdom_get(want, "pool_size"))) return "status.pool_size";
    if (!same_integer(s->poolings, jdom_get(want, "poolings"))) return "status.poolings";
    if (!nullable_integer(s->has_decided, s->decided_site, jdom_get(want, "decided_site")))
        return "status.decided_site";
    if (!nullable_double(s->has_decision_time, s->decision_time, jdom_get(want, "decision_time")))
        return "status.decision_time";
    if (!nullable_integer(s->has_decision_trips, s->decision_trips,
                          jdom_get(want, "decision_trips")))
        return "status.decision_trips";
    const JNode *c = jdom_get(want, "comparison");
    if (c == NULL || (c->type == J_NULL) == s->has_comparison) return "status.comparison";
    if (s->has_comparison &&
        !(same_integer(s->comparison.site_a, jdom_get(c, "site_a")) &&
          same_double(s->comparison.quality_a, jdom_get(c, "quality_a")) &&
          same_integer(s->comparison.site_b, jdom_get(c, "site_b")) &&
          same_double(s->comparison.quality_b, jdom_get(c, "quality_b")) &&
          same_integer(s->comparison.eliminated, jdom_get(c, "eliminated"))))
        return "status.comparison";
    if (!same_integer(s->rejected, jdom_get(want, "rejected"))) return "status.rejected";
    if (!same_integer(s->tick, jdom_get(want, "tick"))) return "status.tick";
    if (!same_double(s->t, jdom_get(want, "t"))) return "status.t";
    return NULL;
}

/* --- one track ----------------------------------------------------------------------- */

/* The radio messages of one tick the test holds (the vectors have a few; make test-m4 sets
   fewer, for the board's memory). */
#ifndef MAX_TICK_RX
#define MAX_TICK_RX 256
#endif

typedef struct {
    Heard heard[MAX_TICK_RX];
    int count, next;
} Delivered;

static int next_heard(void *ctx, Heard *out) {
    Delivered *d = ctx;
    if (d->next >= d->count) return 0;
    *out = d->heard[d->next++];
    return 1;
}

/* the first output of the tick that differs, or NULL */
static const char *tick_differs(Controller *c, const JNode *tick, const Command *cmd) {
    const JNode *out = jdom_get(tick, "out");
    if (!same_double(cmd->left, jdom_get(out, "left"))) return "act.left";
    if (!same_double(cmd->right, jdom_get(out, "right"))) return "act.right";
    if (cmd->capture != jdom_get(out, "capture")->boolean) return "act.capture";
    const JNode *casts = jdom_get(out, "broadcasts");
    if ((int)casts->count != (cmd->broadcast ? 1 : 0)) return "broadcasts";
    if (cmd->broadcast) {
        const JNode *b = casts->items[0];
        if (!same_integer(cmd->id, jdom_get(b, "id"))) return "broadcasts[0].id";
        if (!same_integer(cmd->trip, jdom_get(b, "trip"))) return "broadcasts[0].trip";
        if (cmd->decided != jdom_get(b, "decided")->boolean) return "broadcasts[0].decided";
        if (!same_opinion(cmd->opinion, cmd->n, jdom_get(b, "opinion")))
            return "broadcasts[0].opinion";
    }
    if (strcmp(phase_names[controller_phase(c)], jdom_str(out, "phase")) != 0) return "phase";
    const JNode *opinion = jdom_get(out, "opinion");
    if (opinion != NULL && !same_opinion(c->opinion, c->n, opinion)) return "opinion";
    const JNode *status = jdom_get(out, "status");
    int changed = controller_take_status_change(c);
    if (changed != (status != NULL)) return "status";
    if (status != NULL) {
        static double buffer[MAX_OPTIONS];
        StatusOut s;
        controller_status(c, jdom_get(tick, "tick")->integer, &s, buffer);
        return status_differs(&s, status);
    }
    return NULL;
}

/* What a track's ticks are decoded into: on the heap, taken before the vectors are read,
   so that the other groups' vectors have the board's memory (make test-m4). */
typedef struct {
    WorldInfo world;
    char text[TEXT_BYTES];
    unsigned char png[TRACK_FRAME_BYTES];
    RadioPayload payloads[MAX_TICK_RX];
    char senders[MAX_TICK_RX][MAX_NAME + 1];
} TrackBuffers;

static void run_track(const JNode *track, TrackBuffers *b) {
    RadioPayload *payloads = b->payloads;
    const char *name = jdom_str(track, "name");
    char label[160];
    size_t size;
    const char *text = text_of(jdom_get(track, "world"), b->text, &size);
    if (text == NULL || !decode_world_info(text, size, &b->world)) {
        check(0, "controller vectors: the track's WorldInfo decodes", name);
        return;
    }
    ControllerConfig config;
    char error[256];
    text = text_of(jdom_get(track, "controller"), b->text, &size);
    if (text == NULL || decode_controller_config(text, size, &config, error, sizeof error) != 0) {
        check(0, "controller vectors: the track's ControllerConfig decodes", name);
        return;
    }
    int robot = (int)jdom_get(track, "robot")->integer;
    Controller *c = controller_instance();
    const char *why;
    uint64_t seed = seed_of_robot((uint64_t)b->world.seed, (unsigned)robot);
    if (controller_init(c, robot, &b->world, &config, seed, &why) != 0) {
        check(0, "controller vectors: the controller is built", name);
        return;
    }
    const JNode *frames = jdom_get(track, "frames"), *ticks = jdom_get(track, "ticks");
    for (size_t k = 0; k < ticks->count; k++) {
        const JNode *tick = ticks->items[k], *in = jdom_get(tick, "in");
        long number = (long)jdom_get(tick, "tick")->integer;
        Reading reading;
        reading.t = jdom_get(in, "t")->num;
        reading.x = jdom_get(in, "x")->num;
        reading.y = jdom_get(in, "y")->num;
        reading.theta = jdom_get(in, "theta")->num;
        const JNode *prox = jdom_get(in, "prox");
        for (int i = 0; i < 8; i++) reading.proximity[i] = prox->items[i]->num;
        Image image;
        reading.frame = NULL;
        const JNode *frame = jdom_get(in, "frame");
        if (frame->type == J_NUM) {
            const char *encoded = frames->items[frame->integer]->str;
            long n = base64_decode(encoded, b->png, sizeof b->png);
            if (n < 0 || png_decode(b->png, (size_t)n, &image, &why) != 0) {
                snprintf(label, sizeof label, "track %s, tick %ld: its frame decodes", name, number);
                check(0, "controller vectors", label);
                return;
            }
            reading.frame = &image;
        }
        Delivered delivered = {.count = 0, .next = 0};
        const JNode *rx = jdom_get(in, "rx");
        if (rx->count > MAX_TICK_RX) {
            snprintf(label, sizeof label, "track %s, tick %ld: its radio fits MAX_TICK_RX", name,
                     number);
            check(0, "controller vectors", label);
            return;
        }
        for (size_t i = 0; i < rx->count; i++) {
            const JNode *sender = rx->items[i]->items[0];
            text = text_of(rx->items[i]->items[1], b->text, &size);
            if (text == NULL || !decode_radio(text, size, &payloads[delivered.count])) {
                snprintf(label, sizeof label, "track %s, tick %ld: its radio payload decodes",
                         name, number);
                check(0, "controller vectors", label);
                return;
            }
            snprintf(b->senders[delivered.count], sizeof b->senders[0], "%s", sender->str);
            delivered.heard[delivered.count].sender = b->senders[delivered.count];
            delivered.heard[delivered.count].payload = &payloads[delivered.count];
            delivered.count++;
        }
        Command command;
        controller_step(c, &reading, next_heard, &delivered, &command);
        const char *field = tick_differs(c, tick, &command);
        if (field != NULL) {
            snprintf(label, sizeof label, "track %s, tick %ld: %s differs", name, number, field);
            check(0, "controller vectors", label);
            return;
        }
        passed++;
    }
}

void test_controller_vectors(void) {
    TrackBuffers *buffers = malloc(sizeof *buffers);
    if (buffers == NULL) {
        check(0, "controller vectors: room for a track's buffers", "malloc");
        return;
    }
    JNode *root = load("controller.json");
    if (root) {
        const JNode *tracks = jdom_get(root, "tracks");
        for (size_t i = 0; i < tracks->count; i++) run_track(tracks->items[i], buffers);
    }
    free(buffers);
}
