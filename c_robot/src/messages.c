#include "messages.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "json.h"
#include "numeric.h"

#define MAX_COORD 1e6
#define MAX_ANGLE_MSG 1e3
#define MAX_SIM_TIME 1e9
#define MAX_WHEEL 10.0

int is_name(const char *text, size_t len) {
    if (len < 1 || len > MAX_NAME) return 0;
    for (size_t i = 0; i < len; i++) {
        char c = text[i];
        if (!((c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
              c == '_' || c == '.' || c == '-'))
            return 0;
    }
    return 1;
}

/* --- field readers ---------------------------------------------------------------- */

static int get_int(JR *r, int64_t *v, int64_t lo, int64_t hi) {
    if (!jr_int(r, v)) return 0;
    if (*v < lo || *v > hi) return jr_fail(r);
    return 1;
}

/* bounds: lo_kind 0 none, 1 ge, 2 gt; hi_kind 0 none, 1 le, 2 lt */
static int get_float(JR *r, double *v, int lo_kind, double lo, int hi_kind, double hi) {
    if (!jr_float(r, v)) return 0;
    if ((lo_kind == 1 && !(*v >= lo)) || (lo_kind == 2 && !(*v > lo))) return jr_fail(r);
    if ((hi_kind == 1 && !(*v <= hi)) || (hi_kind == 2 && !(*v < hi))) return jr_fail(r);
    return 1;
}

#define GET_COORD(r, v) get_float(r, v, 1, -MAX_COORD, 1, MAX_COORD)
#define GET_ANGLE(r, v) get_float(r, v, 1, -MAX_ANGLE_MSG, 1, MAX_ANGLE_MSG)
#define GET_SIMTIME(r, v) get_float(r, v, 1, 0.0, 1, MAX_SIM_TIME)
#define GET_TICK(r, v) get_int(r, v, 0, MAX_TICK)
#define GET_COUNT(r, v) get_int(r, v, 0, MAX_COUNT)
#define GET_UNIT(r, v) get_float(r, v, 1, 0.0, 1, 1.0)
#define GET_POSITIVE(r, v) get_float(r, v, 2, 0.0, 1, 1e6)

static int get_name(JR *r, char *buf) {
    size_t len, chars;
    char tmp[4 * MAX_NAME + 8];
    if (!jr_string(r, tmp, sizeof tmp, &len, &chars)) return 0;
    if (!is_name(tmp, len)) return jr_fail(r);
    memcpy(buf, tmp, len + 1);
    return 1;
}

/* a string that must be one of words (NULL-terminated list); the index */
static int get_enum(JR *r, const char *const *words, int *index) {
    char tmp[64];
    size_t len, chars;
    if (!jr_string(r, tmp, sizeof tmp, &len, &chars)) return 0;
    for (int i = 0; words[i]; i++)
        if (strlen(words[i]) == len && memcmp(words[i], tmp, len) == 0) {
            *index = i;
            return 1;
        }
    return jr_fail(r);
}

static int get_v(JR *r) {
    int64_t v;
    if (!jr_int(r, &v)) return 0;
    if (v != 1) return jr_fail(r);
    return 1;
}

static int get_bool(JR *r, int *v) { return jr_bool(r, v); }

/* a list of floats in [0, 1], min..max long */
static int get_unit_list(JR *r, double *out, int *n, int min, int max) {
    if (!jr_arr_begin(r)) return 0;
    int first = 1, count = 0;
    while (jr_arr_next(r, &first)) {
        double v;
        if (count >= max) return jr_fail(r);
        if (!GET_UNIT(r, &v)) return 0;
        if (out) out[count] = v;
        count++;
    }
    if (r->err) return 0;
    if (count < min) return jr_fail(r);
    *n = count;
    return 1;
}

#define KEY(name) (strcmp(key, name) == 0)
#define OBJECT_LOOP(r)                       \
    int first_ = 1;                          \
    char key[80];                            \
    if (!jr_obj_begin(r)) return 0;          \
    while (jr_obj_next(r, &first_, key, sizeof key))
#define DONE(r, seen, required) (!(r)->err && ((seen) & (required)) == (required))

static int start(JR *r, const void *data, size_t size) {
    if (size > MAX_PAYLOAD_BYTES) return 0;
    jr_init(r, data, size);
    return 1;
}

/* --- Sense, CameraMeta, radio metadata ---------------------------------------------- */

static int sense_body(JR *r, Sense *s) {
    unsigned seen = 0;
    OBJECT_LOOP(r) {
        if (KEY("v")) { if (!get_v(r)) return 0; seen |= 1; }
        else if (KEY("tick")) { if (!GET_TICK(r, &s->tick)) return 0; seen |= 2; }
        else if (KEY("t")) { if (!GET_SIMTIME(r, &s->t)) return 0; seen |= 4; }
        else if (KEY("x")) { if (!GET_COORD(r, &s->x)) return 0; seen |= 8; }
        else if (KEY("y")) { if (!GET_COORD(r, &s->y)) return 0; seen |= 16; }
        else if (KEY("theta")) { if (!GET_ANGLE(r, &s->theta)) return 0; seen |= 32; }
        else if (KEY("prox")) {
            int n;
            if (!get_unit_list(r, s->prox, &n, 8, 8)) return 0;
            seen |= 64;
        }
        else if (KEY("rx")) { if (!get_int(r, &s->rx, 0, 10000)) return 0; seen |= 128; }
        else if (KEY("camera")) { if (!get_bool(r, &s->camera)) return 0; seen |= 256; }
        else return jr_fail(r);
    }
    return DONE(r, seen, 511u) && jr_end(r);
}

int decode_sense(const void *data, size_t size, Sense *out) {
    JR r;
    if (!start(&r, data, size)) return 0;
    return sense_body(&r, out);
}

int decode_camera_meta(const void *data, size_t size, CameraMeta *m) {
    static const char *const encodings[] = {"png", "jpeg", NULL};
    JR jr, *r = &jr;
    if (!start(r, data, size)) return 0;
    unsigned seen = 0;
    OBJECT_LOOP(r) {
        if (KEY("v")) { if (!get_v(r)) return 0; seen |= 1; }
        else if (KEY("tick")) { if (!GET_TICK(r, &m->tick)) return 0; seen |= 2; }
        else if (KEY("width")) { if (!get_int(r, &m->width, 1, 4096)) return 0; seen |= 4; }
        else if (KEY("height")) { if (!get_int(r, &m->height, 1, 4096)) return 0; seen |= 8; }
        else if (KEY("encoding")) { if (!get_enum(r, encodings, &m->jpeg)) return 0; seen |= 16; }
        else return jr_fail(r);
    }
    return DONE(r, seen, 31u) && jr_end(r);
}

int decode_radio_rx_meta(const void *data, size_t size, RadioRxMeta *m) {
    JR jr, *r = &jr;
    if (!start(r, data, size)) return 0;
    unsigned seen = 0;
    OBJECT_LOOP(r) {
        if (KEY("v")) { if (!get_v(r)) return 0; seen |= 1; }
        else if (KEY("tick")) { if (!GET_TICK(r, &m->tick)) return 0; seen |= 2; }
        else if (KEY("sender")) { if (!get_name(r, m->sender)) return 0; seen |= 4; }
        else if (KEY("seq")) { if (!GET_COUNT(r, &m->seq)) return 0; seen |= 8; }
        else if (KEY("sent_tick")) { if (!GET_TICK(r, &m->sent_tick)) return 0; seen |= 16; }
        else return jr_fail(r);
    }
    return DONE(r, seen, 31u) && jr_end(r);
}

int decode_radio_tx_meta(const void *data, size_t size, RadioTxMeta *m) {
    JR jr, *r = &jr;
    if (!start(r, data, size)) return 0;
    unsigned seen = 0;
    OBJECT_LOOP(r) {
        if (KEY("v")) { if (!get_v(r)) return 0; seen |= 1; }
        else if (KEY("tick")) { if (!GET_TICK(r, &m->tick)) return 0; seen |= 2; }
        else if (KEY("seq")) { if (!GET_COUNT(r, &m->seq)) return 0; seen |= 4; }
        else return jr_fail(r);
    }
    return DONE(r, seen, 7u) && jr_end(r);
}

/* --- radio payloads: a union tagged by "kind" ---------------------------------------- */

/* The first "kind" of the object, as msgspec finds its tag: 0 none/other, else RADIO_*. */
static int find_tag(const void *data, size_t size) {
    static const char *const tags[] = {"opinion", "beacon", "vote", NULL};
    JR jr, *r = &jr;
    jr_init(r, data, size);
    OBJECT_LOOP(r) {
        if (KEY("kind")) {
            int index;
            if (!get_enum(r, tags, &index)) return 0;
            return index + 1;
        }
        const uint8_t *a, *b;
        if (!jr_skip(r, &a, &b)) return 0;
    }
    return 0;
}

int decode_radio(const void *data, size_t size, RadioPayload *p) {
    static const char *const tags[] = {"opinion", "beacon", "vote", NULL};
    if (size > MAX_PAYLOAD_BYTES) return 0;
    int kind = find_tag(data, size);
    if (kind == 0) return 0;
    p->kind = kind;
    JR jr, *r = &jr;
    jr_init(r, data, size);
    unsigned seen = 0, required;
    OBJECT_LOOP(r) {
        if (KEY("kind")) {
            int index;
            if (!get_enum(r, tags, &index)) return 0;
            if (index + 1 != kind) return jr_fail(r);
            continue;
        }
        if (KEY("v")) { if (!get_v(r)) return 0; seen |= 1; continue; }
        if (kind == RADIO_BEACON) {
            if (KEY("id")) { if (!get_name(r, p->name)) return 0; seen |= 2; }
            else if (KEY("seq")) { if (!GET_COUNT(r, &p->seq)) return 0; seen |= 4; }
            else return jr_fail(r);
            continue;
        }
        if (KEY("id")) { if (!get_int(r, &p->id, 0, MAX_ROBOTS - 1)) return 0; seen |= 2; }
        else if (KEY("trip")) { if (!GET_COUNT(r, &p->trip)) return 0; seen |= 4; }
        else if (KEY("decided")) { if (!get_bool(r, &p->decided)) return 0; seen |= 8; }
        else if (kind == RADIO_OPINION && KEY("opinion")) {
            if (!get_unit_list(r, p->opinion, &p->n, 2, MAX_OPTIONS)) return 0; /* held */
            seen |= 16;
        }
        else if (kind == RADIO_VOTE && KEY("site")) {
            if (!get_int(r, &p->site, 0, PROTOCOL_MAX_OPTIONS - 1)) return 0;
            seen |= 16;
        }
        else if (kind == RADIO_VOTE && KEY("quality")) {
            if (!GET_UNIT(r, &p->quality)) return 0;
            seen |= 32;
        }
        else return jr_fail(r);
    }
    required = kind == RADIO_BEACON ? 7u : kind == RADIO_OPINION ? 31u : 63u;
    if (!(DONE(r, seen, required) && jr_end(r))) return 0;
    if (kind == RADIO_OPINION) {
        double sum;
        if (nk_fsum(p->opinion, p->n, &sum) != 0) return 0;
        if (fabs(sum - 1.0) > 1e-6) return 0;
    }
    return 1;
}

/* --- WorldInfo ---------------------------------------------------------------------- */

static int nest_body(JR *r, WorldInfo *w) {
    unsigned seen = 0;
    OBJECT_LOOP(r) {
        if (KEY("x")) { if (!GET_COORD(r, &w->nest_x)) return 0; seen |= 1; }
        else if (KEY("y")) { if (!GET_COORD(r, &w->nest_y)) return 0; seen |= 2; }
        else if (KEY("radius")) { if (!GET_POSITIVE(r, &w->nest_radius)) return 0; seen |= 4; }
        else return jr_fail(r);
    }
    return DONE(r, seen, 7u);
}

static int site_body(JR *r, Site *s) {
    unsigned seen = 0;
    OBJECT_LOOP(r) {
        if (KEY("id")) { if (!get_int(r, &s->id, 0, PROTOCOL_MAX_OPTIONS - 1)) return 0; seen |= 1; }
        else if (KEY("x")) { if (!GET_COORD(r, &s->x)) return 0; seen |= 2; }
        else if (KEY("y")) { if (!GET_COORD(r, &s->y)) return 0; seen |= 4; }
        else return jr_fail(r);
    }
    return DONE(r, seen, 7u);
}

static int camera_body(JR *r, WorldInfo *w) {
    unsigned seen = 0;
    OBJECT_LOOP(r) {
        if (KEY("width")) { if (!get_int(r, &w->cam_width, 8, 1024)) return 0; seen |= 1; }
        else if (KEY("height")) { if (!get_int(r, &w->cam_height, 8, 1024)) return 0; seen |= 2; }
        else if (KEY("fov")) { if (!get_float(r, &w->cam_fov, 2, 0.0, 2, 3.2)) return 0; seen |= 4; }
        else return jr_fail(r);
    }
    return DONE(r, seen, 7u);
}

int decode_world_info(const void *data, size_t size, WorldInfo *w) {
    static const char *const clocks[] = {"lockstep", "realtime", NULL};
    JR jr, *r = &jr;
    if (!start(r, data, size)) return 0;
    unsigned seen = 0;
    OBJECT_LOOP(r) {
        if (KEY("v")) { if (!get_v(r)) return 0; seen |= 1; }
        else if (KEY("run")) { if (!get_name(r, w->run)) return 0; seen |= 2; }
        else if (KEY("seed")) { if (!get_int(r, &w->seed, 0, INT64_MAX)) return 0; seen |= 4; }
        else if (KEY("dt")) { if (!GET_POSITIVE(r, &w->dt)) return 0; seen |= 8; }
        else if (KEY("arena_radius")) { if (!GET_POSITIVE(r, &w->arena_radius)) return 0; seen |= 16; }
        else if (KEY("nest")) { if (!nest_body(r, w)) return 0; seen |= 32; }
        else if (KEY("sites")) {
            if (!jr_arr_begin(r)) return 0;
            int first = 1, n = 0;
            while (jr_arr_next(r, &first)) {
                Site site; /* held up to MAX_OPTIONS; a longer map is refused at start */
                if (n >= PROTOCOL_MAX_OPTIONS) return jr_fail(r);
                if (!site_body(r, &site)) return 0;
                if (n < MAX_OPTIONS) w->sites[n] = site;
                n++;
            }
            if (r->err || n < 2) return jr_fail(r);
            w->n_sites = n;
            seen |= 64;
        }
        else if (KEY("robot_radius")) { if (!GET_POSITIVE(r, &w->robot_radius)) return 0; seen |= 128; }
        else if (KEY("wheel_base")) { if (!GET_POSITIVE(r, &w->wheel_base)) return 0; seen |= 256; }
        else if (KEY("max_wheel_speed")) { if (!GET_POSITIVE(r, &w->max_wheel_speed)) return 0; seen |= 512; }
        else if (KEY("camera")) { if (!camera_body(r, w)) return 0; seen |= 1024; }
        else if (KEY("clock")) {
            int index;
            if (!get_enum(r, clocks, &index)) return 0;
            w->lockstep = index == 0;
            seen |= 2048;
        }
        else return jr_fail(r);
    }
    return DONE(r, seen, 4095u) && jr_end(r);
}

/* --- Act ---------------------------------------------------------------------------- */

int decode_act(const void *data, size_t size, Act *a) {
    JR jr, *r = &jr;
    if (!start(r, data, size)) return 0;
    unsigned seen = 0;
    OBJECT_LOOP(r) {
        if (KEY("v")) { if (!get_v(r)) return 0; seen |= 1; }
        else if (KEY("tick")) { if (!GET_TICK(r, &a->tick)) return 0; seen |= 2; }
        else if (KEY("left")) { if (!get_float(r, &a->left, 1, -MAX_WHEEL, 1, MAX_WHEEL)) return 0; seen |= 4; }
        else if (KEY("right")) { if (!get_float(r, &a->right, 1, -MAX_WHEEL, 1, MAX_WHEEL)) return 0; seen |= 8; }
        else if (KEY("capture")) { if (!get_bool(r, &a->capture)) return 0; seen |= 16; }
        else if (KEY("radio_tx")) { if (!get_int(r, &a->radio_tx, 0, 1000)) return 0; seen |= 32; }
        else return jr_fail(r);
    }
    return DONE(r, seen, 63u) && jr_end(r);
}

/* --- LinkWelcome (bestofn_swarm/link/core/codec.py) ------------------------------------------------------ */

int decode_welcome(const void *data, size_t size, LinkWelcome *w) {
    static const char *const ciphers[] = {"none", "chacha20-poly1305", NULL};
    JR jr, *r = &jr;
    jr_init(r, data, size);
    unsigned seen = 0;
    OBJECT_LOOP(r) {
        if (KEY("v")) { if (!get_v(r)) return 0; seen |= 1; }
        else if (KEY("run")) { if (!get_name(r, w->run)) return 0; seen |= 2; }
        else if (KEY("root")) { if (!get_name(r, w->root)) return 0; seen |= 4; }
        else if (KEY("cipher")) { if (!get_enum(r, ciphers, &w->encrypted)) return 0; seen |= 8; }
        else if (KEY("ping_every")) { if (!get_float(r, &w->ping_every, 2, 0.0, 1, 60.0)) return 0; seen |= 16; }
        else if (KEY("silence")) { if (!get_float(r, &w->silence, 2, 0.0, 1, 600.0)) return 0; seen |= 32; }
        else if (KEY("controller")) {
            const uint8_t *a, *b;
            if (!jr_skip(r, &a, &b)) return 0;
            w->controller = a;
            w->controller_size = (size_t)(b - a);
            seen |= 64;
        }
        else return jr_fail(r);
    }
    return DONE(r, seen, 127u) && jr_end(r);
}

/* --- ControllerConfig (robot_agent/core/controller_config.py, bestofn_swarm/wire/settings.py) ------ */

void controller_config_defaults(ControllerConfig *c) {
    memset(c, 0, sizeof *c);
    c->alpha = 0.0;
    c->threshold = 1.0;
    c->loglinear = 0;
    c->dwell = 3.0;
    c->broadcast_period = 0.5;
    c->linger = 0.0;
    c->strategy = 0;
    c->exploration = 10.0;
    c->dissemination = 10.0;
    c->listen = 3.0;
    c->neighbours = 2;
    c->settle = 3;
    c->trimmed = 0;
    c->trim = 1;
    c->view_distance = 0.15;
    c->beacon_timeout = 1.5;
    c->capture_timeout = 1.0;
    c->capture_attempts = 3;
    c->view_tolerance = 0.015;
    c->heading_tolerance = 0.05;
    c->wiggle = 0.12;
    c->nest_tolerance = 0.05;
    c->stall_timeout = 4.0;
    c->near_distance = 0.2;
    c->travel_timeout = 120.0;
    c->travel_crawl = 1.0 / 30.0;
    c->park_clearance = 0.06;
    c->park_spacing = 0.1;
    c->park_corridor = 0.11;
    c->park_lane = 0.2;
}

int decode_controller_config(const void *data, size_t size, ControllerConfig *c, char *error,
                             size_t error_size) {
    static const char *const poolings[] = {"mprodop", "loglinear", NULL};
    static const char *const strategies[] = {"paper", "dmvd", "dmmd", "dc", NULL};
    static const char *const defences[] = {"none", "trimmed", NULL};
    controller_config_defaults(c);
    snprintf(error, error_size, "not a controller configuration");
    if (size > (1u << 20)) return -1;
    JR jr, *r = &jr;
    jr_init(r, data, size);
    int first_ = 1;
    char key[80];
    if (!jr_obj_begin(r)) return -1;
    while (jr_obj_next(r, &first_, key, sizeof key)) {
        int ok;
#define SECONDS(name) else if (KEY(#name)) ok = get_float(r, &c->name, 2, 0.0, 0, 0.0)
#define NONNEG(name) else if (KEY(#name)) ok = get_float(r, &c->name, 1, 0.0, 0, 0.0)
        if (KEY("alpha")) ok = get_float(r, &c->alpha, 1, 0.0, 1, 0.5);
        else if (KEY("threshold")) ok = get_float(r, &c->threshold, 2, 0.0, 1, 1.0);
        else if (KEY("pooling")) ok = get_enum(r, poolings, &c->loglinear);
        SECONDS(dwell);
        SECONDS(broadcast_period);
        NONNEG(linger);
        else if (KEY("strategy")) ok = get_enum(r, strategies, &c->strategy);
        SECONDS(exploration);
        SECONDS(dissemination);
        SECONDS(listen);
        else if (KEY("neighbours")) ok = get_int(r, &c->neighbours, 1, 1000);
        else if (KEY("settle")) ok = get_int(r, &c->settle, 1, 1000000);
        else if (KEY("defence")) ok = get_enum(r, defences, &c->trimmed);
        else if (KEY("trim")) ok = get_int(r, &c->trim, 0, 1000);
        SECONDS(view_distance);
        SECONDS(beacon_timeout);
        SECONDS(capture_timeout);
        else if (KEY("capture_attempts")) ok = get_int(r, &c->capture_attempts, 1, INT64_MAX);
        SECONDS(view_tolerance);
        SECONDS(heading_tolerance);
        else if (KEY("wiggle")) ok = get_float(r, &c->wiggle, 1, 0.0, 1, NK_HALF_PI);
        SECONDS(nest_tolerance);
        SECONDS(stall_timeout);
        SECONDS(near_distance);
        SECONDS(travel_timeout);
        SECONDS(travel_crawl);
        NONNEG(park_clearance);
        SECONDS(park_spacing);
        NONNEG(park_corridor);
        SECONDS(park_lane);
        else {
            snprintf(error, error_size, "unknown setting '%s'", key);
            return -1;
        }
#undef SECONDS
#undef NONNEG
        if (!ok) {
            snprintf(error, error_size, "setting '%s' is invalid", key);
            return -1;
        }
    }
    if (r->err || !jr_end(r)) {
        snprintf(error, error_size, "not one JSON object");
        return -1;
    }
    if (c->alpha > 0.0 && c->threshold >= 1.0) {
        snprintf(error, error_size, "with alpha = %g > 0 the threshold must be below 1", c->alpha);
        return -1;
    }
    if (c->trimmed && (c->strategy != 0 || c->alpha != 0.0)) {
        snprintf(error, error_size, "defence trimmed works on the paper's strategy with alpha 0");
        return -1;
    }
    return 0;
}

/* --- the other messages, only checked ---------------------------------------------- */

static int check_clock(JR *r) {
    unsigned seen = 0;
    int64_t i;
    double d;
    OBJECT_LOOP(r) {
        if (KEY("v")) { if (!get_v(r)) return 0; seen |= 1; }
        else if (KEY("tick")) { if (!GET_TICK(r, &i)) return 0; seen |= 2; }
        else if (KEY("t")) { if (!GET_SIMTIME(r, &d)) return 0; seen |= 4; }
        else return jr_fail(r);
    }
    return DONE(r, seen, 7u);
}

static int check_join_reply(JR *r) {
    unsigned seen = 0;
    int64_t i;
    OBJECT_LOOP(r) {
        if (KEY("v")) { if (!get_v(r)) return 0; seen |= 1; }
        else if (KEY("id")) { if (!get_int(r, &i, 0, MAX_ROBOTS - 1)) return 0; seen |= 2; }
        else return jr_fail(r);
    }
    return DONE(r, seen, 3u);
}

static int check_ack(JR *r) {
    unsigned seen = 0;
    int64_t i;
    OBJECT_LOOP(r) {
        if (KEY("v")) { if (!get_v(r)) return 0; seen |= 1; }
        else if (KEY("tick")) { if (!GET_TICK(r, &i)) return 0; seen |= 2; }
        else if (KEY("radio_tx")) { if (!get_int(r, &i, 0, 1000)) return 0; seen |= 4; }
        else if (KEY("rejected")) { if (!GET_COUNT(r, &i)) return 0; }
        else if (KEY("next_tick")) { if (!jr_null(r) && !GET_TICK(r, &i)) return 0; }
        else return jr_fail(r);
    }
    return DONE(r, seen, 7u);
}

static int nullable_count(JR *r) {
    int64_t i;
    if (jr_null(r)) return 1;
    return GET_COUNT(r, &i);
}

static int check_comparison(JR *r) {
    unsigned seen = 0;
    int64_t i;
    double d;
    if (jr_null(r)) return 1;
    OBJECT_LOOP(r) {
        if (KEY("site_a")) { if (!get_int(r, &i, 0, PROTOCOL_MAX_OPTIONS - 1)) return 0; seen |= 1; }
        else if (KEY("quality_a")) { if (!GET_UNIT(r, &d)) return 0; seen |= 2; }
        else if (KEY("site_b")) { if (!get_int(r, &i, 0, PROTOCOL_MAX_OPTIONS - 1)) return 0; seen |= 4; }
        else if (KEY("quality_b")) { if (!GET_UNIT(r, &d)) return 0; seen |= 8; }
        else if (KEY("eliminated")) { if (!get_int(r, &i, 0, PROTOCOL_MAX_OPTIONS - 1)) return 0; seen |= 16; }
        else return jr_fail(r);
    }
    return DONE(r, seen, 31u);
}

static int check_status(JR *r) {
    static const char *const phases[] = {"waiting", "to_site", "sensing", "to_nest", "at_nest",
                                          "lingering", "to_decision", "stopped", NULL};
    unsigned seen = 0;
    int64_t i;
    double d;
    int n, index;
    OBJECT_LOOP(r) {
        if (KEY("v")) { if (!get_v(r)) return 0; seen |= 1; }
        else if (KEY("id")) { if (!get_int(r, &i, 0, MAX_ROBOTS - 1)) return 0; seen |= 2; }
        else if (KEY("tick")) { if (!GET_TICK(r, &i)) return 0; seen |= 4; }
        else if (KEY("t")) { if (!GET_SIMTIME(r, &d)) return 0; seen |= 8; }
        else if (KEY("phase")) { if (!get_enum(r, phases, &index)) return 0; seen |= 16; }
        else if (KEY("trips")) { if (!GET_COUNT(r, &i)) return 0; seen |= 32; }
        else if (KEY("opinion")) { if (!get_unit_list(r, NULL, &n, 2, PROTOCOL_MAX_OPTIONS)) return 0; seen |= 64; }
        else if (KEY("pool_size")) { if (!GET_COUNT(r, &i)) return 0; seen |= 128; }
        else if (KEY("poolings")) { if (!GET_COUNT(r, &i)) return 0; seen |= 256; }
        else if (KEY("decided_site")) {
            if (!jr_null(r) && !get_int(r, &i, 0, PROTOCOL_MAX_OPTIONS - 1)) return 0;
            seen |= 512;
        }
        else if (KEY("decision_time")) {
            if (!jr_null(r) && !GET_SIMTIME(r, &d)) return 0;
            seen |= 1024;
        }
        else if (KEY("decision_trips")) { if (!nullable_count(r)) return 0; seen |= 2048; }
        else if (KEY("comparison")) { if (!check_comparison(r)) return 0; seen |= 4096; }
        else if (KEY("rejected")) { if (!GET_COUNT(r, &i)) return 0; }
        else return jr_fail(r);
    }
    return DONE(r, seen, 8191u);
}

static int check_refusals(JR *r) {
    static const char *const reasons[] = {"malformed", "oversize", "corrupt", "forged",
                                           "replayed", "unexpected", "rate", NULL};
    int64_t i;
    OBJECT_LOOP(r) {
        int known = 0;
        for (int k = 0; reasons[k]; k++) known |= KEY(reasons[k]);
        if (!known) return jr_fail(r);
        if (!GET_COUNT(r, &i)) return 0;
    }
    return !r->err;
}

static int nullable_millis(JR *r) {
    double d;
    if (jr_null(r)) return 1;
    return get_float(r, &d, 1, 0.0, 1, 1e9);
}

static int check_link_stats(JR *r) {
    static const char *const transports[] = {"udp", "serial", NULL};
    unsigned seen = 0;
    int64_t i;
    double d;
    int index, b;
    OBJECT_LOOP(r) {
        if (KEY("v")) { if (!get_v(r)) return 0; seen |= 1; }
        else if (KEY("robot")) { if (!get_int(r, &i, 0, MAX_ROBOTS - 1)) return 0; seen |= 2; }
        else if (KEY("transport")) { if (!get_enum(r, transports, &index)) return 0; seen |= 4; }
        else if (KEY("address")) {
            char text[1100];
            size_t len, chars;
            if (!jr_string(r, text, sizeof text, &len, &chars)) return 0;
            if (chars > 256) return jr_fail(r);
            seen |= 8;
        }
        else if (KEY("connected")) { if (!get_bool(r, &b)) return 0; seen |= 16; }
        else if (KEY("sessions")) { if (!GET_COUNT(r, &i)) return 0; seen |= 32; }
        else if (KEY("rtt_ms")) { if (!nullable_millis(r)) return 0; seen |= 64; }
        else if (KEY("rtt_p95_ms")) { if (!nullable_millis(r)) return 0; seen |= 128; }
        else if (KEY("pings")) { if (!GET_COUNT(r, &i)) return 0; seen |= 256; }
        else if (KEY("loss")) { if (!GET_UNIT(r, &d)) return 0; seen |= 512; }
        else if (KEY("frames_in")) { if (!GET_COUNT(r, &i)) return 0; seen |= 1024; }
        else if (KEY("frames_out")) { if (!GET_COUNT(r, &i)) return 0; seen |= 2048; }
        else if (KEY("bytes_in")) { if (!GET_COUNT(r, &i)) return 0; seen |= 4096; }
        else if (KEY("bytes_out")) { if (!GET_COUNT(r, &i)) return 0; seen |= 8192; }
        else if (KEY("impaired")) { if (!GET_COUNT(r, &i)) return 0; seen |= 16384; }
        else if (KEY("refused")) { if (!check_refusals(r)) return 0; seen |= 32768; }
        else return jr_fail(r);
    }
    return DONE(r, seen, 65535u);
}

static int check_log_line(JR *r) {
    static char text[4 * 4096 + 8];
    char name[MAX_NAME + 1];
    unsigned seen = 0;
    double d;
    OBJECT_LOOP(r) {
        if (KEY("v")) { if (!get_v(r)) return 0; seen |= 1; }
        else if (KEY("process")) { if (!get_name(r, name)) return 0; seen |= 2; }
        else if (KEY("wall_time")) { if (!get_float(r, &d, 1, 0.0, 1, 1e11)) return 0; seen |= 4; }
        else if (KEY("line")) {
            size_t len, chars;
            if (!jr_string(r, text, sizeof text, &len, &chars)) return 0;
            if (chars > 4096) return jr_fail(r);
            seen |= 8;
        }
        else return jr_fail(r);
    }
    return DONE(r, seen, 15u);
}

static int check_world_state(JR *r) {
    unsigned seen = 0;
    int64_t i;
    double d;
    OBJECT_LOOP(r) {
        if (KEY("v")) { if (!get_v(r)) return 0; seen |= 1; }
        else if (KEY("tick")) { if (!GET_TICK(r, &i)) return 0; seen |= 2; }
        else if (KEY("t")) { if (!GET_SIMTIME(r, &d)) return 0; seen |= 4; }
        else if (KEY("robots")) {
            if (!jr_arr_begin(r)) return 0;
            int first = 1;
            while (jr_arr_next(r, &first)) { /* a Pose: [id, x, y, theta] */
                int inner = 1;
                if (!jr_arr_begin(r)) return 0;
                if (!jr_arr_next(r, &inner) || !get_int(r, &i, 0, MAX_ROBOTS - 1)) return jr_fail(r);
                if (!jr_arr_next(r, &inner) || !GET_COORD(r, &d)) return jr_fail(r);
                if (!jr_arr_next(r, &inner) || !GET_COORD(r, &d)) return jr_fail(r);
                if (!jr_arr_next(r, &inner) || !GET_ANGLE(r, &d)) return jr_fail(r);
                if (jr_arr_next(r, &inner) || r->err) return jr_fail(r);
            }
            if (r->err) return 0;
            seen |= 8;
        }
        else if (KEY("radio")) {
            OBJECT_LOOP(r) {
                if (KEY("sent") || KEY("delivered") || KEY("dropped") || KEY("rejected")) {
                    if (!GET_COUNT(r, &i)) return 0;
                } else return jr_fail(r);
            }
            if (r->err) return 0;
            seen |= 16;
        }
        else if (KEY("rejected")) { if (!GET_COUNT(r, &i)) return 0; seen |= 32; }
        else if (KEY("stalls")) { if (!GET_COUNT(r, &i)) return 0; seen |= 64; }
        else if (KEY("departures")) { if (!GET_COUNT(r, &i)) return 0; }
        else return jr_fail(r);
    }
    return DONE(r, seen, 127u);
}

int check_message(const char *type, const void *data, size_t size) {
    static Sense sense;
    static CameraMeta camera;
    static RadioRxMeta rx;
    static RadioTxMeta tx;
    static RadioPayload radio;
    static WorldInfo world;
    static Act act;
    if (!strcmp(type, "Sense")) return decode_sense(data, size, &sense);
    if (!strcmp(type, "CameraMeta")) return decode_camera_meta(data, size, &camera);
    if (!strcmp(type, "RadioRxMeta")) return decode_radio_rx_meta(data, size, &rx);
    if (!strcmp(type, "RadioTxMeta")) return decode_radio_tx_meta(data, size, &tx);
    if (!strcmp(type, "WorldInfo")) return decode_world_info(data, size, &world);
    if (!strcmp(type, "Act")) return decode_act(data, size, &act);
    if (!strcmp(type, "OpinionPayload") || !strcmp(type, "BeaconPayload") ||
        !strcmp(type, "VotePayload"))
        return decode_radio(data, size, &radio);
    JR jr, *r = &jr;
    if (!start(r, data, size)) return 0;
    int ok;
    if (!strcmp(type, "Clock")) ok = check_clock(r);
    else if (!strcmp(type, "JoinReply")) ok = check_join_reply(r);
    else if (!strcmp(type, "Ack")) ok = check_ack(r);
    else if (!strcmp(type, "Status")) ok = check_status(r);
    else if (!strcmp(type, "LinkStats")) ok = check_link_stats(r);
    else if (!strcmp(type, "LogLine")) ok = check_log_line(r);
    else if (!strcmp(type, "WorldState")) ok = check_world_state(r);
    else return -1;
    return ok && jr_end(r);
}

/* --- encoders ----------------------------------------------------------------------- */

static int finish(JW *w) { return w->err ? -1 : (int)w->len; }

int encode_act(const Act *a, char *out, size_t cap) {
    JW w;
    jw_init(&w, out, cap);
    jw_raw(&w, "{\"v\":1,\"tick\":");
    jw_int(&w, a->tick);
    jw_raw(&w, ",\"left\":");
    jw_float(&w, a->left);
    jw_raw(&w, ",\"right\":");
    jw_float(&w, a->right);
    jw_raw(&w, ",\"capture\":");
    jw_bool(&w, a->capture);
    jw_raw(&w, ",\"radio_tx\":");
    jw_int(&w, a->radio_tx);
    jw_raw(&w, "}");
    return finish(&w);
}

int encode_radio_tx_meta(int64_t tick, int64_t seq, char *out, size_t cap) {
    JW w;
    jw_init(&w, out, cap);
    jw_raw(&w, "{\"v\":1,\"tick\":");
    jw_int(&w, tick);
    jw_raw(&w, ",\"seq\":");
    jw_int(&w, seq);
    jw_raw(&w, "}");
    return finish(&w);
}

static void float_list(JW *w, const double *values, int n) {
    jw_raw(w, "[");
    for (int i = 0; i < n; i++) {
        if (i) jw_raw(w, ",");
        jw_float(w, values[i]);
    }
    jw_raw(w, "]");
}

int encode_opinion(int64_t id, int64_t trip, int decided, const double *opinion, int n,
                   char *out, size_t cap) {
    JW w;
    jw_init(&w, out, cap);
    jw_raw(&w, "{\"kind\":\"opinion\",\"v\":1,\"id\":");
    jw_int(&w, id);
    jw_raw(&w, ",\"trip\":");
    jw_int(&w, trip);
    jw_raw(&w, ",\"decided\":");
    jw_bool(&w, decided);
    jw_raw(&w, ",\"opinion\":");
    float_list(&w, opinion, n);
    jw_raw(&w, "}");
    return finish(&w);
}

int encode_status(const StatusOut *s, char *out, size_t cap) {
    JW w;
    jw_init(&w, out, cap);
    jw_raw(&w, "{\"v\":1,\"id\":");
    jw_int(&w, s->id);
    jw_raw(&w, ",\"tick\":");
    jw_int(&w, s->tick);
    jw_raw(&w, ",\"t\":");
    jw_float(&w, s->t);
    jw_raw(&w, ",\"phase\":");
    jw_str(&w, s->phase, strlen(s->phase));
    jw_raw(&w, ",\"trips\":");
    jw_int(&w, s->trips);
    jw_raw(&w, ",\"opinion\":");
    float_list(&w, s->opinion, s->n);
    jw_raw(&w, ",\"pool_size\":");
    jw_int(&w, s->pool_size);
    jw_raw(&w, ",\"poolings\":");
    jw_int(&w, s->poolings);
    jw_raw(&w, ",\"decided_site\":");
    if (s->has_decided) jw_int(&w, s->decided_site); else jw_raw(&w, "null");
    jw_raw(&w, ",\"decision_time\":");
    if (s->has_decision_time) jw_float(&w, s->decision_time); else jw_raw(&w, "null");
    jw_raw(&w, ",\"decision_trips\":");
    if (s->has_decision_trips) jw_int(&w, s->decision_trips); else jw_raw(&w, "null");
    jw_raw(&w, ",\"comparison\":");
    if (s->has_comparison) {
        const Comparison *c = &s->comparison;
        jw_raw(&w, "{\"site_a\":");
        jw_int(&w, c->site_a);
        jw_raw(&w, ",\"quality_a\":");
        jw_float(&w, c->quality_a);
        jw_raw(&w, ",\"site_b\":");
        jw_int(&w, c->site_b);
        jw_raw(&w, ",\"quality_b\":");
        jw_float(&w, c->quality_b);
        jw_raw(&w, ",\"eliminated\":");
        jw_int(&w, c->eliminated);
        jw_raw(&w, "}");
    } else {
        jw_raw(&w, "null");
    }
    jw_raw(&w, ",\"rejected\":");
    jw_int(&w, s->rejected);
    jw_raw(&w, "}");
    return finish(&w);
}
