#include "client.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "auth.h"
#include "entropy.h"
#include "json.h"
#include "log.h"

/* --- LinkClient ---------------------------------------------------------------------- */

/* the place of the body of a frame of body_size bytes at the end of the queue, or NULL
   when it does not fit */
static uint8_t *frame_room(LinkClient *c, size_t body_size) {
    size_t total = LINK_HEADER_BYTES + body_size + LINK_TAG_BYTES;
    if (c->frame_count >= OUT_QUEUE_FRAMES || c->queue_used + total > OUT_QUEUE_BYTES) return NULL;
    return c->queue + c->queue_used + LINK_HEADER_BYTES;
}

/* seal f at the end of the queue (its body may be there already: frame_room) */
static void queue_frame(LinkClient *c, const Frame *f) {
    if (f->body_size > LINK_MAX_BODY_BYTES) {
        c->refused[R_OVERSIZE]++;
        return;
    }
    if (frame_room(c, f->body_size) == NULL) {
        c->queue_dropped++;
        return;
    }
    long n = link_seal(f, c->key, c->has_cipher ? c->cipher_key : NULL, c->queue + c->queue_used,
                       OUT_QUEUE_BYTES - c->queue_used);
    c->queue_used += (size_t)n;
    c->frame_size[c->frame_count++] = (size_t)n;
}

const uint8_t *client_frame(LinkClient *c, int index, size_t *size) {
    if (index >= c->frame_count) return NULL;
    size_t offset = 0;
    for (int i = 0; i < index; i++) offset += c->frame_size[i];
    *size = c->frame_size[index];
    return c->queue + offset;
}

void client_clear(LinkClient *c) {
    c->frame_count = 0;
    c->queue_used = 0;
}

/* 0, or -1: no random bytes for the first nonce */
static int client_init(LinkClient *c, uint32_t robot, const uint8_t link_key_bytes[32]) {
    memset(c, 0, sizeof *c);
    c->robot = robot;
    memcpy(c->key, link_key_bytes, 32);
    c->silence = SILENCE_BEFORE_WELCOME;
    c->next_hello = 0.0;
    return entropy_bytes(c->robot_nonce, 8);
}

static double client_deadline(const LinkClient *c) {
    return c->open ? c->last_heard + c->silence : c->next_hello;
}

static void send_hello(LinkClient *c, double now) {
    Frame f;
    memset(&f, 0, sizeof f);
    f.type = F_HELLO;
    f.robot = c->robot;
    memcpy(f.robot_nonce, c->robot_nonce, 8);
    int saved = c->has_cipher;
    c->has_cipher = 0;
    queue_frame(c, &f);
    c->has_cipher = saved;
    c->next_hello = now + HELLO_EVERY;
}

static void session_send(LinkClient *c, int type, const uint8_t *body, size_t size) {
    c->sent_seq += 1;
    Frame f;
    memset(&f, 0, sizeof f);
    f.type = type;
    f.robot = c->robot;
    memcpy(f.robot_nonce, c->robot_nonce, 8);
    memcpy(f.bridge_nonce, c->bridge_nonce, 8);
    f.seq = c->sent_seq;
    f.body = body;
    f.body_size = size;
    f.encrypted = c->has_cipher;
    queue_frame(c, &f);
}

/* 0 or the refusal (counted); the DATA body is written straight into the queue */
static int client_send(LinkClient *c, int kind, const uint8_t *payload, size_t payload_size,
                       const uint8_t *attachment, size_t attachment_size) {
    if (!c->open) return -1;
    size_t size = 3 + attachment_size + payload_size;
    if (attachment_size > LINK_MAX_ATTACHMENT_BYTES || size > LINK_MAX_BODY_BYTES) {
        c->refused[R_OVERSIZE]++;
        return R_OVERSIZE;
    }
    uint8_t *body = frame_room(c, size);
    if (body == NULL) { /* its sequence number is spent, as for a frame the line lost */
        c->sent_seq += 1;
        c->queue_dropped++;
        return 0;
    }
    link_encode_data(kind, payload, payload_size, attachment, attachment_size, body, size);
    session_send(c, F_DATA, body, size);
    return 0;
}

