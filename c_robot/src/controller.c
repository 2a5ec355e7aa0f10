#include "controller.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "json.h"
#include "numeric.h"
#include "vision.h"

#define TIME_EPSILON 1e-9

const char *const phase_names[8] = {"waiting", "to_site",     "sensing", "to_nest",
                                    "at_nest", "lingering",   "to_decision", "stopped"};

static Controller the_controller;
Controller *controller_instance(void) { return &the_controller; }

enum Event {
    E_START, E_REACHED_VIEWPOINT, E_LEG_TIMED_OUT, E_SENSED_FIRST_SITE, E_COMPARED,
    E_SITE_UNSEEN, E_HEARD_BEACON, E_REACHED_NEST_CENTRE, E_POOLED_UNDECIDED, E_DECIDED,
    E_DECIDED_TO_LINGER, E_LINGERED, E_PARKED, E_DISPLACED
};

/* phases.TRANSITIONS: -1 where the table has no transition */
static int transition(int phase, int event) {
    switch (phase) {
    case P_TO_SITE:
        if (event == E_START) return P_TO_SITE;
        if (event == E_REACHED_VIEWPOINT) return P_SENSING;
        if (event == E_LEG_TIMED_OUT) return P_TO_NEST;
        break;
    case P_SENSING:
        if (event == E_SENSED_FIRST_SITE) return P_TO_SITE;
        if (event == E_COMPARED || event == E_SITE_UNSEEN) return P_TO_NEST;
        break;
    case P_TO_NEST:
        if (event == E_HEARD_BEACON) return P_AT_NEST;
        if (event == E_REACHED_NEST_CENTRE) return P_WAITING;
        break;
    case P_WAITING:
        if (event == E_HEARD_BEACON) return P_AT_NEST;
        break;
    case P_AT_NEST:
        if (event == E_POOLED_UNDECIDED) return P_TO_SITE;
        if (event == E_DECIDED) return P_TO_DECISION;
        if (event == E_DECIDED_TO_LINGER) return P_LINGERING;
        break;
    case P_LINGERING:
        if (event == E_LINGERED) return P_TO_DECISION;
        break;
    case P_TO_DECISION:
        if (event == E_PARKED) return P_STOPPED;
        break;
    case P_STOPPED:
        if (event == E_DISPLACED) return P_TO_DECISION;
        break;
    default:
        break;
    }
    return -1;
}

/* --- small helpers ------------------------------------------------------------------- */

static double distance_to(const Reading *r, double px, double py) {
    return nk_hypot(r->x - px, r->y - py);
}

static void along_radius(double x, double y, double radius, double *ox, double *oy) {
    double length = nk_hypot(x, y);
    if (length == 0.0) {
        *ox = radius;
        *oy = 0.0;
        return;
    }
    *ox = radius * (x / length);
    *oy = radius * (y / length);
}

static void stop(Command *out) {
    out->left = out->right = 0.0;
    out->capture = 0;
    out->broadcast = 0;
}

static void drive(Command *out, double left, double right) {
    out->left = left;
    out->right = right;
    out->capture = 0;
    out->broadcast = 0;
}

/* --- motion (motion.py) -------------------------------------------------------------- */

static void start_leg(Controller *c, double t) {
    navigator_reset(&c->nav);
    c->leg_start = t;
    c->has_allowance = 0;
    c->best_distance = INFINITY;
    c->last_progress = t;
}

