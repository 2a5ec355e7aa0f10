#include "semihost.h"

#include <string.h>

enum { SYS_OPEN = 0x01, SYS_CLOSE = 0x02, SYS_READ = 0x06, SYS_EXIT = 0x18,
       SYS_EXIT_EXTENDED = 0x20 };
#define ADP_STOPPED_APPLICATION_EXIT 0x20026

static int call(int op, const void *arg) {
    register int r0 __asm__("r0") = op;
    register const void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xab" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}

int semihost_read_file(const char *path, uint8_t *out, size_t size) {
    uint32_t open_args[3] = {(uint32_t)(uintptr_t)path, 1 /* "rb" */, (uint32_t)strlen(path)};
    int handle = call(SYS_OPEN, open_args);
    if (handle < 0) return -1;
    uint32_t read_args[3] = {(uint32_t)handle, (uint32_t)(uintptr_t)out, (uint32_t)size};
    int left = call(SYS_READ, read_args); /* the bytes not read */
    uint32_t close_args[1] = {(uint32_t)handle};
    call(SYS_CLOSE, close_args);
    return left == 0 ? 0 : -1;
}

void semihost_exit(int code) {
    uint32_t args[2] = {ADP_STOPPED_APPLICATION_EXIT, (uint32_t)code};
    call(SYS_EXIT_EXTENDED, args);
    for (;;) {
    }
}