/* say goodbye: the session ends at this end (a second bye would be refused) */
static void client_bye(LinkClient *c, int reason) {
    if (!c->open) return;
    uint8_t b = (uint8_t)reason;
    session_send(c, F_BYE, &b, 1);
    c->open = 0;
}

/* 0, or -1: no random bytes for the next session's nonce */
static int lose(LinkClient *c, const char *why, double now) {
    log_warning("robot %u: link session lost: %s", (unsigned)c->robot, why);
    c->open = 0;
    c->has_cipher = 0;
    c->next_hello = now;
    return entropy_bytes(c->robot_nonce, 8); /* a new session, a new nonce */
}

/* no random bytes for a nonce: the robot cannot go on (never an old or made-up nonce) */
static void no_entropy(LinkRobot *p) {
    log_error("robot %d: the platform gives no random bytes for a nonce: stopping", p->robot);
    p->fatal = 1;
    p->ended = 1;
}

/* --- LinkRobot ----------------------------------------------------------------------- */

int link_robot_init(LinkRobot *p, int robot, const char *run, const uint8_t robot_key[32]) {
    memset(p, 0, sizeof *p);
    p->robot = robot;
    snprintf(p->run, sizeof p->run, "%s", run);
    memcpy(p->robot_key, robot_key, 32);
    snprintf(p->identity, sizeof p->identity, "robot/%d", robot);
    uint8_t lk[32];
    link_key(robot_key, lk);
    static Endpoint endpoint;
    p->endpoint = &endpoint;
    return client_init(&p->client, (uint32_t)robot, lk);
}

double link_robot_deadline(const LinkRobot *p) {
    double deadline = client_deadline(&p->client);
    if (p->asking && p->ask_again_at < deadline) deadline = p->ask_again_at;
    for (int i = 0; i < p->proving_count; i++)
        if (p->proving[i].again_at < deadline) deadline = p->proving[i].again_at;
    if (p->has_last_status && p->status_again_at < deadline) deadline = p->status_again_at;
    return deadline;
}

static void send_status(LinkRobot *p, Outgoing status, double now) {
    client_send(&p->client, K_STATUS, status.payload, status.payload_size, status.attachment,
                status.attachment_size);
    if (status.payload != p->last_status && status.payload_size <= sizeof p->last_status) {
        memcpy(p->last_status, status.payload, status.payload_size);
        memcpy(p->last_status_attachment, status.attachment, status.attachment_size);
    }
    p->last_status_size = status.payload_size;
    p->has_last_status = 1;
    p->status_again_at = now + STATUS_EVERY;
}

static void resend_status(LinkRobot *p, double now) {
    Outgoing o = {OUT_STATUS, p->last_status, p->last_status_size, p->last_status_attachment, 16};
    send_status(p, o, now);
}

static void world_key(const LinkRobot *p, char *out, size_t cap) {
    snprintf(out, cap, "%s/%s/world/info", p->client.root, p->client.run);
}

const uint8_t *questions_latest(const Questions *q) { return q->nonces[q->count - 1]; }

static uint8_t *questions_add(Questions *q) {
    if (q->count == RECENT_QUESTIONS) {
        memmove(q->nonces[0], q->nonces[1], sizeof q->nonces[0] * (RECENT_QUESTIONS - 1));
        q->count--;
    }
    return q->nonces[q->count++];
}

static int questions_hold(const Questions *q, const uint8_t *nonce) {
    for (int i = 0; i < q->count; i++)
        if (!memcmp(q->nonces[i], nonce, 16)) return 1;
    return 0;
}