static int motion_drive_to(Controller *c, const Reading *r, double gx, double gy,
                           double tolerance, int avoid, double *left, double *right) {
    static const double zeros[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    return navigator_drive_to(&c->nav, r->x, r->y, r->theta, avoid ? r->proximity : zeros, gx,
                              gy, tolerance, left, right);
}

static int timed_out(Controller *c, const Reading *r, double gx, double gy) {
    if (!c->has_allowance) {
        double length = distance_to(r, gx, gy);
        double crawl = length / c->config.travel_crawl;
        c->allowance = crawl > c->config.travel_timeout ? crawl : c->config.travel_timeout;
        c->has_allowance = 1;
    }
    return r->t - c->leg_start > c->allowance;
}

static int stalled_near(Controller *c, const Reading *r, double gx, double gy, double near) {
    double gap = distance_to(r, gx, gy);
    if (gap < c->best_distance - 0.01) {
        c->best_distance = gap;
        c->last_progress = r->t;
        return 0;
    }
    return gap <= near && r->t - c->last_progress >= c->config.stall_timeout;
}

/* --- sensing (sensing.py) ------------------------------------------------------------ */

static double site_heading(const Controller *c, const Reading *r) {
    return nk_atan2(c->sense_site_y - r->y, c->sense_site_x - r->x);
}

static void sensing_begin(Controller *c, const Reading *r, double sx, double sy) {
    c->sense_site_x = sx;
    c->sense_site_y = sy;
    c->attempts = 0;
    c->has_capture_time = 0;
    c->aim = site_heading(c, r);
}

/* 1: a quality; 2: gave up; 0: neither. The command in out. */
static int sensing_step(Controller *c, const Reading *r, Command *out, double *quality) {
    int failed = 0;
    if (c->has_capture_time) {
        if (r->frame != NULL) {
            c->has_capture_time = 0;
            double q;
            if (estimate_quality(r->frame, &q) && isfinite(q)) {
                q = q > 0.0 ? q : 0.0; /* min(max(q, 0.0), 1.0) */
                q = 1.0 < q ? 1.0 : q;
                *quality = q;
                stop(out);
                return 1;
            }
            failed = 1;
        } else if (r->t - c->capture_time > c->config.capture_timeout + TIME_EPSILON) {
            c->has_capture_time = 0;
            failed = 1;
        } else {
            stop(out);
            return 0; /* the frame is on its way */
        }
    }
    if (failed) {
        c->attempts += 1;
        if (c->attempts >= c->config.capture_attempts) {
            stop(out);
            return 2;
        }
        double heading = site_heading(c, r);
        c->aim = heading + stream_uniform(&c->rng, -c->config.wiggle, c->config.wiggle);
    }
    double left, right;
    int facing = navigator_turn_to(&c->nav, r->theta, c->aim, c->config.heading_tolerance,
                                   &left, &right);
    if (facing) {
        c->has_capture_time = 1;
        c->capture_time = r->t;
        stop(out);
        out->capture = 1;
        return 0;
    }
    drive(out, left, right);
    return 0;
}

/* --- parking (parking.py) ------------------------------------------------------------ */

static long ring_slot_count(const Controller *c, double radius, double step, double keep_clear) {
    long total = (long)(NK_TWO_PI / step), count = 0;
    for (long index = 0; index < total; index++) {
        double angle = (double)index * step;
        int ok = 1;
        for (int s = 0; s < c->n && ok; s++)
            ok = fabs(remainder(angle - c->site_angle[s], NK_TWO_PI)) * radius >= keep_clear;
        count += ok;
    }
    return count;
}

static void parking_slot(Controller *c, int site, double *sx, double *sy) {
    static double slots[MAX_RING_SLOTS], keys[MAX_RING_SLOTS];
    const ControllerConfig *k = &c->config;
    double pitch = 2 * c->robot_radius + k->park_lane;
    double home = c->site_angle[site];
    /* the rings, from the wall inwards: their radii, steps and slot counts */
    static double radii[MAX_RINGS], steps[MAX_RINGS], clear[MAX_RINGS];
    static long counts[MAX_RINGS];
    int rings = 0;
    long total = 0;
    double radius = c->arena_radius - k->park_clearance;
    while ((radius >= c->inner_radius || rings == 0) && rings < MAX_RINGS) {
        double step, keep_clear;
        if (rings == 0) {
            step = k->park_spacing / radius;
            keep_clear = k->park_corridor;
        } else {
            step = pitch / radius;
            keep_clear = k->park_corridor + k->park_lane / 2;
        }
        radii[rings] = radius;
        steps[rings] = step;
        clear[rings] = keep_clear;
        counts[rings] = ring_slot_count(c, radius, step, keep_clear);
        total += counts[rings];
        rings++;
        radius = c->arena_radius - k->park_clearance - rings * pitch;
    }
    long remaining = c->robot_id % (total > 1 ? total : 1);
    for (int ring = 0; ring < rings; ring++) {
        if (remaining < counts[ring]) {
            long m = 0, all = (long)(NK_TWO_PI / steps[ring]);
            for (long index = 0; index < all && m < MAX_RING_SLOTS; index++) {
                double angle = (double)index * steps[ring];
                int ok = 1;
                for (int s = 0; s < c->n && ok; s++)
                    ok = fabs(remainder(angle - c->site_angle[s], NK_TWO_PI)) * radii[ring] >=
                         clear[ring];
                if (!ok) continue;
                /* a stable insertion by the key: nearest the site first */
                double key = fabs(remainder(angle - home, NK_TWO_PI));
                long at = m;
                while (at > 0 && keys[at - 1] > key) {
                    keys[at] = keys[at - 1];
                    slots[at] = slots[at - 1];
                    at--;
                }
                keys[at] = key;
                slots[at] = angle;
                m++;
            }
            double sine, cosine;
            nk_sincos(slots[remaining], &sine, &cosine);
            *sx = radii[ring] * cosine;
            *sy = radii[ring] * sine;
            return;
        }
        remaining -= counts[ring];
    }
    double sine, cosine;
    nk_sincos(home, &sine, &cosine);
    *sx = radii[0] * cosine;
    *sy = radii[0] * sine;
}

/* whether parking_slot's rings and slots fit this build's room (MAX_RINGS, MAX_RING_SLOTS):
   the run's parking settings in this arena, checked once at start */
static int parking_fits(const Controller *c) {
    const ControllerConfig *k = &c->config;
    double pitch = 2 * c->robot_radius + k->park_lane;
    double radius = c->arena_radius - k->park_clearance;
    for (int rings = 0; radius >= c->inner_radius || rings == 0; rings++) {
        double step = rings == 0 ? k->park_spacing / radius : pitch / radius;
        if (rings == MAX_RINGS || NK_TWO_PI / step >= (double)MAX_RING_SLOTS + 1) return 0;
        radius = c->arena_radius - k->park_clearance - (rings + 1) * pitch;
    }
    return 1;
}

static void parking_begin(Controller *c, int site, double t) {
    parking_slot(c, site, &c->slot_x, &c->slot_y);
    c->has_slot = 1;
    c->has_backoff = 0;
    start_leg(c, t);
}

static void back_off(Controller *c, const Reading *r, Command *out) {
    c->park_retries += 1;
    double radius = nk_hypot(r->x, r->y) - c->config.near_distance;
    radius = radius > c->inner_radius ? radius : c->inner_radius;
    along_radius(r->x, r->y, radius, &c->backoff_x, &c->backoff_y);
    c->backoff_until = r->t + c->config.stall_timeout;
    c->has_backoff = 1;
    navigator_reset(&c->nav);
    stop(out);
}

/* 1: a command in out; 0: parked (None) */
static int parking_step(Controller *c, const Reading *r, Command *out) {
    double gx = c->slot_x, gy = c->slot_y, left, right;
    if (c->has_backoff) {
        if (r->t + TIME_EPSILON < c->backoff_until) {
            motion_drive_to(c, r, c->backoff_x, c->backoff_y, c->config.view_tolerance, 1, &left,
                            &right);
            drive(out, left, right);
            return 1;
        }
        c->has_backoff = 0;
        start_leg(c, r->t);
    }
    if (timed_out(c, r, gx, gy)) {
        back_off(c, r, out);
        return 1;
    }
    int near = distance_to(r, gx, gy) <= c->config.near_distance;
    int arrived = motion_drive_to(c, r, gx, gy, c->config.view_tolerance, !near, &left, &right);
    if (arrived) return 0;
    if (stalled_near(c, r, gx, gy, c->config.near_distance)) {
        if (distance_to(r, gx, gy) > c->robot_radius) {
            back_off(c, r, out);
            return 1;
        }
        return 0;
    }
    drive(out, left, right);
    return 1;
}

/* --- beliefs (beliefs.py) ------------------------------------------------------------ */

static void heard_clear(Controller *c) {
    c->heard_count = 0;
    c->free_count = 0;
    for (int i = c->heard_slots - 1; i >= 0; i--) c->free_slots[c->free_count++] = i;
}

static double *peer_opinion(Controller *c, int slot) { return c->peer_arena + (size_t)slot * c->n; }
static double *heard_opinion(Controller *c, int slot) { return c->heard_arena + (size_t)slot * c->n; }

static void hear(Controller *c, int64_t robot, double t, const double *opinion) {
    int n = c->n;
    int found = -1;
    for (int i = 0; i < c->heard_count; i++)
        if (c->heard[i].robot == robot) found = i;
    if (found < 0) {
        if (c->free_count == 0) {
            /* full: free an entry no pooling can take any more (heard before the visit to
               the nest under way, or before now when not at the nest) */
            double since = c->phase == P_AT_NEST ? c->listen_from - TIME_EPSILON
                                                  : c->t - TIME_EPSILON;
            for (int i = 0; i < c->heard_count; i++)
                if (c->heard[i].t < since) {
                    c->free_slots[c->free_count++] = c->heard[i].slot;
                    c->heard[i] = c->heard[--c->heard_count];
                    break;
                }
        }
        if (c->free_count == 0) {
            c->dropped_heard++;
            goto peers;
        }
        found = c->heard_count++;
        c->heard[found].robot = robot;
        c->heard[found].slot = c->free_slots[--c->free_count];
    }
    c->heard[found].t = t;
    memcpy(heard_opinion(c, c->heard[found].slot), opinion, sizeof(double) * (size_t)n);
peers:
    if (c->config.trimmed) {
        int p = -1;
        for (int i = 0; i < c->peer_count; i++)
            if (c->peers[i].robot == robot) p = i;
        if (p < 0) {
            if (c->peer_count >= c->peer_slots) {
                c->dropped_heard++;
                return;
            }
            p = c->peer_count++;
            c->peers[p].robot = robot;
            c->peers[p].slot = p;
        }
        memcpy(peer_opinion(c, c->peers[p].slot), opinion, sizeof(double) * (size_t)n);
    }
}

static int hear_payload(Controller *c, int64_t robot, double t, const RadioPayload *p) {
    if (p->kind != RADIO_OPINION) return 0;
    if (p->n != c->n || !valid_opinion(p->opinion, p->n)) return 0;
    hear(c, robot, t, p->opinion);
    return 1;
}

static void wire_opinion(const double *opinion, int n, double *out) {
    for (int i = 0; i < n; i++) out[i] = round_significant9(opinion[i]);
}

/* Beliefs.compare: whether the opinion changed */
static int beliefs_compare(Controller *c) {
    int site_a = c->visited[0], site_b = c->visited[1];
    double quality_a = c->qualities[0], quality_b = c->qualities[1];
    if (quality_a == quality_b) return 0;
    int worse = quality_a < quality_b ? site_a : site_b;
    c->has_comparison = 1;
    c->comparison.site_a = site_a;
    c->comparison.quality_a = quality_a;
    c->comparison.site_b = site_b;
    c->comparison.quality_b = quality_b;
    c->comparison.eliminated = worse;
    double updated[MAX_OPTIONS];
    negative_update(c->opinion, c->n, worse, c->config.alpha, updated);
    int same = 1;
    for (int i = 0; i < c->n; i++)
        if (updated[i] != c->opinion[i]) same = 0;
    if (same) return 0;
    memcpy(c->opinion, updated, sizeof(double) * (size_t)c->n);
    return 1;
}

static int by_robot(const void *a, const void *b) {
    int64_t x = ((const HeardEntry *)a)->robot, y = ((const HeardEntry *)b)->robot;
    return x < y ? -1 : x > y;
}

static void beliefs_pool(Controller *c, double since, double t) {
    static const double *pool[MAX_POOL];
    static HeardEntry sorted[MAX_HEARD];
    int count = 0;
    pool[count++] = c->opinion;
    memcpy(sorted, c->heard, sizeof(HeardEntry) * (size_t)c->heard_count);
    /* robot ids are distinct: any sort gives sorted(dict.items())'s order */
    qsort(sorted, (size_t)c->heard_count, sizeof(HeardEntry), by_robot);
    for (int i = 0; i < c->heard_count && count < MAX_POOL; i++)
        if (sorted[i].t >= since) pool[count++] = heard_opinion(c, sorted[i].slot);
    double pooled[MAX_OPTIONS];
    int ok;
    if (c->config.trimmed) {
        static const double *peers[MAX_HEARD];
        for (int i = 0; i < c->peer_count; i++) peers[i] = peer_opinion(c, c->peers[i].slot);
        ok = trimmed_support(c->opinion, c->n, peers, c->peer_count, (long)c->config.trim, pooled);
    } else if (c->config.loglinear) {
        ok = loglinear_pool(pool, count, c->n, 0.5, pooled);
    } else {
        ok = mprodop(pool, count, c->n, pooled);
    }
    if (ok) memcpy(c->opinion, pooled, sizeof(double) * (size_t)c->n);
    heard_clear(c);
    c->last_pool_size = count;
    c->poolings += 1;
    c->trips += 1;
    int decided = decided_option(c->opinion, c->n, c->config.threshold);
    if (decided >= 0) {
        c->decided_site = decided;
        c->decision_time = t;
        c->decision_trips = c->trips;
    }
}

/* --- the controller ------------------------------------------------------------------ */

int controller_init(Controller *c, int robot_id, const WorldInfo *world,
                    const ControllerConfig *config, uint64_t seed, const char **why) {
    memset(c, 0, sizeof *c);
    if (robot_id < 0 || robot_id >= MAX_ROBOTS) {
        *why = "robot id out of range";
        return -1;
    }
    int n = world->n_sites;
    if (n > MAX_OPTIONS) {
        *why = "the map has more sites than this build holds (MAX_OPTIONS)";
        return -1;
    }
    static int seen[MAX_OPTIONS];
    memset(seen, 0, sizeof seen);
    for (int i = 0; i < n; i++) {
        int64_t id = world->sites[i].id;
        if (id < 0 || id >= n || seen[id]) {
            *why = "site ids must be 0..n-1 once each";
            return -1;
        }
        seen[id] = 1;
    }
    if (n < 2) {
        *why = "need at least 2 sites";
        return -1;
    }
    if (config->strategy != 0) {
        *why = "this robot runs the paper's strategy only (--strategy paper)";
        return -1;
    }
    double sensing_radius = world->arena_radius - config->view_distance;
    if (world->arena_radius - config->park_clearance < world->nest_radius + world->robot_radius) {
        *why = "park_clearance leaves no room to park in the arena";
        return -1;
    }
    if (config->view_distance < world->robot_radius) {
        *why = "view_distance puts the robot into the wall";
        return -1;
    }
    c->robot_id = robot_id;
    snprintf(c->name, sizeof c->name, "%d", robot_id);
    c->config = *config;
    stream_seed(&c->rng, seed);
    c->n = n;
    for (int i = 0; i < n; i++) {
        const Site *s = &world->sites[i];
        int id = (int)s->id;
        c->site_x[id] = s->x;
        c->site_y[id] = s->y;
    }
    for (int i = 0; i < n; i++) {
        along_radius(c->site_x[i], c->site_y[i], sensing_radius, &c->view_x[i], &c->view_y[i]);
    }
    c->nest_x = world->nest_x;
    c->nest_y = world->nest_y;
    c->nest_radius = world->nest_radius;
    c->arena_radius = world->arena_radius;
    c->robot_radius = world->robot_radius;
    NavParams params;
    if (nav_params_default(&params, world->max_wheel_speed, world->wheel_base,
                           world->robot_radius, world->dt, why) != 0)
        return -1;
    Stream nav_rng;
    stream_fork(&c->rng, &nav_rng); /* its own stream: obstacles do not shift the pairs */
    if (navigator_init(&c->nav, &params, nav_rng, why) != 0) return -1;
    for (int i = 0; i < n; i++) c->site_angle[i] = nk_atan2(c->site_y[i], c->site_x[i]);
    c->inner_radius = world->nest_radius + 3 * world->robot_radius;
    for (int i = 0; i < n; i++) c->opinion[i] = 1.0 / n; /* uniform_opinion */
    c->decided_site = -1;
    c->heard_slots = HEARD_DOUBLES / n;
    if (c->heard_slots > MAX_HEARD) c->heard_slots = MAX_HEARD;
    c->peer_slots = c->heard_slots;
    heard_clear(c);
    c->phase = P_TO_SITE;
    c->changed = 1;
    c->best_distance = INFINITY;
    if (!parking_fits(c)) {
        *why = "the parking settings need more rings or slots than this build holds";
        return -1;
    }
    return 0;
}

int controller_phase(const Controller *c) { return c->phase; }

int controller_take_status_change(Controller *c) {
    int changed = c->changed;
    c->changed = 0;
    return changed;
}

void controller_status(const Controller *c, int64_t tick, StatusOut *s, double *opinion) {
    memset(s, 0, sizeof *s);
    s->id = c->robot_id;
    s->tick = tick;
    s->t = c->t;
    s->phase = phase_names[c->phase];
    s->trips = c->trips;
    wire_opinion(c->opinion, c->n, opinion);
    s->opinion = opinion;
    s->n = c->n;
    s->pool_size = c->poolings ? c->last_pool_size : 0;
    s->poolings = c->poolings;
    s->has_decided = c->decided_site >= 0;
    s->decided_site = c->decided_site;
    s->has_decision_time = c->decided_site >= 0;
    s->decision_time = c->decision_time;
    s->has_decision_trips = c->decided_site >= 0;
    s->decision_trips = c->decision_trips;
    s->has_comparison = c->has_comparison;
    s->comparison = c->comparison;
    s->rejected = c->rejected;
}

static void choose_next_pair(Controller *c, const Reading *r) {
    int first, second;
    choose_pair(c->opinion, c->n, &c->rng, &first, &second);
    /* the nearer viewpoint first; the sites themselves are what the rng chose */
    if (distance_to(r, c->view_x[second], c->view_y[second]) <
        distance_to(r, c->view_x[first], c->view_y[first])) {
        int t = first;
        first = second;
        second = t;
    }
    c->pair[0] = first;
    c->pair[1] = second;
    c->pair_len = 2;
    c->quality_count = 0;
}

static void fire(Controller *c, int event, const Reading *r);

static void enter(Controller *c, int phase, const Reading *r) {
    switch (phase) {
    case P_TO_SITE:
        start_leg(c, c->t);
        break;
    case P_SENSING:
        sensing_begin(c, r, c->site_x[c->pair[0]], c->site_y[c->pair[0]]);
        c->explore_until = c->t + 0.0; /* the paper's robot leaves a site once it saw it */
        break;
    case P_TO_NEST:
        c->pair_len = 0; /* whatever is left of the pair is given up */
        start_leg(c, c->t);
        break;
    case P_AT_NEST:
        c->nest_arrival = c->t;
        c->next_broadcast = c->t;
        c->dwell_end = c->t + c->config.dwell;
        c->listen_from = c->t;
        break;
    case P_LINGERING:
        c->linger_end = c->t + c->config.linger;
        break;
    case P_TO_DECISION:
        parking_begin(c, c->decided_site, c->t);
        break;
    default:
        break;
    }
}

static void fire(Controller *c, int event, const Reading *r) {
    int leaving = c->phase;
    int entering = transition(leaving, event);
    if (entering < 0) {
        fprintf(stderr, "c-robot: illegal transition (event %d in phase %s)\n", event,
                phase_names[leaving]);
        return;
    }
    c->phase = entering;
    if (entering != leaving) c->changed = 1;
    enter(c, entering, r);
}

static int hears_beacon(const Controller *c, double since) {
    return c->has_last_beacon && c->last_beacon + TIME_EPSILON >= since &&
           c->t - c->last_beacon <= c->config.beacon_timeout + TIME_EPSILON;
}

static void broadcasts(Controller *c, Command *out) {
    if (c->t + TIME_EPSILON < c->next_broadcast) return;
    c->next_broadcast = c->t + c->config.broadcast_period;
    out->broadcast = 1;
    out->id = c->robot_id;
    out->trip = c->trips;
    out->decided = c->decided_site >= 0;
    out->n = c->n;
    wire_opinion(c->opinion, c->n, out->opinion);
}

static void listen(Controller *c, NextHeard next, void *ctx) {
    Heard heard;
    while (next(ctx, &heard)) {
        const RadioPayload *p = heard.payload;
        if (p->kind == RADIO_BEACON) {
            c->has_last_beacon = 1;
            c->last_beacon = c->t;
            continue;
        }
        const char *sender = heard.sender;
        if (!strcmp(sender, c->name) && p->id == c->robot_id) continue; /* our own echo */
        char claimed[21];
        format_int(p->id, claimed);
        if (strcmp(sender, claimed) != 0) {
            c->rejected += 1; /* a robot claiming someone else's id */
            continue;
        }
        if (!hear_payload(c, p->id, c->t, p)) c->rejected += 1;
    }
}

static void compare(Controller *c, const Reading *r) {
    if (beliefs_compare(c)) c->changed = 1;
    fire(c, E_COMPARED, r);
}

static void sense(Controller *c, const Reading *r, Command *out) {
    if (c->exploring) {
        if (c->t + TIME_EPSILON >= c->explore_until) {
            c->exploring = 0;
            compare(c, r);
        }
        stop(out);
        return;
    }
    double quality;
    int look = sensing_step(c, r, out, &quality);
    if (look == 1) {
        int site = c->pair[0];
        c->pair[0] = c->pair[1];
        c->pair_len -= 1;
        c->visited[c->quality_count] = site;
        c->qualities[c->quality_count] = quality;
        c->quality_count++;
        if (c->pair_len > 0) {
            fire(c, E_SENSED_FIRST_SITE, r);
        } else if (c->t + TIME_EPSILON < c->explore_until) {
            c->exploring = 1;
        } else {
            compare(c, r);
        }
    } else if (look == 2) {
        fire(c, E_SITE_UNSEEN, r);
    }
}

static void drive_to_site(Controller *c, const Reading *r, Command *out) {
    int site = c->pair[0];
    double gx = c->view_x[site], gy = c->view_y[site], left, right;
    int arrived = motion_drive_to(c, r, gx, gy, c->config.view_tolerance, 1, &left, &right);
    if (arrived || stalled_near(c, r, gx, gy, c->config.near_distance)) {
        fire(c, E_REACHED_VIEWPOINT, r);
        sense(c, r, out);
        return;
    }
    if (timed_out(c, r, gx, gy)) {
        fire(c, E_LEG_TIMED_OUT, r);
        stop(out);
        return;
    }
    drive(out, left, right);
}

static void drive_home(Controller *c, const Reading *r, Command *out) {
    if (hears_beacon(c, c->leg_start)) {
        fire(c, E_HEARD_BEACON, r);
        stop(out);
        broadcasts(c, out);
        return;
    }
    double left, right;
    int arrived = motion_drive_to(c, r, c->nest_x, c->nest_y, c->config.nest_tolerance, 1, &left,
                                  &right);
    if (arrived) {
        fire(c, E_REACHED_NEST_CENTRE, r);
        stop(out);
        return;
    }
    drive(out, left, right);
}

static void wait_for_beacon(Controller *c, const Reading *r, Command *out) {
    if (hears_beacon(c, c->leg_start)) {
        fire(c, E_HEARD_BEACON, r);
        stop(out);
        broadcasts(c, out);
        return;
    }
    if (distance_to(r, c->nest_x, c->nest_y) <= 2 * c->config.nest_tolerance) {
        stop(out); /* pushed a little: not worth driving back yet */
        return;
    }
    double left, right;
    motion_drive_to(c, r, c->nest_x, c->nest_y, c->config.nest_tolerance, 1, &left, &right);
    drive(out, left, right);
}

static void pool_and_decide(Controller *c, const Reading *r) {
    beliefs_pool(c, c->listen_from - TIME_EPSILON, c->t);
    c->changed = 1;
    if (c->decided_site < 0) {
        choose_next_pair(c, r);
        fire(c, E_POOLED_UNDECIDED, r);
    } else if (c->config.linger > 0.0) {
        fire(c, E_DECIDED_TO_LINGER, r);
    } else {
        fire(c, E_DECIDED, r);
    }
}

static void dwell(Controller *c, const Reading *r, Command *out) {
    stop(out);
    broadcasts(c, out); /* the opinion as it was before pooling */
    if (c->t + TIME_EPSILON >= c->dwell_end) pool_and_decide(c, r);
}

static void linger(Controller *c, const Reading *r, Command *out) {
    stop(out);
    broadcasts(c, out);
    if (c->t + TIME_EPSILON >= c->linger_end) fire(c, E_LINGERED, r);
}

static void park(Controller *c, const Reading *r, Command *out) {
    if (!parking_step(c, r, out)) {
        fire(c, E_PARKED, r);
        stop(out);
    }
}

/* parking.Parking.displaced: pushed more than a body width out of its slot, drive back */
static void stay(Controller *c, const Reading *r, Command *out) {
    if (distance_to(r, c->slot_x, c->slot_y) > 2 * c->robot_radius) {
        fire(c, E_DISPLACED, r);
        park(c, r, out);
    }
}

void controller_step(Controller *c, const Reading *r, NextHeard next, void *ctx, Command *out) {
    stop(out);
    c->t = r->t;
    listen(c, next, ctx);
    if (!c->started) {
        c->started = 1;
        choose_next_pair(c, r);
        fire(c, E_START, r);
    }
    switch (c->phase) {
    case P_TO_SITE: drive_to_site(c, r, out); break;
    case P_SENSING: sense(c, r, out); break;
    case P_TO_NEST: drive_home(c, r, out); break;
    case P_WAITING: wait_for_beacon(c, r, out); break;
    case P_AT_NEST: dwell(c, r, out); break;
    case P_LINGERING: linger(c, r, out); break;
    case P_TO_DECISION: park(c, r, out); break;
    case P_STOPPED: stay(c, r, out); break;
    default: stop(out); break;
    }
}

void controller_parking_slot(Controller *c, int site, double *x, double *y) {
    parking_slot(c, site, x, y);
}
