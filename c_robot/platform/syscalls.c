/* What newlib asks of the system, bare metal: a heap between the linker script's
   __heap_start and __heap_end (its top kept, board_heap_peak), standard output and error to
   the log, and no files. Only snprintf, strtod and the like use the heap (the robot never
   calls malloc). */
#include <errno.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/stat.h>

#include "board.h"

extern uint8_t __heap_start, __heap_end;
static uint8_t *heap_top = &__heap_start, *heap_peak = &__heap_start;

void *_sbrk(ptrdiff_t increment) {
    uint8_t *before = heap_top;
    if (increment > &__heap_end - heap_top || increment < &__heap_start - heap_top) {
        errno = ENOMEM;
        return (void *)-1;
    }
    heap_top += increment;
    if (heap_top > heap_peak) heap_peak = heap_top;
    return before;
}

size_t board_heap_peak(void) { return (size_t)(heap_peak - &__heap_start); }

int _write(int file, const char *data, int size) {
    if (file != 1 && file != 2) {
        errno = EBADF;
        return -1;
    }
    board_log(data, (size_t)size);
    return size;
}

int _read(int file, char *data, int size) {
    (void)file, (void)data, (void)size;
    errno = EBADF;
    return -1;
}

int _close(int file) {
    (void)file;
    errno = EBADF;
    return -1;
}

int _fstat(int file, struct stat *st) {
    (void)file;
    st->st_mode = S_IFCHR;
    return 0;
}

int _isatty(int file) { return file == 1 || file == 2; }

int _lseek(int file, int offset, int whence) {
    (void)file, (void)offset, (void)whence;
    errno = ESPIPE;
    return -1;
}

int _getpid(void) { return 1; }

int _kill(int pid, int signal) {
    (void)pid, (void)signal;
    errno = EINVAL;
    return -1;
}

void _exit(int code) { board_halt(code); }
