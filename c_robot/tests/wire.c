/* auth.json, link_frame.json and the message files a robot decodes or encodes. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "auth.h"
#include "client.h"
#include "link.h"
#include "messages.h"
#include "sha256.h"
#include "tests.h"

static unsigned char buf[70000], buf2[140000];

void test_auth(void) {
    JNode *root = load("auth.json");
    if (!root) return;
    unsigned char secret[32], key[32], want[64];
    jdom_hex(jdom_str(root, "secret_hex"), secret, 32);
    JNode *keys = jdom_get(root, "keys");
    for (size_t i = 0; i < keys->count; i++) {
        const char *identity = jdom_str(keys->items[i], "identity");
        auth_derive_key(secret, identity, key);
        jdom_hex(jdom_str(keys->items[i], "key_hex"), want, 32);
        check(!memcmp(key, want, 32), "auth.json key", identity);
        check(is_identity(identity, strlen(identity)), "auth.json identity", identity);
    }
    JNode *tags = jdom_get(root, "tags");
    for (size_t i = 0; i < tags->count; i++) {
        JNode *t = tags->items[i];
        auth_derive_key(secret, jdom_str(t, "identity"), key);
        const char *meta = jdom_str(t, "metadata_utf8"), *payload = jdom_str(t, "payload_utf8");
        unsigned char tag[16], attachment[512];
        auth_tag(key, jdom_str(t, "key_expr"), (const unsigned char *)meta, strlen(meta),
                 (const unsigned char *)payload, strlen(payload), tag);
        jdom_hex(jdom_str(t, "tag_hex"), want, 16);
        check(!memcmp(tag, want, 16), "auth.json tag", jdom_str(t, "name"));
        size_t n = jdom_hex(jdom_str(t, "attachment_hex"), attachment, sizeof attachment);
        const unsigned char *m;
        size_t mn;
        int ok = auth_open(key, jdom_str(t, "key_expr"), (const unsigned char *)payload,
                           strlen(payload), attachment, n, &m, &mn) == 0 &&
                 mn == strlen(meta) && !memcmp(m, meta, mn);
        check(ok, "auth.json open", jdom_str(t, "name"));
        attachment[3] ^= 1;
        check(auth_open(key, jdom_str(t, "key_expr"), (const unsigned char *)payload,
                        strlen(payload), attachment, n, &m, &mn) != 0,
              "auth.json forged", jdom_str(t, "name"));
    }
    const char *bad[] = {"robot/01", "robot/100000", "host/5-3", "beacon/", "nobody", "robot/-1"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++)
        check(!is_identity(bad[i], strlen(bad[i])), "identity refused", bad[i]);
    const char *good[] = {"robot/0", "robot/99999", "host/3-4", "beacon/nest", "bridge"};
    for (size_t i = 0; i < sizeof good / sizeof good[0]; i++)
        check(is_identity(good[i], strlen(good[i])), "identity", good[i]);
}

static int frame_count;
static unsigned char deframed[70000];
static size_t deframed_size;
static int deframed_refusal;
static void collect(void *ctx, unsigned char *frame, size_t size, int refusal) {
    (void)ctx;
    frame_count++;
    deframed_refusal = refusal;
    if (frame) {
        memcpy(deframed, frame, size);
        deframed_size = size;
    }
}

static unsigned char emitted[80000];
static size_t emitted_size;

static void emit(void *ctx, const unsigned char *bytes, size_t size) {
    (void)ctx;
    if (emitted_size + size <= sizeof emitted) memcpy(emitted + emitted_size, bytes, size);
    emitted_size += size;
}

static const char *type_names[] = {"", "HELLO", "WELCOME", "DATA", "PING", "PONG", "BYE"};
static Deframer deframer;

/* A robot in the state receivers.robot of link_frame.json gives: robot 8, its hello said
   with the file's robot nonce, and the welcome of its session taken (none: "hello"). */
static LinkRobot receiver;

static size_t valid_frame(JNode *root, const char *name, unsigned char *out, size_t cap) {
    JNode *valid = jdom_get(root, "valid");
    for (size_t i = 0; i < valid->count; i++)
        if (!strcmp(jdom_str(valid->items[i], "name"), name))
            return jdom_hex(jdom_str(valid->items[i], "hex"), out, cap);
    return 0;
}

