/* What a board gives the robot's firmware (platform/firmware.c): the platform layer. The
   robot itself (c_robot/src/) needs nothing else of the hardware. platform/stm32f4/ is one
   board: the STM32F405 of a Netduino Plus 2, as qemu-system-arm models it. A port to
   another microcontroller writes these functions and links the same firmware. */
#ifndef CR_BOARD_H
#define CR_BOARD_H
#include <stddef.h>
#include <stdint.h>

/* Clocks, the link's UART and its receive ring, the log's sink, the motors (stopped). */
void board_init(void);

/* The monotonic clock, in ticks of BOARD_CLOCK_HZ since start: 64 bits, so it never wraps
   (a 32-bit millisecond counter would after 49.7 days), and never runs back. */
uint64_t board_clock(void);
extern const uint32_t board_clock_hz;

/* The link's UART, 8N1: the bytes the receive ring holds (received by interrupt, so none
   is lost while the robot steps), up to cap; 0 when none. A byte that came while the ring
   was full is lost and counted (board_link_overruns), as the link's CRC will find. */
size_t board_link_read(uint8_t *out, size_t cap);
uint32_t board_link_overruns(void);
/* Send bytes on the link's UART; returns once the transmitter has taken them (a real
   UART paces itself at its baud rate). */
void board_link_write(const uint8_t *bytes, size_t size);

/* Wait for the next interrupt (a byte received, the clock's tick, at most 1 ms): what the
   processor does while the robot has nothing to do. */
void board_idle(void);

/* The log's sink: one line, with its newline (a second UART here). */
void board_log(const char *line, size_t size);

/* Entropy for the link's nonces: 0 and size bytes, or -1 (no source, or it failed: the
   robot then stops; there is never a fixed fallback). The source is a build choice:
   ENTROPY=rng (the chip's hardware generator), semihost (the emulator's host, through
   semihosting), none. */
int board_entropy(uint8_t *out, size_t size);

/* The key record (platform/key_record.h) where the board keeps it in flash: its bytes
   and how many may be read. */
const uint8_t *board_key_record(size_t *size);

/* The wheels, in m/s; 0, 0 stops them. The firmware's motor guard decides what to give. */
void board_motors(double left, double right);

/* The firmware's end (0: the run ended; 1: it cannot run; 2: no usable key): the wheels
   stopped, and on an emulator the emulation ends with the code. */
void board_halt(int code) __attribute__((noreturn));

/* What the firmware used, for its figures: the deepest the stack went and the heap's top,
   in bytes (the stack is filled with a pattern at reset and read back). */
size_t board_stack_peak(void);
size_t board_heap_peak(void);
#endif