/* a question on world/info in the robot's name with a fresh nonce (auth.query_seal),
   sent: its payload names the world instance that must answer ("": any) */
static void question(LinkRobot *p, const char *instance, Questions *asked) {
    char key[200];
    uint8_t metadata[16 + 32], attachment[16 + 16 + 32], fresh[16];
    if (entropy_bytes(fresh, sizeof fresh) != 0) {
        no_entropy(p);
        return;
    }
    uint8_t *nonce = questions_add(asked);
    memcpy(nonce, fresh, sizeof fresh);
    world_key(p, key, sizeof key);
    size_t id = strlen(p->identity), size = strlen(instance);
    memcpy(metadata, nonce, 16);
    memcpy(metadata + 16, p->identity, id);
    long n = auth_seal(p->robot_key, key, (const uint8_t *)instance, size, metadata, 16 + id,
                       attachment, sizeof attachment);
    client_send(&p->client, K_INFO_QUERY, (const uint8_t *)instance, size, attachment, (size_t)n);
}

/* ask any world for the map */
static void ask(LinkRobot *p, double now) {
    if (!p->asking) p->asked.count = 0;
    question(p, "", &p->asked);
    p->asking = 1;
    p->ask_again_at = now + ASK_EVERY;
}

static int proving_index(const LinkRobot *p, const char *instance) {
    for (int i = 0; i < p->proving_count; i++)
        if (!strcmp(p->proving[i].instance, instance)) return i;
    return -1;
}

static void forget_proving(LinkRobot *p, int at) {
    memmove(&p->proving[at], &p->proving[at + 1],
            sizeof p->proving[0] * (size_t)(p->proving_count - at - 1));
    p->proving_count--;
}

/* ask world instance to answer for its token; after PROVE_TRIES questions without an
   answer that holds, the token is someone else's (counted) */
static void prove(LinkRobot *p, const char *instance, double now, int tries) {
    int at = proving_index(p, instance);
    if (tries > PROVE_TRIES) {
        if (at >= 0) forget_proving(p, at);
        endpoint_world_unproven(p->endpoint, instance);
        return;
    }
    if (at < 0) {
        if (p->proving_count >= MAX_WORLDS) return;
        at = p->proving_count++;
        snprintf(p->proving[at].instance, sizeof p->proving[at].instance, "%s", instance);
        p->proving[at].asked.count = 0;
    }
    question(p, instance, &p->proving[at].asked);
    p->proving[at].again_at = now + PROVE_EVERY;
    p->proving[at].tries = tries;
}

/* whether an answer on world/info is the world's answer to one of a question's askings */
static int holds(const LinkRobot *p, const Questions *asked, const uint8_t *payload, size_t size,
                 const uint8_t *attachment, size_t attachment_size) {
    char key[200];
    world_key(p, key, sizeof key);
    const uint8_t *metadata;
    size_t metadata_size;
    return auth_open(p->robot_key, key, payload, size, attachment, attachment_size, &metadata,
                     &metadata_size) == 0 &&
           metadata_size == 16 && questions_hold(asked, metadata);
}

static void lost(LinkRobot *p, int ended) {
    p->asking = 0;
    p->proving_count = 0;
    if (p->has_endpoint) {
        /* sorted(self.worlds): the world is out of reach with the link */
        for (int pass = 0; pass < p->world_count; pass++) {
            int least = -1;
            for (int i = 0; i < p->world_count; i++)
                if (p->worlds[i][0] && (least < 0 || strcmp(p->worlds[i], p->worlds[least]) < 0))
                    least = i;
            if (least < 0) break;
            endpoint_world_vanished(p->endpoint, p->worlds[least]);
            p->worlds[least][0] = 0;
        }
    }
    p->world_count = 0;
    if (ended) {
        log_info("robot %d: the run has ended", p->robot);
        p->ended = 1;
    }
}