static void robot_in(JNode *root, const char *session, const unsigned char robot_key[32]) {
    static unsigned char welcome[4096];
    link_robot_init(&receiver, 8, "demo", robot_key);
    jdom_hex(jdom_str(root, "robot_nonce_hex"), receiver.client.robot_nonce, 8);
    link_robot_wake(&receiver, 0.0); /* its hello */
    if (strcmp(session, "hello") != 0) {
        const char *name = !strcmp(session, "plain") ? "welcome" : "welcome_encrypted";
        size_t n = valid_frame(root, name, welcome, sizeof welcome);
        link_robot_receive(&receiver, welcome, n, 0.0);
        check(receiver.client.open, "link_frame.json receiver", name);
    }
    client_clear(&receiver.client);
}

/* the counter one frame adds one to (R_NONE: taken; -1: more than one) */
static int refusal_of(const unsigned char *data, size_t size) {
    static unsigned char copy[70000]; /* the robot decrypts in place */
    long before[R_COUNT];
    memcpy(before, receiver.client.refused, sizeof before);
    memcpy(copy, data, size);
    link_robot_receive(&receiver, copy, size, 0.0);
    client_clear(&receiver.client);
    int found = R_NONE;
    long added = 0;
    for (int i = 0; i < R_COUNT; i++) {
        if (receiver.client.refused[i] != before[i]) found = i;
        added += receiver.client.refused[i] - before[i];
    }
    return added > 1 ? -1 : found;
}

