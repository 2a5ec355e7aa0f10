#include "endpoint.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "auth.h"
#include "log.h"
#include "png.h"

static uint8_t arena[PENDING_BYTES + PENDING_MESSAGES * (sizeof(Sense) + 16)];

void endpoint_reject(Endpoint *e, const char *source, const char *why) {
    static char logged[LOGGED_SOURCES][80];
    static int logged_count;
    e->rejects += 1;
    for (int i = 0; i < logged_count; i++)
        if (!strcmp(logged[i], source)) return;
    if (logged_count < LOGGED_SOURCES) snprintf(logged[logged_count++], sizeof logged[0], "%s", source);
    log_warning("dropped an invalid message from robot %d %s: %s (further ones not logged)",
                e->robot_id, source, why);
}

int endpoint_init(Endpoint *e, int robot_id, const char *root, const char *run,
                  const uint8_t key[32], const WorldInfo *world, const ControllerConfig *config,
                  const char **why) {
    memset(e, 0, sizeof *e);
    e->robot_id = robot_id;
    snprintf(e->identity, sizeof e->identity, "robot/%d", robot_id);
    memcpy(e->key, key, 32);
    snprintf(e->key_sense, sizeof e->key_sense, "%s/%s/robot/%d/sense", root, run, robot_id);
    snprintf(e->key_radio_rx, sizeof e->key_radio_rx, "%s/%s/radio/rx/%d", root, run, robot_id);
    snprintf(e->key_camera, sizeof e->key_camera, "%s/%s/robot/%d/camera", root, run, robot_id);
    snprintf(e->key_radio_tx, sizeof e->key_radio_tx, "%s/%s/radio/tx/%d", root, run, robot_id);
    snprintf(e->key_act, sizeof e->key_act, "%s/%s/robot/%d/act", root, run, robot_id);
    snprintf(e->key_status, sizeof e->key_status, "%s/%s/robot/%d/status", root, run, robot_id);
    e->dt = world->dt;
    e->lockstep = world->lockstep;
    e->last_tick = -1;
    e->controller = controller_instance();
    uint64_t seed = seed_of_robot((uint64_t)world->seed, (unsigned)robot_id);
    return controller_init(e->controller, robot_id, world, config, seed, why);
}

/* --- bestofn_swarm/wire/guard.py ------------------------------------------------------------------ */

static int isclose(double a, double b, double rel_tol, double abs_tol) {
    if (a == b) return 1;
    if (isinf(a) || isinf(b)) return 0;
    double diff = fabs(b - a);
    return diff <= fabs(rel_tol * b) || diff <= fabs(rel_tol * a) || diff <= abs_tol;
}

static int time_refused(int64_t tick, double t, double dt) {
    double expected = (double)tick * dt;
    return !isclose(t, expected, 1e-9, 1e-6);
}

/* --- the world follower (WorldFollower) ---------------------------------------------- */

static int present_index(Endpoint *e, const char *instance) {
    for (int i = 0; i < e->present_count; i++)
        if (!strcmp(e->present[i], instance)) return i;
    return -1;
}

static int followed_lost(Endpoint *e) {
    return e->has_followed && present_index(e, e->followed) < 0;
}

static void forget_pending(Endpoint *e) {
    e->item_count = 0;
    e->arena_used = 0;
    e->pending_bytes = 0;
}

void endpoint_world_appeared(Endpoint *e, const char *instance) {
    int back = e->has_followed && !strcmp(instance, e->followed) && followed_lost(e);
    if (present_index(e, instance) < 0 && e->present_count < MAX_WORLDS)
        snprintf(e->present[e->present_count++], sizeof e->present[0], "%s", instance);
    if (!e->has_followed) {
        e->has_followed = 1;
        snprintf(e->followed, sizeof e->followed, "%s", instance);
        return;
    }
    if (!strcmp(instance, e->followed)) {
        if (back) {
            log_warning("robot %d: the world server is back; resuming", e->robot_id);
            forget_pending(e); /* rejoin: take its next tick however far ahead */
            e->rejoined = 1;
        }
        return;
    }
    if (present_index(e, e->followed) >= 0) {
        log_warning("robot %d: ignoring a second world token %s while following %s",
                    e->robot_id, instance, e->followed);
        return;
    }
    snprintf(e->followed, sizeof e->followed, "%s", instance);
    log_warning("robot %d: a new world server appeared; resuming", e->robot_id);
    forget_pending(e); /* follow_new_world: ticks count from zero again */
    e->last_tick = -1;
    e->rejoined = 0;
    e->time_offset = e->last_t;
}