static void welcomed(LinkRobot *p, double now) {
    if (strcmp(p->client.run, p->run) != 0) {
        log_error("the bridge serves run %s, the key file is of run %s", p->client.run, p->run);
        client_bye(&p->client, BYE_GOING_AWAY);
        p->fatal = 1;
        p->ended = 1;
        return;
    }
    log_info("robot %d: link session %ld open", p->robot, p->client.sessions);
    if (!p->has_endpoint) {
        ask(p, now);
    } else { /* back after a lost link: say where it is, and so be present again */
        int64_t tick = p->endpoint->last_tick > 0 ? p->endpoint->last_tick : 0;
        send_status(p, endpoint_status(p->endpoint, tick), now);
    }
}

/* the worlds reported before the map came, proved in sorted order */
static void prove_sorted_worlds(LinkRobot *p, double now) {
    int done[MAX_WORLDS] = {0};
    for (int pass = 0; pass < p->world_count; pass++) {
        int least = -1;
        for (int i = 0; i < p->world_count; i++)
            if (!done[i] && (least < 0 || strcmp(p->worlds[i], p->worlds[least]) < 0)) least = i;
        done[least] = 1;
        prove(p, p->worlds[least], now, 1);
    }
}

static int reported(const LinkRobot *p, const char *instance) {
    for (int i = 0; i < p->world_count; i++)
        if (!strcmp(p->worlds[i], instance)) return 1;
    return 0;
}

static void answered(LinkRobot *p, const uint8_t *payload, size_t size,
                     const uint8_t *attachment, size_t attachment_size, double now) {
    static WorldInfo info;
    if (p->has_endpoint) { /* a world answering for its token, or an answer no longer awaited */
        for (int i = 0; i < p->proving_count; i++) {
            if (!holds(p, &p->proving[i].asked, payload, size, attachment, attachment_size))
                continue;
            char instance[MAX_NAME + 1];
            snprintf(instance, sizeof instance, "%s", p->proving[i].instance);
            forget_proving(p, i);
            if (reported(p, instance)) endpoint_world_appeared(p->endpoint, instance);
            return;
        }
        return;
    }
    if (!p->asking) return; /* an answer to a question no longer asked */
    char key[200];
    world_key(p, key, sizeof key);
    const uint8_t *metadata;
    size_t metadata_size;
    if (auth_open(p->robot_key, key, payload, size, attachment, attachment_size, &metadata,
                  &metadata_size) != 0) {
        log_warning("robot %d: an answer on world/info that does not hold: not tagged by %s's key",
                    p->robot, p->identity);
        return;
    }
    if (metadata_size != 16 || !questions_hold(&p->asked, metadata)) {
        log_warning("robot %d: an answer on world/info that does not hold: it answers another query",
                    p->robot);
        return;
    }
    if (!decode_world_info(payload, size, &info)) {
        log_warning("robot %d: an answer on world/info that does not hold: not a WorldInfo",
                    p->robot);
        return;
    }
    p->asking = 0;
    static ControllerConfig config;
    char error[200];
    if (decode_controller_config(p->client.controller, p->client.controller_size, &config, error,
                                 sizeof error) != 0) {
        log_error("robot %d: the run's controller settings cannot be used: %s", p->robot, error);
        p->fatal = 1;
        p->ended = 1;
        return;
    }
    const char *why;
    if (endpoint_init(p->endpoint, p->robot, p->client.root, p->client.run, p->robot_key, &info,
                      &config, &why) != 0) {
        log_error("robot %d: cannot build the controller: %s", p->robot, why);
        p->fatal = 1;
        p->ended = 1;
        return;
    }
    p->has_endpoint = 1;
    char seed[21];
    format_int(info.seed, seed);
    log_info("robot %d: %d sites, clock %s, seed %s: running", p->robot, info.n_sites,
             info.lockstep ? "lockstep" : "realtime", seed);
    send_status(p, endpoint_status(p->endpoint, 0), now);
    prove_sorted_worlds(p, now);
}