void test_link(void) {
    JNode *root = load("link_frame.json");
    if (!root) return;
    unsigned char robot_key[32], lk[32], sk[32], want[32];
    jdom_hex(jdom_str(root, "robot_key_hex"), robot_key, 32);
    link_key(robot_key, lk);
    jdom_hex(jdom_str(root, "link_key_hex"), want, 32);
    check(!memcmp(lk, want, 32), "link_frame.json", "link key");
    unsigned char rn[8] = {1, 2, 3, 4, 5, 6, 7, 8}, bn[8] = {0x11, 0x12, 0x13, 0x14, 0x15, 0x16, 0x17, 0x18};
    session_key(lk, rn, bn, sk);
    jdom_hex(jdom_str(root, "session_key_hex"), want, 32);
    check(!memcmp(sk, want, 32), "link_frame.json", "session key");
    JNode *valid = jdom_get(root, "valid");
    for (size_t i = 0; i < valid->count; i++) {
        JNode *v = valid->items[i];
        const char *name = jdom_str(v, "name");
        size_t n = jdom_hex(jdom_str(v, "hex"), buf, sizeof buf);
        int encrypted = jdom_get(v, "encrypted")->boolean;
        Frame f;
        static unsigned char plain[70000];
        int refusal = link_open(buf, n, lk, encrypted ? sk : NULL, plain, &f);
        if (!refusal) refusal = link_check_body(&f);
        check(refusal == R_NONE, "link_frame.json valid opens", name);
        if (refusal) continue;
        unsigned char body[70000], rnonce[8], bnonce[8];
        size_t bs = jdom_hex(jdom_str(v, "body_hex"), body, sizeof body);
        jdom_hex(jdom_str(v, "robot_nonce_hex"), rnonce, 8);
        jdom_hex(jdom_str(v, "bridge_nonce_hex"), bnonce, 8);
        int ok = !strcmp(type_names[f.type], jdom_str(v, "type")) &&
                 f.from_bridge == jdom_get(v, "from_bridge")->boolean &&
                 f.robot == (unsigned)jdom_get(v, "robot")->integer &&
                 !memcmp(f.robot_nonce, rnonce, 8) && !memcmp(f.bridge_nonce, bnonce, 8) &&
                 f.seq == (unsigned long long)jdom_get(v, "seq")->integer &&
                 f.body_size == bs && !memcmp(f.body, body, bs) && f.encrypted == encrypted;
        check(ok, "link_frame.json valid reads as", name);
        Frame g = f;
        g.body = body;
        long sealed = link_seal(&g, lk, encrypted ? sk : NULL, buf2, sizeof buf2);
        check(sealed == (long)n && !memcmp(buf2, buf, n), "link_frame.json seals to its bytes", name);
        unsigned char serial[80000], want_serial[80000];
        long sn = serial_encode(buf, n, serial, sizeof serial);
        size_t wn = jdom_hex(jdom_str(v, "serial_hex"), want_serial, sizeof want_serial);
        check(sn == (long)wn && !memcmp(serial, want_serial, wn), "link_frame.json serial", name);
        emitted_size = 0; /* the same bytes made one block at a time, as firmware sends them */
        serial_encode_each(buf, n, emit, NULL);
        check(emitted_size == wn && !memcmp(emitted, want_serial, wn),
              "link_frame.json serial, block by block", name);
        frame_count = 0;
        deframer.used = 0;
        deframer.overflowed = 0;
        /* fed in two pieces: a frame may arrive in any chunks */
        deframer_feed(&deframer, serial, (size_t)sn / 2, collect, NULL);
        deframer_feed(&deframer, serial + sn / 2, (size_t)sn - (size_t)sn / 2, collect, NULL);
        check(frame_count == 1 && deframed_refusal == R_NONE && deframed_size == n &&
                  !memcmp(deframed, buf, n),
              "link_frame.json deframes", name);
        JNode *data = jdom_get(v, "data");
        if (data && data->type == J_OBJ) {
            int kind;
            const unsigned char *payload, *attachment;
            size_t ps, as;
            int r = link_decode_data(f.body, f.body_size, &kind, &payload, &ps, &attachment, &as);
            unsigned char att[2000];
            size_t an = jdom_hex(jdom_str(data, "attachment_hex"), att, sizeof att);
            const char *pu = jdom_str(data, "payload_utf8");
            ok = r == R_NONE && kind == jdom_get(data, "kind_byte")->integer && ps == strlen(pu) &&
                 !memcmp(payload, pu, ps) && as == an && (an == 0 || !memcmp(attachment, att, an));
            check(ok, "link_frame.json data", name);
            unsigned char again[70000];
            long en = link_encode_data(kind, payload, ps, attachment, as, again, sizeof again);
            check(en == (long)f.body_size && !memcmp(again, f.body, f.body_size),
                  "link_frame.json data encodes", name);
        }
        if (f.type == F_WELCOME) {
            LinkWelcome w;
            check(decode_welcome(f.body, f.body_size, &w) && !strcmp(w.run, "demo") &&
                      w.ping_every == 0.5 && w.silence == 3.0 &&
                      w.encrypted == (strstr(jdom_str(v, "body_utf8"), "chacha20") != NULL) &&
                      w.controller_size == strlen("{\"dwell\":3.0}"),
                  "link_frame.json welcome", name);
            ControllerConfig c;
            char error[200];
            check(decode_controller_config(w.controller, w.controller_size, &c, error, sizeof error) == 0 &&
                      c.dwell == 3.0 && c.broadcast_period == 0.5,
                  "welcome's controller settings", name);
        }
    }
    /* each end's counters: what the robot (this program) adds a frame to, in the state the
       file gives (receivers.robot) */
    JNode *invalid = jdom_get(root, "invalid");
    for (size_t i = 0; i < invalid->count; i++) {
        JNode *v = invalid->items[i];
        size_t n = jdom_hex(jdom_str(v, "hex"), buf, sizeof buf);
        robot_in(root, jdom_str(v, "session"), robot_key);
        int refusal = refusal_of(buf, n);
        const char *want = jdom_str(jdom_get(v, "refusal"), "robot");
        check(refusal > R_NONE && !strcmp(refusal_names[refusal], want),
              "link_frame.json invalid: the robot's counter", jdom_str(v, "name"));
    }
    JNode *sequences = jdom_get(root, "sequences");
    for (size_t i = 0; i < sequences->count; i++) {
        JNode *s = sequences->items[i];
        if (strcmp(jdom_str(s, "receiver"), "robot") != 0) continue;
        robot_in(root, jdom_str(s, "session"), robot_key);
        JNode *frames = jdom_get(s, "frames");
        int ok = 1;
        for (size_t k = 0; k < frames->count; k++) {
            JNode *item = frames->items[k];
            size_t n = jdom_hex(jdom_str(item, "hex"), buf, sizeof buf);
            int refusal = refusal_of(buf, n);
            JNode *want = jdom_get(item, "refused");
            ok &= want->type == J_NULL ? refusal == R_NONE
                                       : refusal > R_NONE && !strcmp(refusal_names[refusal], want->str);
        }
        check(ok, "link_frame.json sequence", jdom_str(s, "name"));
    }
    /* the bridge's frames are taken by a robot in their session */
    for (size_t i = 0; i < valid->count; i++) {
        JNode *v = valid->items[i];
        if (!jdom_get(v, "from_bridge")->boolean) continue;
        size_t n = jdom_hex(jdom_str(v, "hex"), buf, sizeof buf);
        const char *type = jdom_str(v, "type");
        robot_in(root,
                 !strcmp(type, "WELCOME") ? "hello"
                 : jdom_get(v, "encrypted")->boolean ? "encrypted"
                                                     : "plain",
                 robot_key);
        check(refusal_of(buf, n) == R_NONE, "link_frame.json valid: taken by the robot",
              jdom_str(v, "name"));
    }
    /* kind 19 and kind 4: tag || nonce || identity, and tag || nonce, under the run key */
    for (size_t i = 0; i < valid->count; i++) {
        JNode *v = valid->items[i];
        JNode *data = jdom_get(v, "data");
        JNode *query = data && data->type == J_OBJ ? jdom_get(data, "query") : NULL;
        if (!query || query->type != J_OBJ) continue;
        unsigned char attachment[256], nonce[16], want_meta[128];
        size_t an = jdom_hex(jdom_str(data, "attachment_hex"), attachment, sizeof attachment);
        jdom_hex(jdom_str(query, "nonce_hex"), nonce, 16);
        size_t mn = jdom_hex(jdom_str(query, "metadata_hex"), want_meta, sizeof want_meta);
        const char *payload = jdom_str(data, "payload_utf8");
        const char *identity = jdom_str(query, "identity");
        const unsigned char *meta;
        size_t meta_size;
        int ok = auth_open(robot_key, jdom_str(query, "key_expr"), (const unsigned char *)payload,
                           strlen(payload), attachment, an, &meta, &meta_size) == 0 &&
                 meta_size == mn && !memcmp(meta, want_meta, mn) && !memcmp(meta, nonce, 16);
        if (!strcmp(jdom_str(data, "kind"), "INFO_QUERY"))
            ok &= meta_size == 16 + strlen(identity) && !memcmp(meta + 16, identity, strlen(identity));
        else
            ok &= meta_size == 16;
        check(ok, "link_frame.json world/info under the run key", jdom_str(v, "name"));
    }
    JNode *serial_invalid = jdom_get(root, "serial_invalid");
    for (size_t i = 0; i < serial_invalid->count; i++) {
        JNode *v = serial_invalid->items[i];
        size_t n = jdom_hex(jdom_str(v, "hex"), buf, sizeof buf);
        frame_count = 0;
        deframer.used = 0;
        deframer.overflowed = 0;
        deframer_feed(&deframer, buf, n, collect, NULL);
        check(frame_count == 1 && deframed_refusal != R_NONE &&
                  !strcmp(refusal_names[deframed_refusal], jdom_str(v, "category")),
              "link_frame.json serial_invalid", jdom_str(v, "name"));
    }
    /* COBS block by block around the 254-byte runs: every length from 1 to 800, without a
       zero, and with one zero at each of a few places, the same bytes as serial_encode */
    int same = 1;
    static unsigned char frame[800], whole[1000];
    for (size_t size = 1; size <= sizeof frame; size++) {
        for (size_t zero_at = 0; zero_at <= size; zero_at += zero_at < 4 ? 1 : 127) {
            memset(frame, 0x5A, size);
            if (zero_at < size) frame[zero_at] = 0;
            long wn = serial_encode(frame, size, whole, sizeof whole);
            emitted_size = 0;
            serial_encode_each(frame, size, emit, NULL);
            same &= wn == (long)emitted_size && !memcmp(whole, emitted, (size_t)wn);
        }
    }
    check(same, "serial", "COBS block by block is serial_encode, 254-byte runs included");
    /* the replay window: 63 behind the highest is taken, 64 behind refused */
    ReplayWindow w = {0, 0};
    replay_take(&w, 100);
    check(!replay_refuses(&w, 37) && replay_refuses(&w, 36) && replay_refuses(&w, 100) &&
              !replay_refuses(&w, 99) && !replay_refuses(&w, 101),
          "replay window", "63 behind taken, 64 behind refused");
    /* the deframer: idle zeros, an overlong chunk */
    frame_count = 0;
    deframer.used = 0;
    deframer.overflowed = 0;
    unsigned char zeros[3] = {0, 0, 0};
    deframer_feed(&deframer, zeros, 3, collect, NULL);
    check(frame_count == 0, "deframer", "consecutive zeros are idle fill");
    static unsigned char big[LINK_MAX_ENCODED_BYTES + 10];
    memset(big, 1, sizeof big);
    big[sizeof big - 1] = 0;
    deframer_feed(&deframer, big, sizeof big, collect, NULL);
    check(frame_count == 1 && deframed_refusal == R_OVERSIZE, "deframer", "overlong chunk");
}