void endpoint_world_vanished(Endpoint *e, const char *instance) {
    int i = present_index(e, instance);
    if (i >= 0) {
        memmove(e->present[i], e->present[i + 1], sizeof e->present[0] * (size_t)(e->present_count - i - 1));
        e->present_count--;
    }
    if (e->has_followed && !strcmp(instance, e->followed))
        log_warning("robot %d lost the world server; waiting", e->robot_id);
}

/* a world token no world answered for: someone else's, ignored and counted */
void endpoint_world_unproven(Endpoint *e, const char *instance) {
    char why[MAX_NAME + 40];
    snprintf(why, sizeof why, "no world answers for '%s'", instance);
    endpoint_reject(e, "world token", why);
}

/* --- the tick assembly --------------------------------------------------------------- */

/* Room for one input of tick: 1 held (then *item), 0 stale, -1 refused (counted). */
static int admit(Endpoint *e, int64_t tick, size_t charged, size_t stored, PendingItem **item,
                 const char **why) {
    if (!(tick > e->last_tick)) return 0;
    if (e->last_tick >= 0 && !e->rejoined && tick > e->last_tick + TICK_WINDOW) {
        *why = "the tick is too far ahead of the last one";
        return -1;
    }
    if (e->pending_bytes + charged > PENDING_BYTES || e->item_count >= PENDING_MESSAGES) {
        *why = "more than the pending budget waiting";
        return -1;
    }
    if (e->arena_used + stored > sizeof arena) {
        *why = "more than the pending budget waiting";
        return -1;
    }
    PendingItem *it = &e->items[e->item_count++];
    it->tick = tick;
    it->offset = e->arena_used;
    it->size = stored;
    it->charged = charged;
    it->sender[0] = 0;
    e->arena_used += stored;
    e->pending_bytes += charged;
    *item = it;
    return 1;
}

static void drop_where(Endpoint *e, int64_t below, int64_t also) {
    /* remove the items of ticks < below, and of tick also; compact the arena */
    int kept = 0;
    size_t used = 0;
    for (int i = 0; i < e->item_count; i++) {
        PendingItem it = e->items[i];
        if (it.tick < below || it.tick == also) {
            e->pending_bytes -= it.charged;
            continue;
        }
        if (it.offset != used) memmove(arena + used, arena + it.offset, it.size);
        it.offset = used;
        used += it.size;
        e->items[kept++] = it;
    }
    e->item_count = kept;
    e->arena_used = used;
}

/* --- the step (SimulatedPorts.answer, ports.control_step, RobotEndpoint._step) ------- */

static uint8_t tx_payload[RADIO_TX_BYTES], tx_attachment[256], act_payload[256], act_attachment[32];
static uint8_t status_payload[STATUS_BYTES], status_attachment[32];

typedef struct {
    Endpoint *e;
    const PendingItem **rx;
    int count, at;
} RxCursor;

/* decode_received, one message at a time: invalid payloads dropped and counted */
static int next_heard(void *ctx, Heard *out) {
    static RadioPayload payload;
    RxCursor *cursor = ctx;
    while (cursor->at < cursor->count) {
        const PendingItem *it = cursor->rx[cursor->at++];
        if (!decode_radio(arena + it->offset, it->size, &payload)) {
            endpoint_reject(cursor->e, it->sender, "not a valid radio payload");
            continue;
        }
        out->sender = it->sender;
        out->payload = &payload;
        return 1;
    }
    return 0;
}