/* A world token the bridge reports, appeared or gone. The bridge is trusted with nothing
   the robot believes: an appeared token is followed only once that world answers for
   itself (prove). */
static void world_token(LinkRobot *p, int up, const uint8_t *payload, size_t size, double now) {
    char instance[MAX_NAME + 1];
    size_t n = size < MAX_NAME ? size : MAX_NAME;
    memcpy(instance, payload, n);
    instance[n] = 0;
    int at = -1;
    for (int i = 0; i < p->world_count; i++)
        if (!strcmp(p->worlds[i], instance)) at = i;
    if (up) {
        if (at < 0 && p->world_count < MAX_WORLDS)
            snprintf(p->worlds[p->world_count++], sizeof p->worlds[0], "%s", instance);
        if (p->has_endpoint && proving_index(p, instance) < 0) prove(p, instance, now, 1);
    } else {
        if (at >= 0) {
            memmove(p->worlds[at], p->worlds[at + 1], sizeof p->worlds[0] * (size_t)(p->world_count - at - 1));
            p->world_count--;
        }
        int proving = proving_index(p, instance);
        if (proving >= 0) forget_proving(p, proving);
        if (p->has_endpoint) endpoint_world_vanished(p->endpoint, instance);
    }
}

static void received(LinkRobot *p, int kind, const uint8_t *payload, size_t size,
                     const uint8_t *attachment, size_t attachment_size, double now) {
    if (kind == K_INFO_REPLY) {
        answered(p, payload, size, attachment, attachment_size, now);
    } else if (kind == K_INFO_ERROR) {
        log_warning("the world refused the question for the map: %.*s", (int)(size < 200 ? size : 200),
                    (const char *)payload);
    } else if (kind == K_WORLD_UP || kind == K_WORLD_DOWN) {
        world_token(p, kind == K_WORLD_UP, payload, size, now);
    } else if (kind == K_SENSE || kind == K_RADIO_RX || kind == K_CAMERA) {
        int input = kind == K_SENSE ? IN_SENSE : kind == K_RADIO_RX ? IN_RADIO_RX : IN_CAMERA;
        if (!p->has_endpoint) {
            p->dropped[input]++;
            return;
        }
        Outgoing out[4];
        int count = endpoint_receive(p->endpoint, input, payload, size, attachment,
                                     attachment_size, out, 4);
        for (int i = 0; i < count; i++) {
            if (out[i].kind == OUT_STATUS)
                send_status(p, out[i], now);
            else
                client_send(&p->client, out[i].kind == OUT_ACT ? K_ACT : K_RADIO_TX,
                            out[i].payload, out[i].payload_size, out[i].attachment,
                            out[i].attachment_size);
        }
    }
}

/* LinkClient._receive: the checks in their order; the refusal, or R_NONE. An encrypted
   body is decrypted in place. */