/* --- messages ----------------------------------------------------------------------- */

static double num(JNode *m, const char *key) { return jdom_get(m, key)->num; }
static long long integer(JNode *m, const char *key) { return jdom_get(m, key)->integer; }

static int same_sense(const Sense *s, JNode *m) {
    JNode *prox = jdom_get(m, "prox");
    int ok = s->tick == integer(m, "tick") && s->t == num(m, "t") && s->x == num(m, "x") &&
             s->y == num(m, "y") && s->theta == num(m, "theta") && s->rx == integer(m, "rx") &&
             s->camera == jdom_get(m, "camera")->boolean && prox->count == 8;
    for (int i = 0; i < 8 && ok; i++) ok &= s->prox[i] == prox->items[i]->num;
    return ok;
}

static int same_world(const WorldInfo *w, JNode *m) {
    JNode *nest = jdom_get(m, "nest"), *sites = jdom_get(m, "sites"), *cam = jdom_get(m, "camera");
    int ok = !strcmp(w->run, jdom_str(m, "run")) && w->seed == integer(m, "seed") &&
             w->dt == num(m, "dt") && w->arena_radius == num(m, "arena_radius") &&
             w->nest_x == num(nest, "x") && w->nest_y == num(nest, "y") &&
             w->nest_radius == num(nest, "radius") && w->n_sites == (int)sites->count &&
             w->robot_radius == num(m, "robot_radius") && w->wheel_base == num(m, "wheel_base") &&
             w->max_wheel_speed == num(m, "max_wheel_speed") &&
             w->cam_width == integer(cam, "width") && w->cam_height == integer(cam, "height") &&
             w->cam_fov == num(cam, "fov") &&
             w->lockstep == !strcmp(jdom_str(m, "clock"), "lockstep");
    for (int i = 0; ok && i < w->n_sites; i++)
        ok &= w->sites[i].id == integer(sites->items[i], "id") &&
              w->sites[i].x == num(sites->items[i], "x") && w->sites[i].y == num(sites->items[i], "y");
    return ok;
}