Outgoing endpoint_status(Endpoint *e, int64_t tick) {
    static double opinion[MAX_OPTIONS];
    StatusOut s;
    controller_status(e->controller, tick, &s, opinion);
    s.rejected += e->rejects;
    int n = encode_status(&s, (char *)status_payload, sizeof status_payload);
    Outgoing out = {OUT_STATUS, status_payload, (size_t)(n > 0 ? n : 0), status_attachment, 16};
    auth_seal(e->key, e->key_status, status_payload, out.payload_size, NULL, 0,
              status_attachment, sizeof status_attachment);
    return out;
}

static int step(Endpoint *e, const Sense *sense_in, const PendingItem **rx, int rx_count,
                const PendingItem *frame, Outgoing *out, int out_cap) {
    Sense sense = *sense_in;
    if (e->time_offset != 0.0) sense.t = sense.t + e->time_offset;
    e->last_t = sense.t;
    /* Body.read: the reading, the frame decoded (a frame that is no image: counted) */
    Reading reading;
    reading.t = sense.t;
    reading.x = sense.x;
    reading.y = sense.y;
    reading.theta = sense.theta;
    memcpy(reading.proximity, sense.prox, sizeof reading.proximity);
    reading.frame = NULL;
    static Image image;
    if (frame != NULL) {
        const char *why;
        if (png_decode(arena + frame->offset, frame->size, &image, &why) == 0)
            reading.frame = &image;
        else
            endpoint_reject(e, "camera", why);
    }
    /* Radio.poll, then decode_received as the controller listens */
    RxCursor cursor = {e, rx, rx_count, 0};
    static Command command;
#ifdef STEP_PROBE
    step_probe(1);
#endif
    controller_step(e->controller, &reading, next_heard, &cursor, &command);
#ifdef STEP_PROBE
    step_probe(0);
#endif
    e->steps += 1;
    e->left = command.left;
    e->right = command.right;
    int count = 0;
    int64_t radio_tx = 0;
    if (command.broadcast) {
        int n = encode_opinion(command.id, command.trip, command.decided, command.opinion,
                               command.n, (char *)tx_payload, sizeof tx_payload);
        e->radio_seq += 1;
        char meta[96];
        int m = encode_radio_tx_meta(sense.tick, e->radio_seq, meta, sizeof meta);
        long a = auth_seal(e->key, e->key_radio_tx, tx_payload, (size_t)n, (const uint8_t *)meta,
                           (size_t)m, tx_attachment, sizeof tx_attachment);
        if (count < out_cap)
            out[count++] = (Outgoing){OUT_RADIO_TX, tx_payload, (size_t)n, tx_attachment, (size_t)a};
        radio_tx = 1;
    }
    Act act = {sense.tick, command.left, command.right, command.capture, radio_tx};
    int n = encode_act(&act, (char *)act_payload, sizeof act_payload);
    auth_seal(e->key, e->key_act, act_payload, (size_t)n, NULL, 0, act_attachment,
              sizeof act_attachment);
    if (count < out_cap)
        out[count++] = (Outgoing){OUT_ACT, act_payload, (size_t)n, act_attachment, 16};
    if (controller_take_status_change(e->controller) && count < out_cap)
        out[count++] = endpoint_status(e, sense.tick);
    return count;
}

