/* PNG and vision against OpenCV and vision.py (png_cases.json), the decision math, the
   endpoint and the link client. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "controller.h"
#include "decision.h"
#include "png.h"
#include "sha256.h"
#include "tests.h"
#include "vision.h"

static unsigned char data[64 * 1024]; /* a PNG of png_cases.json (at most 9.4 KB) */

void test_png(void) {
    JNode *root = jdom_parse_file("tests/png_cases.json");
    if (!root) {
        check(0, "png_cases.json", "missing (run from c_robot/)");
        return;
    }
    for (size_t i = 0; i < root->count; i++) {
        JNode *c = root->items[i];
        const char *name = jdom_str(c, "name");
        size_t n = jdom_hex(jdom_str(c, "hex"), data, sizeof data);
        Image image;
        const char *why;
        int rc = png_decode(data, n, &image, &why);
        if (!jdom_get(c, "decodes")->boolean) {
            check(rc != 0, "png refused", name);
            continue;
        }
        int ok = rc == 0 && image.width == jdom_get(c, "width")->integer &&
                 image.height == jdom_get(c, "height")->integer;
        if (ok) {
            unsigned char digest[32], want[32];
            sha256(image.bgr, (size_t)image.width * image.height * 3, digest);
            jdom_hex(jdom_str(c, "sha256"), want, 32);
            ok = !memcmp(digest, want, 32);
        }
        check(ok, "png decodes as OpenCV", name);
        if (!ok) continue;
        double quality;
        int seen = estimate_quality(&image, &quality);
        JNode *q = jdom_get(c, "quality");
        if (q->type == J_NULL) {
            check(!seen, "vision: no site", name);
        } else {
            unsigned long long want = strtoull(q->str, NULL, 16), got;
            memcpy(&got, &quality, 8);
            check(seen && got == want, "vision: the same quality", name);
        }
    }
}


static double hexd(const char *hex) {
    unsigned long long v = strtoull(hex, NULL, 16);
    double d;
    memcpy(&d, &v, 8);
    return d;
}

static int same_list(const double *got, JNode *want, int n) {
    if ((int)want->count != n) return 0;
    for (int i = 0; i < n; i++) {
        double w = hexd(want->items[i]->str);
        if (memcmp(&got[i], &w, 8) != 0) return 0;
    }
    return 1;
}

static void list_of(JNode *list, double *out) {
    for (size_t i = 0; i < list->count; i++) out[i] = hexd(list->items[i]->str);
}