/* Decode data as the file's type; compare with message (if given); re-encode where the
   robot encodes that type and compare with want (if given). */
static int decode_check(const char *type, const unsigned char *data, size_t size, JNode *m,
                        const unsigned char *want, size_t want_size) {
    static RadioPayload radio;
    static WorldInfo world;
    static char out[70000];
    int n = -2;
    if (!strcmp(type, "Sense")) {
        Sense s;
        if (!decode_sense(data, size, &s)) return 0;
        if (m && !same_sense(&s, m)) return 0;
    } else if (!strcmp(type, "CameraMeta")) {
        CameraMeta c;
        if (!decode_camera_meta(data, size, &c)) return 0;
        if (m && !(c.tick == integer(m, "tick") && c.width == integer(m, "width") &&
                   c.height == integer(m, "height") &&
                   c.jpeg == !strcmp(jdom_str(m, "encoding"), "jpeg")))
            return 0;
    } else if (!strcmp(type, "RadioRxMeta")) {
        RadioRxMeta r;
        if (!decode_radio_rx_meta(data, size, &r)) return 0;
        if (m && !(r.tick == integer(m, "tick") && !strcmp(r.sender, jdom_str(m, "sender")) &&
                   r.seq == integer(m, "seq") && r.sent_tick == integer(m, "sent_tick")))
            return 0;
    } else if (!strcmp(type, "RadioTxMeta")) {
        RadioTxMeta r;
        if (!decode_radio_tx_meta(data, size, &r)) return 0;
        if (m && !(r.tick == integer(m, "tick") && r.seq == integer(m, "seq"))) return 0;
        n = encode_radio_tx_meta(r.tick, r.seq, out, sizeof out);
    } else if (!strcmp(type, "Act")) {
        Act a;
        if (!decode_act(data, size, &a)) return 0;
        if (m && !(a.tick == integer(m, "tick") && a.left == num(m, "left") &&
                   a.right == num(m, "right") && a.capture == jdom_get(m, "capture")->boolean &&
                   a.radio_tx == integer(m, "radio_tx")))
            return 0;
        n = encode_act(&a, out, sizeof out);
    } else if (!strcmp(type, "WorldInfo")) {
        if (!decode_world_info(data, size, &world)) return 0;
        if (m && !same_world(&world, m)) return 0;
    } else if (!strcmp(type, "OpinionPayload") || !strcmp(type, "BeaconPayload") ||
               !strcmp(type, "VotePayload")) {
        if (!decode_radio(data, size, &radio)) return 0;
        int kind = !strcmp(type, "OpinionPayload") ? RADIO_OPINION
                   : !strcmp(type, "BeaconPayload") ? RADIO_BEACON : RADIO_VOTE;
        if (radio.kind != kind) return 0;
        if (m) {
            if (kind == RADIO_BEACON) {
                if (strcmp(radio.name, jdom_str(m, "id")) || radio.seq != integer(m, "seq")) return 0;
            } else {
                if (radio.id != integer(m, "id") || radio.trip != integer(m, "trip") ||
                    radio.decided != jdom_get(m, "decided")->boolean)
                    return 0;
                if (kind == RADIO_OPINION) {
                    JNode *o = jdom_get(m, "opinion");
                    if (radio.n != (int)o->count) return 0;
                    for (int i = 0; i < radio.n; i++)
                        if (radio.opinion[i] != o->items[i]->num) return 0;
                } else if (radio.site != integer(m, "site") || radio.quality != num(m, "quality")) {
                    return 0;
                }
            }
        }
        if (kind == RADIO_OPINION)
            n = encode_opinion(radio.id, radio.trip, radio.decided, radio.opinion, radio.n, out, sizeof out);
    } else if (!strcmp(type, "Status")) {
        if (check_message(type, data, size) != 1) return 0;
        if (m) {
            static double opinion[1000];
            StatusOut s;
            memset(&s, 0, sizeof s);
            s.id = integer(m, "id");
            s.tick = integer(m, "tick");
            s.t = num(m, "t");
            s.phase = jdom_str(m, "phase");
            s.trips = integer(m, "trips");
            JNode *o = jdom_get(m, "opinion");
            for (size_t i = 0; i < o->count; i++) opinion[i] = o->items[i]->num;
            s.opinion = opinion;
            s.n = (int)o->count;
            s.pool_size = integer(m, "pool_size");
            s.poolings = integer(m, "poolings");
            JNode *d = jdom_get(m, "decided_site");
            s.has_decided = d->type != J_NULL;
            s.decided_site = d->integer;
            d = jdom_get(m, "decision_time");
            s.has_decision_time = d->type != J_NULL;
            s.decision_time = d->num;
            d = jdom_get(m, "decision_trips");
            s.has_decision_trips = d->type != J_NULL;
            s.decision_trips = d->integer;
            d = jdom_get(m, "comparison");
            s.has_comparison = d->type != J_NULL;
            if (s.has_comparison) {
                s.comparison.site_a = integer(d, "site_a");
                s.comparison.quality_a = num(d, "quality_a");
                s.comparison.site_b = integer(d, "site_b");
                s.comparison.quality_b = num(d, "quality_b");
                s.comparison.eliminated = integer(d, "eliminated");
            }
            s.rejected = integer(m, "rejected");
            n = encode_status(&s, out, sizeof out);
        }
    } else {
        if (check_message(type, data, size) != 1) return 0;
    }
    if (want && n != -2) {
        if (n < 0 || (size_t)n != want_size || memcmp(out, want, want_size)) {
            printf("  encoded %.*s\n  wanted  %.*s\n", n, out, (int)want_size, want);
            return 0;
        }
    }
    return 1;
}