static int take_ready(Endpoint *e, int64_t tick, Outgoing *out, int out_cap) {
    static const PendingItem *rx[PENDING_MESSAGES];
    const PendingItem *sense_item = NULL, *frame = NULL;
    int rx_count = 0;
    for (int i = 0; i < e->item_count; i++) {
        const PendingItem *it = &e->items[i];
        if (it->tick != tick) continue;
        if (it->kind == IN_SENSE) sense_item = it;
        else if (it->kind == IN_CAMERA) frame = it;
    }
    if (sense_item == NULL) return 0;
    Sense sense;
    memcpy(&sense, arena + sense_item->offset, sizeof sense);
    if (e->lockstep) {
        for (int i = 0; i < e->item_count; i++)
            if (e->items[i].tick == tick && e->items[i].kind == IN_RADIO_RX)
                rx[rx_count++] = &e->items[i];
        if (rx_count < sense.rx || (frame == NULL && sense.camera)) return 0;
    } else {
        /* real time: the radio of earlier ticks in front (by tick), and the latest of
           their frames if this tick has none */
        int64_t at = -1;
        while (1) { /* each earlier tick in order */
            int64_t next = INT64_MAX;
            for (int i = 0; i < e->item_count; i++)
                if (e->items[i].tick > at && e->items[i].tick < tick && e->items[i].tick < next)
                    next = e->items[i].tick;
            if (next == INT64_MAX) break;
            for (int i = 0; i < e->item_count; i++)
                if (e->items[i].tick == next && e->items[i].kind == IN_RADIO_RX)
                    rx[rx_count++] = &e->items[i];
            at = next;
        }
        if (frame == NULL) {
            int64_t latest = -1;
            for (int i = 0; i < e->item_count; i++) {
                const PendingItem *it = &e->items[i];
                if (it->kind == IN_CAMERA && it->tick < tick && it->tick >= latest) {
                    latest = it->tick;
                    frame = it; /* the last one held for the latest tick */
                }
            }
        }
        for (int i = 0; i < e->item_count; i++)
            if (e->items[i].tick == tick && e->items[i].kind == IN_RADIO_RX)
                rx[rx_count++] = &e->items[i];
    }
    e->last_tick = tick; /* ticks.acted */
    e->rejoined = 0;
    int count = step(e, &sense, rx, rx_count, frame, out, out_cap);
    drop_where(e, tick, tick); /* the older ticks (never completed) and this one */
    return count;
}

int endpoint_receive(Endpoint *e, int kind, const uint8_t *payload, size_t payload_size,
                     const uint8_t *attachment, size_t attachment_size, Outgoing *out,
                     int out_cap) {
    static const char *const sources[] = {"sense", "radio/rx", "camera"};
    const char *key = kind == IN_SENSE ? e->key_sense : kind == IN_RADIO_RX ? e->key_radio_rx
                                                                            : e->key_camera;
    const uint8_t *metadata;
    size_t metadata_size;
    if (auth_open(e->key, key, payload, payload_size, attachment, attachment_size, &metadata,
                  &metadata_size) != 0) {
        endpoint_reject(e, sources[kind], "not tagged by its own key");
        return 0;
    }
    PendingItem *item;
    const char *why = "not a valid message";
    int64_t tick;
    int held;
    if (kind == IN_SENSE) {
        Sense sense;
        if (!decode_sense(payload, payload_size, &sense)) {
            endpoint_reject(e, sources[kind], why);
            return 0;
        }
        if (time_refused(sense.tick, sense.t, e->dt)) {
            endpoint_reject(e, sources[kind], "sim time is not the tick's");
            return 0;
        }
        tick = sense.tick;
        held = admit(e, tick, 0, sizeof sense, &item, &why);
        if (held == 1) {
            item->kind = IN_SENSE;
            memcpy(arena + item->offset, &sense, sizeof sense);
        }
    } else if (kind == IN_RADIO_RX) {
        RadioRxMeta meta;
        if (!decode_radio_rx_meta(metadata, metadata_size, &meta)) {
            endpoint_reject(e, sources[kind], why);
            return 0;
        }
        tick = meta.tick;
        held = admit(e, tick, payload_size, payload_size, &item, &why);
        if (held == 1) {
            item->kind = IN_RADIO_RX;
            snprintf(item->sender, sizeof item->sender, "%s", meta.sender);
            memcpy(arena + item->offset, payload, payload_size);
        }
    } else {
        CameraMeta meta;
        if (!decode_camera_meta(metadata, metadata_size, &meta)) {
            endpoint_reject(e, sources[kind], why);
            return 0;
        }
        tick = meta.tick;
        held = admit(e, tick, payload_size, payload_size, &item, &why);
        if (held == 1) {
            item->kind = IN_CAMERA;
            memcpy(arena + item->offset, payload, payload_size);
        }
    }
    if (held < 0) {
        endpoint_reject(e, sources[kind], why);
        return 0;
    }
    if (held == 0) return 0;
    return take_ready(e, tick, out, out_cap);
}
