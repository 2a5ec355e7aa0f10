#include "keyfile.h"

#include <stdio.h>
#include <string.h>

#include "auth.h"
#include "json.h"

static int hex_key(const char *text, uint8_t out[32]) {
    /* bytes.fromhex: pairs of hex digits, whitespace allowed between them */
    size_t n = 0;
    const char *p = text;
    while (*p) {
        if (*p == ' ' || *p == '\t' || *p == '\n' || *p == '\r' || *p == '\f' || *p == '\v') {
            p++;
            continue;
        }
        unsigned v = 0;
        for (int k = 0; k < 2; k++, p++) {
            char c = *p;
            v <<= 4;
            if (c >= '0' && c <= '9') v |= (unsigned)(c - '0');
            else if (c >= 'a' && c <= 'f') v |= (unsigned)(c - 'a' + 10);
            else if (c >= 'A' && c <= 'F') v |= (unsigned)(c - 'A' + 10);
            else return -1;
        }
        if (n >= 32) return -1;
        out[n++] = (uint8_t)v;
    }
    return n == 32 ? 0 : -1;
}

static int bad(const char **why, const char *what) {
    *why = what;
    return KEY_FILE_BAD;
}

int key_file_read(const uint8_t *text, size_t size, int robot, char run[MAX_NAME + 1],
                  uint8_t key[32], const char **why) {
    char identity[32];
    snprintf(identity, sizeof identity, "robot/%d", robot);
    JR jr, *r = &jr;
    jr_init(r, text, size);
    int first = 1, have_v = 0, have_run = 0, have_secret = 0, have_keys = 0, found = 0;
    char name[128];
    static char value[KEY_FILE_VALUE_BYTES];
    uint8_t secret[32];
    if (jr_peek(r) != '{') return bad(why, "not a run key object ({\"v\": 1, ...})");
    jr_obj_begin(r);
    while (jr_obj_next(r, &first, name, sizeof name)) {
        size_t len, chars;
        if (!strcmp(name, "v")) {
            double v;
            int b;
            if (jr_peek(r) == 't' || jr_peek(r) == 'f') have_v = jr_bool(r, &b) && b;
            else if (jr_peek(r) == '-' || (jr_peek(r) >= '0' && jr_peek(r) <= '9')) have_v = jr_float(r, &v) && v == 1.0;
            else { const uint8_t *x, *y; jr_skip(r, &x, &y); have_v = 0; }
        } else if (!strcmp(name, "run")) {
            if (jr_peek(r) == '"') {
                have_run = jr_string(r, value, 256, &len, &chars);
                if (have_run) {
                    size_t keep = len < MAX_NAME ? len : MAX_NAME;
                    memcpy(run, value, keep); /* a longer run id: no bridge can serve it */
                    run[keep] = 0;
                }
            } else {
                const uint8_t *x, *y;
                jr_skip(r, &x, &y);
                have_run = 0;
            }
        } else if (!strcmp(name, "secret")) {
            have_secret = 1;
            if (jr_peek(r) != '"' || !jr_string(r, value, sizeof value, &len, &chars) ||
                hex_key(value, secret) != 0)
                have_secret = -1;
        } else if (!strcmp(name, "keys")) {
            have_keys = -1;
            if (jr_peek(r) == '{') {
                int inner = 1, count = 0, wrong = 0;
                jr_obj_begin(r);
                while (jr_obj_next(r, &inner, name, sizeof name)) {
                    count++;
                    uint8_t k[32];
                    if (jr_peek(r) != '"' || !jr_string(r, value, sizeof value, &len, &chars) ||
                        hex_key(value, k) != 0 || !is_identity(name, strlen(name))) {
                        wrong = 1;
                        if (r->err) break;
                        continue;
                    }
                    if (!strcmp(name, identity)) {
                        memcpy(key, k, 32);
                        found = 1;
                    }
                }
                have_keys = !r->err && count > 0 && !wrong ? 1 : -1;
            } else {
                const uint8_t *x, *y;
                jr_skip(r, &x, &y);
            }
        } else {
            const uint8_t *x, *y;
            jr_skip(r, &x, &y);
        }
    }
    if (r->err || !jr_end(r)) return bad(why, "not JSON");
    if (!have_v) return bad(why, "not a run key object ({\"v\": 1, ...})");
    if (!have_run) return bad(why, "the keys name no run");
    if (have_secret) {
        if (have_secret < 0) return bad(why, "the secret is not 32 bytes of hex");
        auth_derive_key(secret, identity, key);
        return KEY_FILE_OK;
    }
    if (have_keys <= 0) return bad(why, "neither \"secret\" nor \"keys\"");
    if (!found) {
        *why = "holds no key for robot";
        return KEY_FILE_NO_KEY;
    }
    return KEY_FILE_OK;
}