void test_messages(void) {
    const char *files[] = {"sense.json", "act.json", "status.json", "opinion_payload.json",
                           "beacon_payload.json", "vote_payload.json", "world_info.json",
                           "join_reply.json", "camera_meta.json", "radio_tx_meta.json",
                           "radio_rx_meta.json", "clock.json", "ack.json", "link_stats.json",
                           "log_line.json", "world_state.json"};
    static unsigned char data[70000], canonical[70000];
    for (size_t f = 0; f < sizeof files / sizeof files[0]; f++) {
        JNode *root = load(files[f]);
        if (!root) continue;
        const char *type = jdom_str(root, "type");
        JNode *valid = jdom_get(root, "valid");
        for (size_t i = 0; i < valid->count; i++) {
            JNode *v = valid->items[i];
            size_t n = jdom_hex(jdom_str(v, "hex"), data, sizeof data);
            char name[200];
            snprintf(name, sizeof name, "%s %s", files[f], jdom_str(v, "name"));
            check(decode_check(type, data, n, jdom_get(v, "message"), data, n), "valid", name);
        }
        JNode *accepted = jdom_get(root, "accepted");
        for (size_t i = 0; accepted && i < accepted->count; i++) {
            JNode *v = accepted->items[i];
            size_t n = jdom_hex(jdom_str(v, "hex"), data, sizeof data);
            size_t cn = jdom_hex(jdom_str(v, "canonical_hex"), canonical, sizeof canonical);
            char name[200];
            snprintf(name, sizeof name, "%s %s", files[f], jdom_str(v, "name"));
            int ok = decode_check(type, data, n, NULL, canonical, cn);
            /* and the canonical bytes decode to the same as the accepted ones */
            ok &= decode_check(type, canonical, cn, NULL, canonical, cn);
            check(ok, "accepted", name);
        }
        JNode *invalid = jdom_get(root, "invalid");
        for (size_t i = 0; i < invalid->count; i++) {
            JNode *v = invalid->items[i];
            size_t n = jdom_hex(jdom_str(v, "hex"), data, sizeof data);
            char name[200];
            snprintf(name, sizeof name, "%s %s (%s)", files[f], jdom_str(v, "name"),
                     jdom_str(v, "category"));
            check(!decode_check(type, data, n, NULL, NULL, 0), "invalid refused", name);
        }
        /* a worst case, where the file has one */
        JNode *worst = jdom_get(root, "worst_case_n100");
        if (worst && jdom_str(worst, "hex")) {
            size_t n = jdom_hex(jdom_str(worst, "hex"), data, sizeof data);
            check(decode_check(type, data, n, NULL, data, n), "worst case", files[f]);
        }
    }
    /* payloads over 64 KiB are refused before they are read */
    static unsigned char huge[MAX_PAYLOAD_BYTES + 2];
    memset(huge, ' ', sizeof huge);
    memcpy(huge, "{\"v\":1,\"tick\":1,\"t\":0.1}", 24);
    check(!check_message("Clock", huge, sizeof huge), "messages", "over 64 KiB refused");
    check(check_message("Clock", huge, 24 + 100), "messages", "whitespace after the object");
}

