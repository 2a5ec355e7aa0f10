/* entropy_bytes on a board: its hook (board.h board_entropy), whatever the build chose. */
#include "board.h"
#include "entropy.h"

int entropy_bytes(uint8_t *out, size_t size) { return board_entropy(out, size); }
