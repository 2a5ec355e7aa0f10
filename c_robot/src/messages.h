/* The project's messages (bestofn_swarm/wire/protocol.py) a robot decodes or encodes, with msgspec's
   checks: version, unknown and missing fields, types, bounds, lengths, names. */
#ifndef CR_MESSAGES_H
#define CR_MESSAGES_H
#include <stddef.h>
#include <stdint.h>

#include "limits.h"

/* The protocol's bound on sites (bestofn_swarm/wire/protocol.py MAX_OPTIONS): what is valid. What the
   robot holds is MAX_OPTIONS (limits.h), the same on the host. */
#define PROTOCOL_MAX_OPTIONS 1000
#define MAX_ROBOTS 100000
#define MAX_PAYLOAD_BYTES (64 * 1024)
#define MAX_NAME 64
#define MAX_TICK 9007199254740992LL /* 2^53 */
#define MAX_COUNT 9007199254740992LL

typedef struct {
    int64_t tick;
    double t, x, y, theta;
    double prox[8];
    int64_t rx;
    int camera;
} Sense;

typedef struct {
    int64_t tick, width, height;
    int jpeg; /* 0: png */
} CameraMeta;

typedef struct {
    int64_t tick;
    char sender[MAX_NAME + 1];
    int64_t seq, sent_tick;
} RadioRxMeta;

typedef struct {
    int64_t tick, seq;
} RadioTxMeta;

enum { RADIO_OPINION = 1, RADIO_BEACON = 2, RADIO_VOTE = 3 };

typedef struct {
    int kind;
    int64_t id; /* opinion, vote */
    char name[MAX_NAME + 1]; /* beacon id */
    int64_t trip, seq;
    int decided;
    int n;
    double opinion[MAX_OPTIONS];
    int64_t site;
    double quality;
} RadioPayload;

typedef struct {
    int64_t id;
    double x, y;
} Site;

typedef struct {
    char run[MAX_NAME + 1];
    int64_t seed;
    double dt, arena_radius;
    double nest_x, nest_y, nest_radius;
    int n_sites;
    Site sites[MAX_OPTIONS];
    double robot_radius, wheel_base, max_wheel_speed;
    int64_t cam_width, cam_height;
    double cam_fov;
    int lockstep;
} WorldInfo;

typedef struct {
    int64_t tick;
    double left, right;
    int capture;
    int64_t radio_tx;
} Act;

typedef struct {
    int64_t site_a;
    double quality_a;
    int64_t site_b;
    double quality_b;
    int64_t eliminated;
} Comparison;

typedef struct {
    int64_t id, tick;
    double t;
    const char *phase;
    int64_t trips;
    int n;
    const double *opinion; /* already at the wire's precision */
    int64_t pool_size, poolings;
    int has_decided;
    int64_t decided_site;
    int has_decision_time;
    double decision_time;
    int has_decision_trips;
    int64_t decision_trips;
    int has_comparison;
    Comparison comparison;
    int64_t rejected;
} StatusOut;

typedef struct {
    char run[MAX_NAME + 1];
    char root[MAX_NAME + 1];
    int encrypted;
    double ping_every, silence;
    const uint8_t *controller; /* the raw JSON object, inside the decoded body */
    size_t controller_size;
} LinkWelcome;

typedef struct {
    double alpha, threshold;
    int loglinear; /* pooling */
    double dwell, broadcast_period, linger;
    int strategy; /* 0 paper, 1 dmvd, 2 dmmd, 3 dc */
    double exploration, dissemination, listen;
    int64_t neighbours, settle;
    int trimmed; /* defence */
    int64_t trim;
    double view_distance, beacon_timeout, capture_timeout;
    int64_t capture_attempts;
    double view_tolerance, heading_tolerance, wiggle, nest_tolerance, stall_timeout,
        near_distance, travel_timeout, travel_crawl, park_clearance, park_spacing,
        park_corridor, park_lane;
} ControllerConfig;

int is_name(const char *text, size_t len);
int decode_sense(const void *data, size_t size, Sense *out);
int decode_camera_meta(const void *data, size_t size, CameraMeta *out);
int decode_radio_rx_meta(const void *data, size_t size, RadioRxMeta *out);
int decode_radio_tx_meta(const void *data, size_t size, RadioTxMeta *out);
/* decode_radio also checks that an opinion sums to 1 within 1e-6 (math.fsum) */
int decode_radio(const void *data, size_t size, RadioPayload *out);
int decode_world_info(const void *data, size_t size, WorldInfo *out);
int decode_act(const void *data, size_t size, Act *out);
int decode_welcome(const void *data, size_t size, LinkWelcome *out);
void controller_config_defaults(ControllerConfig *c);
/* returns 0 or -1 (and why in error) */
int decode_controller_config(const void *data, size_t size, ControllerConfig *out,
                             char *error, size_t error_size);
/* the other message types, decoded only to check them (conformance vectors) */
int check_message(const char *type, const void *data, size_t size);

/* encoders: the byte count, or -1 if it does not fit */
int encode_act(const Act *act, char *out, size_t cap);
int encode_radio_tx_meta(int64_t tick, int64_t seq, char *out, size_t cap);
int encode_opinion(int64_t id, int64_t trip, int decided, const double *opinion, int n,
                   char *out, size_t cap);
int encode_status(const StatusOut *s, char *out, size_t cap);
#endif
