#include "key_record.h"

#include <string.h>

#include "limits.h"
#include "link.h" /* crc32_of */
#include "messages.h" /* MAX_ROBOTS */

static uint32_t le32(const uint8_t *p) {
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

int key_record_read(const uint8_t *record, size_t available, int *robot, const uint8_t **text,
                    size_t *size, const char **why) {
    if (available < 16 || memcmp(record, "BOKR", 4) != 0) {
        *why = "no key record in flash";
        return -1;
    }
    uint32_t id = le32(record + 4), n = le32(record + 8);
    if (n > KEY_FILE_BYTES || n > available - 16) {
        *why = "the key record's length is out of bounds";
        return -1;
    }
    if (crc32_of(record, 12 + (size_t)n) != le32(record + 12 + n)) {
        *why = "the key record's CRC does not check out";
        return -1;
    }
    if (id >= MAX_ROBOTS) {
        *why = "the key record's robot id is out of range";
        return -1;
    }
    *robot = (int)id;
    *text = record + 12;
    *size = n;
    return 0;
}
