/* entropy_bytes on Linux and other POSIX systems: the kernel's generator, /dev/urandom.
   -DENTROPY_NONE builds a robot without a source (it refuses to start: tests/test_mcu.py);
   -DENTROPY_DEVICE='"PATH"' reads another device. */
#include "entropy.h"

#include <fcntl.h>
#include <unistd.h>

#ifndef ENTROPY_DEVICE
#define ENTROPY_DEVICE "/dev/urandom"
#endif

int entropy_bytes(uint8_t *out, size_t size) {
#ifdef ENTROPY_NONE
    (void)out;
    (void)size;
    return -1;
#else
    static int fd = -1;
    if (fd < 0) fd = open(ENTROPY_DEVICE, O_RDONLY);
    if (fd < 0) return -1;
    size_t got = 0;
    while (got < size) {
        ssize_t n = read(fd, out + got, size - got);
        if (n <= 0) return -1;
        got += (size_t)n;
    }
    return 0;
#endif
}