void test_decision(void) {
    JNode *root = cases_json();
    if (!root) return;
    JNode *cases = jdom_get(root, "decision");
    static double opinion[MAX_OPTIONS], out[MAX_OPTIONS], pool_values[64][MAX_OPTIONS];
    for (size_t k = 0; k < cases->count; k++) {
        JNode *c = cases->items[k];
        const char *op = jdom_str(c, "op");
        char name[64];
        snprintf(name, sizeof name, "%s case %zu", op, k);
        if (!strcmp(op, "negative_update")) {
            JNode *o = jdom_get(c, "opinion");
            list_of(o, opinion);
            negative_update(opinion, (int)o->count, (int)jdom_get(c, "eliminated")->integer,
                            hexd(jdom_str(c, "alpha")), out);
            check(same_list(out, jdom_get(c, "out"), (int)o->count), "decision", name);
        } else if (!strcmp(op, "mprodop") || !strcmp(op, "loglinear")) {
            JNode *pool = jdom_get(c, "pool");
            const double *ptrs[64];
            int n = (int)pool->items[0]->count;
            for (size_t i = 0; i < pool->count; i++) {
                list_of(pool->items[i], pool_values[i]);
                ptrs[i] = pool_values[i];
            }
            int ok = !strcmp(op, "mprodop") ? mprodop(ptrs, (int)pool->count, n, out)
                                            : loglinear_pool(ptrs, (int)pool->count, n, 0.5, out);
            JNode *want = jdom_get(c, "out");
            check(want->type == J_NULL ? !ok : ok && same_list(out, want, n), "decision", name);
        } else if (!strcmp(op, "choose_pair")) {
            JNode *o = jdom_get(c, "opinion");
            list_of(o, opinion);
            Stream s;
            stream_seed(&s, strtoull(jdom_str(c, "seed"), NULL, 16));
            int first, second;
            choose_pair(opinion, (int)o->count, &s, &first, &second);
            JNode *want = jdom_get(c, "out");
            check(first == want->items[0]->integer && second == want->items[1]->integer &&
                      s.state == strtoull(jdom_str(c, "state_after"), NULL, 16),
                  "decision", name);
        } else {
            JNode *o = jdom_get(c, "opinion");
            list_of(o, opinion);
            check(decided_option(opinion, (int)o->count, hexd(jdom_str(c, "threshold"))) ==
                      jdom_get(c, "out")->integer,
                  "decision", name);
        }
    }
    JNode *parking = jdom_get(root, "parking");
    static WorldInfo world;
    ControllerConfig config;
    controller_config_defaults(&config);
    for (size_t k = 0; k < parking->count; k++) {
        JNode *p = parking->items[k];
        JNode *w = jdom_get(p, "world"), *sites = jdom_get(w, "sites");
        memset(&world, 0, sizeof world);
        world.dt = 0.1;
        world.arena_radius = hexd(jdom_str(w, "arena_radius"));
        world.nest_radius = hexd(jdom_str(w, "nest_radius"));
        world.robot_radius = 0.037;
        world.wheel_base = 0.053;
        world.max_wheel_speed = 0.13;
        world.lockstep = 1;
        world.n_sites = (int)sites->count;
        for (int i = 0; i < world.n_sites; i++) {
            world.sites[i].id = i;
            world.sites[i].x = hexd(sites->items[i]->items[0]->str);
            world.sites[i].y = hexd(sites->items[i]->items[1]->str);
        }
        JNode *slots = jdom_get(p, "slots");
        for (size_t i = 0; i < slots->count; i++) {
            JNode *s = slots->items[i];
            int robot = (int)s->items[0]->integer, site = (int)s->items[1]->integer;
            const char *why;
            Controller *c = controller_instance();
            int ok = controller_init(c, robot, &world, &config, 1, &why) == 0;
            double x = 0, y = 0;
            if (ok) controller_parking_slot(c, site, &x, &y);
            double wx = hexd(s->items[2]->str), wy = hexd(s->items[3]->str);
            char name[96];
            snprintf(name, sizeof name, "%d robots: robot %d, site %d",
                     (int)jdom_get(p, "robots")->integer, robot, site);
            check(ok && !memcmp(&x, &wx, 8) && !memcmp(&y, &wy, 8), "parking slot", name);
        }
    }
}
/* --- the link session and the start-up sequence, against a bridge made here ----------- */

#include "auth.h"
#include "client.h"
#include "link.h"

static LinkRobot robot;
static uint8_t lk[32], robot_key[32];
static const uint8_t bridge_nonce[8] = {0x11, 0x12, 0x13, 0x14, 0x15, 0x16, 0x17, 0x18};

static void from_bridge(int type, const uint8_t *body, size_t size, uint64_t seq, double now) {
    static uint8_t frame[LINK_MAX_FRAME_BYTES];
    Frame f;
    memset(&f, 0, sizeof f);
    f.type = type;
    f.from_bridge = 1;
    f.robot = 8;
    memcpy(f.robot_nonce, robot.client.robot_nonce, 8);
    memcpy(f.bridge_nonce, bridge_nonce, 8);
    f.seq = seq;
    f.body = body;
    f.body_size = size;
    long n = link_seal(&f, lk, NULL, frame, sizeof frame);
    link_robot_receive(&robot, frame, (size_t)n, now);
}

/* the robot's queued frames, opened; their types in order */
static int sent_types(int *types, Frame *frames, int cap) {
    static uint8_t copies[16][16384];
    int n = 0;
    size_t size;
    const uint8_t *frame;
    for (int i = 0; n < cap && (frame = client_frame(&robot.client, i, &size)) != NULL; i++) {
        if (size > sizeof copies[0]) {
            check(0, "client", "a frame longer than the test keeps");
            break;
        }
        memcpy(copies[n], frame, size);
        static uint8_t plain[70000];
        check(link_open(copies[n], size, lk, NULL, plain, &frames[n]) == R_NONE, "client", "its frames are tagged under the link key");
        types[n] = frames[n].type;
        n++;
    }
    client_clear(&robot.client);
    return n;
}


