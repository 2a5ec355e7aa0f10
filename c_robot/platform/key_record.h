/* The robot's key in flash: a record a host tool writes beside the firmware (on qemu with
   -device loader; on a board with the flasher), so that one firmware image serves any
   robot and any run. Its layout, integers little-endian:

     offset  size  field
     0       4     magic, ASCII "BOKR"
     4       4     the robot's id
     8       4     n, the key file's length (at most KEY_FILE_BYTES)
     12      n     the key file, as `swarm run --link-keys` writes it (docs/porting.md)
     12 + n  4     CRC-32 (zlib's) of bytes 0 to 12 + n

   Erased flash (0xFF) or a record that does not check out is no record. */
#ifndef CR_KEY_RECORD_H
#define CR_KEY_RECORD_H
#include <stddef.h>
#include <stdint.h>

/* 0 and the robot id and the key file's bytes (inside record), or -1 and why */
int key_record_read(const uint8_t *record, size_t available, int *robot, const uint8_t **text,
                    size_t *size, const char **why);
#endif
