/* The robot's key file (docs/porting.md "The program on a link"; bestofn_swarm/wire/auth.py
   keyring_from_text, bestofn_swarm/plumbing/run_keys.py read_key_file), read from its bytes: a file on
   Linux, a record in flash on a microcontroller (platform/key_record.h). */
#ifndef CR_KEYFILE_H
#define CR_KEYFILE_H
#include <stddef.h>
#include <stdint.h>

#include "messages.h"

enum { KEY_FILE_OK = 0, KEY_FILE_BAD = -1, KEY_FILE_NO_KEY = -2 };

/* The run and robot `robot`'s key: KEY_FILE_OK; KEY_FILE_BAD and why ("not JSON", ...);
   or KEY_FILE_NO_KEY (the file holds no key for the robot). */
int key_file_read(const uint8_t *text, size_t size, int robot, char run[MAX_NAME + 1],
                  uint8_t key[32], const char **why);
#endif