void test_client(void) {
    memset(robot_key, 7, sizeof robot_key);
    link_key(robot_key, lk);
    link_robot_init(&robot, 8, "demo", robot_key);
    int types[16];
    Frame frames[16];
    link_robot_wake(&robot, 0.0);
    int n = sent_types(types, frames, 16);
    check(n == 1 && types[0] == F_HELLO && frames[0].seq == 0, "client", "a hello at once");
    link_robot_wake(&robot, 0.3);
    check(sent_types(types, frames, 16) == 0, "client", "no second hello before 0.5 s");
    link_robot_wake(&robot, 0.5);
    check(sent_types(types, frames, 16) == 1 && types[0] == F_HELLO, "client", "hello every 0.5 s");
    const char *welcome = "{\"v\":1,\"run\":\"demo\",\"root\":\"bestofn\",\"cipher\":\"none\","
                          "\"ping_every\":0.5,\"silence\":3.0,\"controller\":{\"dwell\":3.0}}";
    from_bridge(F_WELCOME, (const uint8_t *)welcome, strlen(welcome), 0, 0.6);
    n = sent_types(types, frames, 16);
    check(n == 2 && types[0] == F_PING && frames[0].seq == 1 && types[1] == F_DATA &&
              frames[1].seq == 2,
          "client", "welcome: a ping at once, then the question for the map");
    if (n == 2) {
        int kind;
        const uint8_t *payload, *attachment, *metadata;
        size_t ps, as, ms;
        link_decode_data(frames[1].body, frames[1].body_size, &kind, &payload, &ps, &attachment, &as);
        int ok = kind == K_INFO_QUERY && ps == 0 && as == 16 + 16 + 7 &&
                 !memcmp(attachment + 32, "robot/8", 7) &&
                 auth_open(robot_key, "bestofn/demo/world/info", payload, 0, attachment, as,
                           &metadata, &ms) == 0 &&
                 !memcmp(metadata, questions_latest(&robot.asked), 16);
        check(ok, "client", "kind 19: tag, nonce, identity, tagged with the robot's key");
    }
    link_robot_wake(&robot, 1.6);
    n = sent_types(types, frames, 16);
    check(n == 1 && types[0] == F_DATA, "client", "the question again after 1 s");
    from_bridge(F_WELCOME, (const uint8_t *)welcome, strlen(welcome), 0, 1.6);
    check(sent_types(types, frames, 16) == 0 && robot.client.refused[R_UNEXPECTED] == 0,
          "client", "the same welcome again is ignored");
    uint8_t ping[8] = {0, 0, 0, 0, 0, 0, 0, 9};
    from_bridge(F_PING, ping, 8, 1, 1.7);
    n = sent_types(types, frames, 16);
    check(n == 1 && types[0] == F_PONG && !memcmp(frames[0].body, ping, 8), "client", "a pong repeats the ping");
    from_bridge(F_PING, ping, 8, 1, 1.8);
    check(robot.client.refused[R_REPLAYED] == 1 && sent_types(types, frames, 16) == 0, "client",
          "a sequence number taken twice is refused (replayed)");
    /* a world/info answer for another nonce is not taken */
    uint8_t body[4096], att[64];
    const char *info = "{\"v\":1,\"run\":\"demo\",\"seed\":0,\"dt\":0.1,\"arena_radius\":0.75,\"nest\":"
                       "{\"x\":0.0,\"y\":0.0,\"radius\":0.2},\"sites\":[{\"id\":0,\"x\":0.75,\"y\":0.0},"
                       "{\"id\":1,\"x\":-0.375,\"y\":0.649519053},{\"id\":2,\"x\":-0.375,\"y\":-0.649519053}],"
                       "\"robot_radius\":0.037,\"wheel_base\":0.053,\"max_wheel_speed\":0.13,\"camera\":"
                       "{\"width\":64,\"height\":48,\"fov\":0.84},\"clock\":\"lockstep\"}";
    uint8_t wrong[16];
    memset(wrong, 1, 16);
    long an = auth_seal(robot_key, "bestofn/demo/world/info", (const uint8_t *)info, strlen(info), wrong, 16, att, sizeof att);
    long bn = link_encode_data(K_INFO_REPLY, (const uint8_t *)info, strlen(info), att, (size_t)an, body, sizeof body);
    from_bridge(F_DATA, body, (size_t)bn, 2, 1.9);
    check(!robot.has_endpoint && sent_types(types, frames, 16) == 0, "client", "an answer to another question is not taken");
    /* answered an asking late (asked at 0.6 s and again at 1.6 s): the first still counts */
    uint8_t first[16];
    memcpy(first, robot.asked.nonces[0], 16);
    check(robot.asked.count == 2 && memcmp(questions_latest(&robot.asked), first, 16) != 0,
          "client", "each asking has its own nonce, the earlier ones kept");
    an = auth_seal(robot_key, "bestofn/demo/world/info", (const uint8_t *)info, strlen(info), first, 16, att, sizeof att);
    bn = link_encode_data(K_INFO_REPLY, (const uint8_t *)info, strlen(info), att, (size_t)an, body, sizeof body);
    from_bridge(F_DATA, body, (size_t)bn, 3, 2.0);
    n = sent_types(types, frames, 16);
    int status_ok = 0;
    if (n == 1 && types[0] == F_DATA) {
        int kind;
        const uint8_t *payload, *attachment;
        size_t ps, as;
        link_decode_data(frames[0].body, frames[0].body_size, &kind, &payload, &ps, &attachment, &as);
        const char *head = "{\"v\":1,\"id\":8,\"tick\":0,\"t\":0.0,\"phase\":\"to_site\",\"trips\":0,";
        status_ok = kind == K_STATUS && ps > strlen(head) && !memcmp(payload, head, strlen(head));
    }
    check(robot.has_endpoint && status_ok, "client", "the map answered: the first status, at tick 0");
    link_robot_wake(&robot, 3.9);
    check(sent_types(types, frames, 16) == 0, "client", "no repeat before 2 s");
    link_robot_wake(&robot, 4.0);
    n = sent_types(types, frames, 16);
    check(n == 1 && types[0] == F_DATA, "client", "the status again every 2 s");
    /* a world token is followed once that world answers world/info asked with its instance */
    uint8_t token[64];
    long tn = link_encode_data(K_WORLD_UP, (const uint8_t *)"w-1", 3, NULL, 0, token, sizeof token);
    from_bridge(F_DATA, token, (size_t)tn, 4, 4.1);
    n = sent_types(types, frames, 16);
    int asked = 0;
    if (n == 1 && types[0] == F_DATA) {
        int kind;
        const uint8_t *payload, *attachment;
        size_t ps, as;
        link_decode_data(frames[0].body, frames[0].body_size, &kind, &payload, &ps, &attachment, &as);
        asked = kind == K_INFO_QUERY && ps == 3 && !memcmp(payload, "w-1", 3);
    }
    check(asked && !robot.endpoint->has_followed, "client",
          "a world token: its world asked to answer for it, not followed yet");
    an = auth_seal(robot_key, "bestofn/demo/world/info", (const uint8_t *)info, strlen(info),
                   questions_latest(&robot.proving[0].asked), 16, att, sizeof att);
    bn = link_encode_data(K_INFO_REPLY, (const uint8_t *)info, strlen(info), att, (size_t)an, body, sizeof body);
    from_bridge(F_DATA, body, (size_t)bn, 5, 4.2);
    check(robot.endpoint->has_followed && !strcmp(robot.endpoint->followed, "w-1") &&
              robot.proving_count == 0,
          "client", "the world answered for its token: followed");
    /* a token no world answers for: asked PROVE_TRIES times, PROVE_EVERY apart, then counted */
    long rejects = robot.endpoint->rejects;
    tn = link_encode_data(K_WORLD_UP, (const uint8_t *)"w-2", 3, NULL, 0, token, sizeof token);
    from_bridge(F_DATA, token, (size_t)tn, 6, 4.3);
    int questions = 0;
    uint64_t seq = 7;
    for (double t = 4.3; t < 14.5; t += 1.0) {
        if (t > 4.3) {
            from_bridge(F_PING, ping, 8, seq++, t); /* the bridge keeps the session alive */
            link_robot_wake(&robot, t);
        }
        n = sent_types(types, frames, 16);
        for (int i = 0; i < n; i++) {
            int kind;
            const uint8_t *payload, *attachment;
            size_t ps, as;
            if (types[i] != F_DATA) continue;
            link_decode_data(frames[i].body, frames[i].body_size, &kind, &payload, &ps, &attachment, &as);
            questions += kind == K_INFO_QUERY && ps == 3 && !memcmp(payload, "w-2", 3);
        }
    }
    check(questions == PROVE_TRIES && robot.endpoint->rejects == rejects + 1 &&
              !strcmp(robot.endpoint->followed, "w-1") && robot.proving_count == 0,
          "client", "an unanswered token: asked 5 times, then one rejection, still on its world");
    uint8_t bye = BYE_RUN_ENDED;
    from_bridge(F_BYE, &bye, 1, seq, 14.6);
    check(robot.ended && !robot.client.open, "client", "a bye (run ended) ends the program");
    char summary[1024];
    link_robot_summary(&robot, summary, sizeof summary);
    check(strstr(summary, "\"sessions\": 1") && strstr(summary, "\"refused\": {\"replayed\": 1}"),
          "client", summary);
}

