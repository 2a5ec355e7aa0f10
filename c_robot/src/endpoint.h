/* The robot's end of the wire (robot_agent/core/endpoint.py, tick_assembly.py,
   simulated.py, ports.control_step; bestofn_swarm/wire/guard.py): checks every input, gathers ticks,
   steps the controller, seals what it sends. */
#ifndef CR_ENDPOINT_H
#define CR_ENDPOINT_H
#include <stddef.h>
#include <stdint.h>

#include "controller.h"
#include "messages.h"

#define TICK_WINDOW 100
#define MAX_WORLDS 16

enum InputKind { IN_SENSE, IN_RADIO_RX, IN_CAMERA };
enum OutputKind { OUT_RADIO_TX, OUT_ACT, OUT_STATUS };

typedef struct {
    int kind;
    const uint8_t *payload;
    size_t payload_size;
    const uint8_t *attachment;
    size_t attachment_size;
} Outgoing;

typedef struct {
    int64_t tick;
    uint8_t kind; /* IN_* */
    char sender[MAX_NAME + 1];
    size_t offset, size; /* in the arena; a sense: a Sense struct */
    size_t charged;      /* what the budget counts (0 for a sense) */
} PendingItem;

typedef struct {
    int robot_id;
    char identity[32];
    uint8_t key[32];
    char key_sense[160], key_radio_rx[160], key_camera[160];
    char key_radio_tx[160], key_act[160], key_status[160];
    double dt;
    int lockstep;
    int64_t rejects;
    /* the tick assembly */
    PendingItem items[PENDING_MESSAGES];
    int item_count;
    size_t arena_used, pending_bytes;
    int64_t last_tick;
    int rejoined;
    /* the world follower */
    int has_followed;
    char followed[MAX_NAME + 1];
    char present[MAX_WORLDS][MAX_NAME + 1];
    int present_count;
    double time_offset, last_t;
    int64_t radio_seq; /* SimulatedRadio.seq */
    Controller *controller;
    /* the steps taken, and the wheel speeds the last one commanded (a firmware's motors) */
    int64_t steps;
    double left, right;
} Endpoint;

/* 0, or -1 and why */
int endpoint_init(Endpoint *e, int robot_id, const char *root, const char *run,
                  const uint8_t key[32], const WorldInfo *world, const ControllerConfig *config,
                  const char **why);
/* Take one input; when it completes a step, the messages to send (transmissions, the act,
   the status if it changed) in out (static storage, valid until the next call); their
   count, or 0. */
int endpoint_receive(Endpoint *e, int kind, const uint8_t *payload, size_t payload_size,
                     const uint8_t *attachment, size_t attachment_size, Outgoing *out,
                     int out_cap);
/* the robot's status at tick, sealed (static storage) */
Outgoing endpoint_status(Endpoint *e, int64_t tick);
void endpoint_world_appeared(Endpoint *e, const char *instance);
void endpoint_world_vanished(Endpoint *e, const char *instance);
void endpoint_world_unproven(Endpoint *e, const char *instance);
void endpoint_reject(Endpoint *e, const char *source, const char *why);
#ifdef STEP_PROBE
/* a firmware times the controller's step: called just before (1) and after (0) it */
void step_probe(int begin);
#endif
#endif