static int client_receive(LinkRobot *p, uint8_t *data, size_t size, double now) {
    LinkClient *c = &p->client;
    Frame f;
    int refusal = link_read_header(data, size, &f);
    if (refusal) return refusal;
    if (f.robot != c->robot || !f.from_bridge) return R_UNEXPECTED; /* not for this robot */
    refusal = link_open(data, size, c->key, c->has_cipher ? c->cipher_key : NULL,
                        data + LINK_HEADER_BYTES, &f);
    if (refusal) return refusal;
    refusal = link_check_body(&f);
    if (refusal) return refusal;
    if (memcmp(f.robot_nonce, c->robot_nonce, 8) != 0) return R_UNEXPECTED; /* another session */
    if (f.type == F_WELCOME) {
        if (c->open) {
            if (!memcmp(f.bridge_nonce, c->bridge_nonce, 8)) return R_NONE; /* our hello repeated */
            return R_UNEXPECTED; /* a second welcome for one hello */
        }
        static LinkWelcome w;
        if (!decode_welcome(f.body, f.body_size, &w) || w.controller_size > sizeof c->controller)
            return R_MALFORMED;
        c->has_welcome = 1;
        snprintf(c->run, sizeof c->run, "%s", w.run);
        snprintf(c->root, sizeof c->root, "%s", w.root);
        c->encrypted = w.encrypted;
        c->ping_every = w.ping_every;
        memcpy(c->controller, w.controller, w.controller_size);
        c->controller_size = w.controller_size;
        memcpy(c->bridge_nonce, f.bridge_nonce, 8);
        c->open = 1;
        c->has_cipher = w.encrypted;
        if (w.encrypted) session_key(c->key, c->robot_nonce, f.bridge_nonce, c->cipher_key);
        c->sent_seq = 0;
        c->window.highest = c->window.seen = 0;
        c->silence = w.silence;
        c->last_heard = now;
        c->sessions += 1;
        /* an authentic frame of the new session at once: the bridge takes the session only
           on the robot's first frame in it */
        uint8_t zeros[LINK_PING_BODY_BYTES] = {0};
        session_send(c, F_PING, zeros, sizeof zeros);
        welcomed(p, now);
        return R_NONE;
    }
    if (!c->open || memcmp(f.bridge_nonce, c->bridge_nonce, 8) != 0) return R_UNEXPECTED;
    if (f.encrypted != c->has_cipher) return R_UNEXPECTED; /* not protected as the session is */
    if (replay_refuses(&c->window, f.seq)) return R_REPLAYED;
    replay_take(&c->window, f.seq);
    c->last_heard = now;
    if (f.type == F_PING) {
        uint8_t body[LINK_PING_BODY_BYTES];
        memcpy(body, f.body, sizeof body);
        session_send(c, F_PONG, body, sizeof body);
        return R_NONE;
    }
    if (f.type == F_BYE) {
        int reason = f.body[0];
        static const char *const names[] = {"", "run_ended", "going_away", "replaced"};
        char why[80];
        snprintf(why, sizeof why, "the bridge said bye (%s)", names[reason]);
        int fresh = lose(c, why, now);
        lost(p, reason == BYE_RUN_ENDED);
        if (fresh != 0 && !p->ended) no_entropy(p);
        return R_NONE;
    }
    if (f.type == F_DATA) {
        int kind;
        const uint8_t *payload, *attachment;
        size_t payload_size, attachment_size;
        refusal = link_decode_data(f.body, f.body_size, &kind, &payload, &payload_size,
                                   &attachment, &attachment_size);
        if (refusal) return refusal;
        if (kind >= K_FIRST_FROM_ROBOT) return R_UNEXPECTED; /* not a kind the bridge sends */
        received(p, kind, payload, payload_size, attachment, attachment_size, now);
        return R_NONE;
    }
    return R_NONE; /* a pong: the bridge measures round trips, not this end */
}

void link_robot_receive(LinkRobot *p, uint8_t *data, size_t size, double now) {
    int refusal = client_receive(p, data, size, now);
    if (refusal == R_NONE) return;
    p->client.refused[refusal]++;
    long total = 0;
    for (int i = 0; i < R_COUNT; i++) total += p->client.refused[i];
    if (total <= 10)
        log_warning("robot %d: refused a link frame: %s", p->robot, refusal_names[refusal]);
}

void link_robot_wake(LinkRobot *p, double now) {
    LinkClient *c = &p->client;
    if (c->open) {
        if (now - c->last_heard >= c->silence) {
            char why[80];
            snprintf(why, sizeof why, "the bridge was silent for %g s", c->silence);
            int fresh = lose(c, why, now);
            lost(p, 0);
            if (fresh != 0) {
                no_entropy(p);
                return;
            }
        }
    } else if (now >= c->next_hello) {
        send_hello(c, now);
    }
    if (p->asking && now >= p->ask_again_at && c->open) ask(p, now);
    for (int i = 0; i < p->proving_count; i++) {
        if (now < p->proving[i].again_at || !c->open) continue;
        int before = p->proving_count;
        char instance[MAX_NAME + 1];
        snprintf(instance, sizeof instance, "%s", p->proving[i].instance);
        prove(p, instance, now, p->proving[i].tries + 1);
        if (p->proving_count < before) i--; /* given up: the next moved into its place */
    }
    if (p->has_last_status && now >= p->status_again_at && c->open) resend_status(p, now);
}

