/* ARM semihosting (the debugger's or the emulator's services, through BKPT 0xAB): what the
   emulated board uses of it. Under qemu-system-arm with -semihosting-config enable=on;
   on a board without a debugger attached a BKPT stops the processor, so a firmware for a
   real robot is built without it (SEMIHOST=0). */
#ifndef CR_SEMIHOST_H
#define CR_SEMIHOST_H
#include <stddef.h>
#include <stdint.h>

/* read size bytes of a host file into out: 0, or -1 */
int semihost_read_file(const char *path, uint8_t *out, size_t size);
/* end the emulation with exit code (0 to 255) */
void semihost_exit(int code) __attribute__((noreturn));
#endif