/* --- key files (key_file.json) ------------------------------------------------------ */

#include "keyfile.h"

/* each file read from its bytes, as the firmware reads its key record's: the key of robot 8
   and the run, or refused */
static void key_files_read(JNode *root) {
    unsigned char want[32];
    jdom_hex(jdom_str(root, "key_hex"), want, 32);
    JNode *valid = jdom_get(root, "valid");
    for (size_t i = 0; i < valid->count; i++) {
        const char *text = jdom_str(valid->items[i], "utf8");
        char run[MAX_NAME + 1];
        unsigned char key[32];
        const char *why;
        int ok = key_file_read((const uint8_t *)text, strlen(text), 8, run, key, &why) ==
                     KEY_FILE_OK &&
                 !memcmp(key, want, 32) && !strcmp(run, jdom_str(root, "run"));
        check(ok, "key_file.json valid: its key and run", jdom_str(valid->items[i], "name"));
    }
    JNode *invalid = jdom_get(root, "invalid");
    for (size_t i = 0; i < invalid->count; i++) {
        const char *text = jdom_str(invalid->items[i], "utf8");
        char run[MAX_NAME + 1];
        unsigned char key[32];
        const char *why;
        check(key_file_read((const uint8_t *)text, strlen(text), 8, run, key, &why) != KEY_FILE_OK,
              "key_file.json invalid: refused", jdom_str(invalid->items[i], "name"));
    }
}

