/* The robot's Section 5 controller (robot_agent/core/controller.py and its parts:
   phases, beliefs, motion, sensing, parking), for the paper's strategy. */
#ifndef CR_CONTROLLER_H
#define CR_CONTROLLER_H
#include "decision.h"
#include "messages.h"
#include "navigation.h"
#include "png.h"
#include "rng.h"

enum Phase {
    P_WAITING, P_TO_SITE, P_SENSING, P_TO_NEST, P_AT_NEST, P_LINGERING, P_TO_DECISION,
    P_STOPPED
};
extern const char *const phase_names[8];

/* what the body read this step (ports.BodyReading) */
typedef struct {
    double t, x, y, theta;
    double proximity[8];
    const Image *frame; /* NULL: none */
} Reading;

/* one radio message that passed validation (ports.Received) */
typedef struct {
    const char *sender;
    const RadioPayload *payload;
} Heard;

typedef struct {
    double left, right;
    int capture;
    int broadcast; /* 1: broadcast the opinion in out_opinion */
    int64_t id, trip;
    int decided;
    int n;
    double opinion[MAX_OPTIONS]; /* at the wire's precision */
} Command;


typedef struct {
    int64_t robot;
    double t;
    int slot; /* in the arena */
} HeardEntry;

typedef struct Controller Controller;

/* 0, or -1 and why (the Python constructor's ValueError) */
int controller_init(Controller *c, int robot_id, const WorldInfo *world,
                    const ControllerConfig *config, uint64_t seed, const char **why);
/* the step's radio messages, one valid one at a time (1), until there are none (0) */
typedef int (*NextHeard)(void *ctx, Heard *out);
void controller_step(Controller *c, const Reading *reading, NextHeard next, void *ctx,
                     Command *out);
int controller_take_status_change(Controller *c);
/* the status (without the endpoint's rejections); opinion_buffer holds n doubles */
void controller_status(const Controller *c, int64_t tick, StatusOut *s, double *opinion_buffer);
int controller_phase(const Controller *c);
/* robot c->robot_id's parking slot for site (parking.parking_slot) */
void controller_parking_slot(Controller *c, int site, double *x, double *y);
Controller *controller_instance(void); /* the one static controller of this program */

struct Controller {
    int robot_id;
    char name[16];
    ControllerConfig config;
    Stream rng;
    int n;
    double site_x[MAX_OPTIONS], site_y[MAX_OPTIONS];
    double view_x[MAX_OPTIONS], view_y[MAX_OPTIONS];
    double site_angle[MAX_OPTIONS];
    double nest_x, nest_y, nest_radius, arena_radius, robot_radius;
    /* motion */
    Navigator nav;
    double leg_start;
    int has_allowance;
    double allowance, best_distance, last_progress;
    /* sensing */
    double sense_site_x, sense_site_y;
    int attempts;
    int has_capture_time;
    double capture_time, aim;
    /* parking */
    double inner_radius;
    int has_slot;
    double slot_x, slot_y;
    long park_retries;
    int has_backoff;
    double backoff_x, backoff_y, backoff_until;
    /* beliefs */
    double opinion[MAX_OPTIONS];
    int64_t trips, poolings, last_pool_size;
    int has_comparison;
    Comparison comparison;
    int decided_site; /* -1: none */
    double decision_time;
    int64_t decision_trips;
    HeardEntry heard[MAX_HEARD];
    int heard_count, heard_slots;
    int free_slots[MAX_HEARD], free_count;
    double heard_arena[HEARD_DOUBLES];
    /* the trimmed defence's peers: the latest opinion of every peer */
    HeardEntry peers[MAX_HEARD];
    int peer_count, peer_slots;
    double peer_arena[HEARD_DOUBLES];
    long dropped_heard;
    int64_t rejected;
    /* trip state */
    int phase;
    int started;
    double t;
    int changed;
    int pair[2], pair_len;
    int visited[2];
    double qualities[2];
    int quality_count;
    int has_last_beacon;
    double last_beacon;
    double nest_arrival, dwell_end, listen_from, explore_until;
    int exploring;
    double next_broadcast, linger_end;
};
#endif