void link_robot_hearing(LinkRobot *p, double now) {
    LinkClient *c = &p->client;
    if (c->open && now > c->last_heard) c->last_heard = now;
    if (p->asking && p->ask_again_at < now + ASK_EVERY) p->ask_again_at = now + ASK_EVERY;
    for (int i = 0; i < p->proving_count; i++)
        if (p->proving[i].again_at < now + PROVE_EVERY) p->proving[i].again_at = now + PROVE_EVERY;
}

void link_robot_stop(LinkRobot *p) { client_bye(&p->client, BYE_GOING_AWAY); }

static void json_counts(JW *w, const long *counts, const char *const *names, int n) {
    jw_raw(w, "{");
    int first = 1;
    for (int i = 0; i < n; i++) {
        if (!counts[i] || !names[i][0]) continue;
        if (!first) jw_raw(w, ", ");
        first = 0;
        jw_str(w, names[i], strlen(names[i]));
        jw_raw(w, ": ");
        jw_int(w, counts[i]);
    }
    jw_raw(w, "}");
}

/* Python's repr of a float (json.dumps): shortest digits, exponent below 1e-4 and from 1e16 */
static void py_float(JW *w, double x) {
    char text[64];
    format_double(x, text, sizeof text);
    /* the two spellings agree from 1e-4 up to 1e16; decisions are in seconds of sim time */
    jw_raw(w, text);
}

void link_robot_summary(const LinkRobot *p, char *out, size_t cap) {
    JW w;
    jw_init(&w, out, cap);
    jw_raw(&w, "{\"id\": ");
    jw_int(&w, p->robot);
    const Controller *c = p->has_endpoint ? p->endpoint->controller : NULL;
    jw_raw(&w, ", \"phase\": ");
    if (c) {
        jw_str(&w, phase_names[c->phase], strlen(phase_names[c->phase]));
    } else {
        jw_raw(&w, "null");
    }
    jw_raw(&w, ", \"decided_site\": ");
    if (c && c->decided_site >= 0) jw_int(&w, c->decided_site); else jw_raw(&w, "null");
    jw_raw(&w, ", \"decision_time\": ");
    if (c && c->decided_site >= 0) py_float(&w, c->decision_time); else jw_raw(&w, "null");
    jw_raw(&w, ", \"trips\": ");
    jw_int(&w, c ? c->trips : 0);
    jw_raw(&w, ", \"last_tick\": ");
    if (c) jw_int(&w, p->endpoint->last_tick); else jw_raw(&w, "null");
    jw_raw(&w, ", \"rejected\": ");
    jw_int(&w, c ? p->endpoint->rejects : 0);
    jw_raw(&w, ", \"sessions\": ");
    jw_int(&w, p->client.sessions);
    jw_raw(&w, ", \"refused\": ");
    json_counts(&w, p->client.refused, refusal_names, R_COUNT);
    static const char *const inputs[] = {"sense", "radio_rx", "camera"};
    long dropped[3] = {p->dropped[IN_SENSE], p->dropped[IN_RADIO_RX], p->dropped[IN_CAMERA]};
    jw_raw(&w, ", \"dropped\": ");
    json_counts(&w, dropped, inputs, 3);
    jw_raw(&w, "}");
    if (w.err) snprintf(out, cap, "{\"id\": %d}", p->robot);
    else out[w.len] = 0;
}
