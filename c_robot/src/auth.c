#include "auth.h"

#include <string.h>

#include "messages.h"
#include "sha256.h"

void auth_derive_key(const uint8_t secret[32], const char *identity, uint8_t key[32]) {
    HmacSha256 h;
    hmac_init(&h, secret, 32);
    hmac_update(&h, "bestofn-key:", 12);
    hmac_update(&h, identity, strlen(identity));
    hmac_final(&h, key);
}

static void u32(HmacSha256 *h, size_t v) {
    uint8_t b[4] = {(uint8_t)(v >> 24), (uint8_t)(v >> 16), (uint8_t)(v >> 8), (uint8_t)v};
    hmac_update(h, b, 4);
}

void auth_tag(const uint8_t key[32], const char *key_expr, const uint8_t *metadata,
              size_t metadata_size, const uint8_t *payload, size_t payload_size,
              uint8_t tag[16]) {
    HmacSha256 h;
    uint8_t mac[32];
    size_t k = strlen(key_expr);
    hmac_init(&h, key, 32);
    u32(&h, k);
    hmac_update(&h, key_expr, k);
    u32(&h, metadata_size);
    if (metadata_size) hmac_update(&h, metadata, metadata_size);
    u32(&h, payload_size);
    if (payload_size) hmac_update(&h, payload, payload_size);
    hmac_final(&h, mac);
    memcpy(tag, mac, 16);
}

long auth_seal(const uint8_t key[32], const char *key_expr, const uint8_t *payload,
               size_t payload_size, const uint8_t *metadata, size_t metadata_size,
               uint8_t *out, size_t cap) {
    if (16 + metadata_size > cap) return -1;
    if (metadata_size) memmove(out + 16, metadata, metadata_size);
    auth_tag(key, key_expr, out + 16, metadata_size, payload, payload_size, out);
    return (long)(16 + metadata_size);
}

int auth_open(const uint8_t key[32], const char *key_expr, const uint8_t *payload,
              size_t payload_size, const uint8_t *attachment, size_t attachment_size,
              const uint8_t **metadata, size_t *metadata_size) {
    if (attachment == NULL || attachment_size < 16) return -1;
    uint8_t tag[16];
    auth_tag(key, key_expr, attachment + 16, attachment_size - 16, payload, payload_size, tag);
    if (!equal_ct(tag, attachment, 16)) return -1;
    *metadata = attachment + 16;
    *metadata_size = attachment_size - 16;
    return 0;
}

static int robot_id_text(const char *t, size_t len) {
    /* 0|[1-9][0-9]{0,4} */
    if (len == 0 || len > 5) return 0;
    if (t[0] == '0') return len == 1;
    for (size_t i = 0; i < len; i++)
        if (t[i] < '0' || t[i] > '9') return 0;
    return 1;
}

static long robot_id_value(const char *t, size_t len) {
    long v = 0;
    for (size_t i = 0; i < len; i++) v = v * 10 + (t[i] - '0');
    return v;
}

int is_identity(const char *t, size_t len) {
    static const char *const single[] = {"world", "launcher", "recorder", "viewer", "foxglove",
                                         "bridge", NULL};
    for (int i = 0; single[i]; i++)
        if (strlen(single[i]) == len && !memcmp(single[i], t, len)) return 1;
    if (len > 6 && !memcmp(t, "robot/", 6)) return robot_id_text(t + 6, len - 6);
    if (len > 7 && !memcmp(t, "beacon/", 7)) return is_name(t + 7, len - 7);
    if (len > 5 && !memcmp(t, "host/", 5)) {
        const char *dash = memchr(t + 5, '-', len - 5);
        if (!dash) return 0;
        size_t a = (size_t)(dash - (t + 5)), b = len - 5 - a - 1;
        if (!robot_id_text(t + 5, a) || !robot_id_text(dash + 1, b)) return 0;
        return robot_id_value(t + 5, a) <= robot_id_value(dash + 1, b);
    }
    return 0;
}