#ifdef C_ROBOT_BARE_METAL
void test_key_files(void) {
    JNode *root = load("key_file.json");
    if (root) key_files_read(root);
}
#else
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

/* Run the c-robot next to the unit tests (through C_ROBOT_EMULATOR's command prefix, if
   set) on a key file against a UDP socket of this test: its exit code (it gives up after
   0.01 s without a bridge: 1; a key file it refuses: 2). */
static int run_program(const char *key_file, int port) {
    const char *emulator = getenv("C_ROBOT_EMULATOR");
    char command[3072];
    snprintf(command, sizeof command,
             "%s %s/c-robot --link udp://127.0.0.1:%d --id 8 --key-file %s"
             " --give-up 0.01 --log-level error >/dev/null 2>&1",
             emulator ? emulator : "", program_dir, port, key_file);
    int status = system(command);
    return status != -1 && WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

static int write_key_file(const char *key_file, const char *text) {
    FILE *file = fopen(key_file, "w");
    if (!file) return -1;
    fputs(text, file);
    fclose(file);
    return chmod(key_file, 0600);
}

/* ... and by the program itself, from a file (on Linux) */
void test_key_files(void) {
    JNode *root = load("key_file.json");
    if (!root) return;
    key_files_read(root);
    char program[1100], key_file[1100];
    snprintf(program, sizeof program, "%s/c-robot", program_dir);
    snprintf(key_file, sizeof key_file, "%s/key-file-vector.key", program_dir);
    if (access(program, X_OK) != 0) {
        check(0, "key_file.json", "c-robot is not built next to unit-tests (make -C c_robot)");
        return;
    }
    int fd = socket(AF_INET, SOCK_DGRAM, 0);
    struct sockaddr_in address;
    memset(&address, 0, sizeof address);
    address.sin_family = AF_INET;
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t length = sizeof address;
    if (fd < 0 || bind(fd, (struct sockaddr *)&address, sizeof address) != 0 ||
        getsockname(fd, (struct sockaddr *)&address, &length) != 0) {
        check(0, "key_file.json", "no UDP socket on 127.0.0.1");
        return;
    }
    int port = ntohs(address.sin_port);
    unsigned char key[32], lk[32];
    jdom_hex(jdom_str(root, "key_hex"), key, 32);
    link_key(key, lk);
    JNode *valid = jdom_get(root, "valid");
    for (size_t i = 0; i < valid->count; i++) {
        JNode *v = valid->items[i];
        while (recv(fd, buf, sizeof buf, MSG_DONTWAIT) > 0) {
        }
        int code = write_key_file(key_file, jdom_str(v, "utf8")) == 0
                       ? run_program(key_file, port)
                       : -1;
        /* its hello is tagged under the link key of the key the file holds */
        ssize_t n = recv(fd, buf, sizeof buf, MSG_DONTWAIT);
        Frame f;
        static unsigned char plain[70000];
        int ok = code == 1 && n > 0 && link_open(buf, (size_t)n, lk, NULL, plain, &f) == R_NONE &&
                 f.type == F_HELLO && f.robot == 8;
        check(ok, "key_file.json valid: read, and its key tags the hello", jdom_str(v, "name"));
    }
    JNode *invalid = jdom_get(root, "invalid");
    for (size_t i = 0; i < invalid->count; i++) {
        JNode *v = invalid->items[i];
        int code = write_key_file(key_file, jdom_str(v, "utf8")) == 0
                       ? run_program(key_file, port)
                       : -1;
        check(code == 2, "key_file.json invalid: exit code 2", jdom_str(v, "name"));
    }
    unlink(key_file);
    close(fd);
}
#endif