/* --- a serial line's long frames, and the firmware's platform pieces ------------------ */

#include "key_record.h"
#include "motor_guard.h"

static void test_hearing(void) {
    link_robot_init(&robot, 8, "demo", robot_key);
    link_robot_wake(&robot, 0.0);
    client_clear(&robot.client);
    const char *welcome = "{\"v\":1,\"run\":\"demo\",\"root\":\"bestofn\",\"cipher\":\"none\","
                          "\"ping_every\":0.5,\"silence\":3.0,\"controller\":{\"dwell\":3.0}}";
    from_bridge(F_WELCOME, (const uint8_t *)welcome, strlen(welcome), 0, 0.0);
    client_clear(&robot.client); /* the ping and the question for the map */
    int types[16];
    Frame frames[16];
    int asked = 0;
    for (double t = 0.5; t <= 5.51; t += 0.5) { /* a long frame arriving all along */
        link_robot_hearing(&robot, t);
        link_robot_wake(&robot, t);
        asked += sent_types(types, frames, 16);
    }
    check(robot.client.open && asked == 0, "serial line",
          "a frame under way: the session holds, and nothing is asked again");
    link_robot_wake(&robot, 6.5);
    check(sent_types(types, frames, 16) == 1 && types[0] == F_DATA, "serial line",
          "the question again 1 s after the last bytes");
    link_robot_wake(&robot, 8.5);
    check(!robot.client.open, "serial line", "silence 3 s after the last bytes heard");
}

static void test_motor_guard(void) {
    MotorGuard guard;
    double left, right;
    motor_guard_init(&guard, 0.3);
    motor_guard_wheels(&guard, 0.0, &left, &right);
    int ok = left == 0.0 && right == 0.0;
    motor_guard_command(&guard, 1.0, 0.1, -0.05);
    motor_guard_wheels(&guard, 1.29, &left, &right);
    ok &= left == 0.1 && right == -0.05 && guard.stops == 0;
    motor_guard_wheels(&guard, 1.3, &left, &right);
    ok &= left == 0.0 && right == 0.0 && guard.stops == 1;
    motor_guard_wheels(&guard, 1.4, &left, &right);
    ok &= guard.stops == 1; /* stopped once, not again */
    motor_guard_command(&guard, 1.5, 0.0, 0.0);
    motor_guard_wheels(&guard, 2.0, &left, &right);
    ok &= guard.stops == 1; /* wheels already still: nothing stopped */
    check(ok, "motor guard", "a command holds for the timeout, then the wheels stop");
}

static size_t make_record(uint8_t *record, uint32_t robot_id, const char *text) {
    uint32_t n = (uint32_t)strlen(text);
    memcpy(record, "BOKR", 4);
    for (int i = 0; i < 4; i++) {
        record[4 + i] = (uint8_t)(robot_id >> (8 * i));
        record[8 + i] = (uint8_t)(n >> (8 * i));
    }
    memcpy(record + 12, text, n);
    uint32_t crc = crc32_of(record, 12 + n);
    for (int i = 0; i < 4; i++) record[12 + n + i] = (uint8_t)(crc >> (8 * i));
    return 16 + n;
}

static void test_key_record(void) {
    static uint8_t record[512];
    const char *text = "{\"v\":1,\"run\":\"demo\",\"keys\":{\"robot/9\":\"" /* 32 bytes of 0xab */
                       "abababababababababababababababababababababababababababababababab\"}}";
    size_t size = make_record(record, 9, text);
    int robot_id;
    const uint8_t *found;
    size_t found_size;
    const char *why;
    int ok = key_record_read(record, sizeof record, &robot_id, &found, &found_size, &why) == 0 &&
             robot_id == 9 && found_size == strlen(text) && !memcmp(found, text, found_size);
    check(ok, "key record", "read back: the robot and its key file");
    record[20] ^= 1;
    check(key_record_read(record, sizeof record, &robot_id, &found, &found_size, &why) != 0,
          "key record", "a changed byte: its CRC does not check out");
    record[20] ^= 1;
    check(key_record_read(record, size - 1, &robot_id, &found, &found_size, &why) != 0,
          "key record", "longer than the flash that holds it");
    memset(record, 0xFF, sizeof record);
    check(key_record_read(record, sizeof record, &robot_id, &found, &found_size, &why) != 0,
          "key record", "erased flash is no record");
}

void test_platform(void) {
    test_hearing();
    test_motor_guard();
    test_key_record();
}
