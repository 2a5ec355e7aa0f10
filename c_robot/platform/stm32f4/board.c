/* The board: an STM32F405 (Cortex-M4F, 1 MB of flash, 192 KB of RAM) as qemu-system-arm's
   `netduinoplus2` models it. USART1 is the link (its receive ring filled by interrupt),
   USART2 the log, SysTick the clock, the RNG peripheral the entropy (ENTROPY=rng), and the
   key record sits in the last flash sector.

   What qemu does not model, and a board file for the silicon adds: the clock tree (qemu's
   runs at 168 MHz from reset; the chip starts on its 16 MHz internal oscillator and needs
   its PLL set, RM0090 6.3), the GPIO pins' alternate functions for the two USARTs, a DMA
   receive ring for rates where one byte's time is shorter than the longest interrupt
   latency (a USART holds one byte), and the RNG (qemu has none: the ENTROPY=rng build
   refuses to start under it). Register addresses and bits are RM0090's. */
#include <stddef.h>
#include <stdint.h>

#include "board.h"
#include "limits.h"
#if SEMIHOST
#include "semihost.h"
#endif

#define REG(address) (*(volatile uint32_t *)(address))

#define RCC_AHB2ENR 0x40023834u
#define RCC_APB1ENR 0x40023840u
#define RCC_APB2ENR 0x40023844u
#define USART1 0x40011000u
#define USART2 0x40004400u
#define USART_SR 0x00u
#define USART_DR 0x04u
#define USART_BRR 0x08u
#define USART_CR1 0x0Cu
#define SR_ORE (1u << 3)
#define SR_RXNE (1u << 5)
#define SR_TXE (1u << 7)
#define CR1_RE (1u << 2)
#define CR1_TE (1u << 3)
#define CR1_RXNEIE (1u << 5)
#define CR1_UE (1u << 13)
#define USART1_IRQ 37u
#define NVIC_ISER 0xE000E100u
#define SYSTICK_CTRL 0xE000E010u
#define SYSTICK_LOAD 0xE000E014u
#define SYSTICK_VAL 0xE000E018u
#define SCB_ICSR 0xE000ED04u
#define ICSR_PENDSTSET (1u << 26)
#define RNG_CR 0x50060800u
#define RNG_SR 0x50060804u
#define RNG_DR 0x50060808u

#define SYSCLK_HZ 168000000u
#define PCLK1_HZ (SYSCLK_HZ / 4) /* APB1: USART2 */
#define PCLK2_HZ (SYSCLK_HZ / 2) /* APB2: USART1 */
#define TICKS_PER_MS (SYSCLK_HZ / 1000u)
#ifndef LINK_BAUD
#define LINK_BAUD 115200u
#endif
#define LOG_BAUD 115200u
/* The key record: the last flash sector, 128 KB at 0x080E0000. */
#define KEY_RECORD_ADDRESS 0x080E0000u
#define KEY_RECORD_BYTES (KEY_FILE_BYTES + 16)

const uint32_t board_clock_hz = SYSCLK_HZ;

/* --- the clock ------------------------------------------------------------------------ */

static volatile uint64_t milliseconds;

void SysTick_Handler(void) { milliseconds++; }

uint64_t board_clock(void) {
    uint64_t ms;
    uint32_t value, pending;
    do { /* a SysTick interrupt between the reads: read again */
        ms = milliseconds;
        value = REG(SYSTICK_VAL);
        pending = REG(SCB_ICSR) & ICSR_PENDSTSET;
    } while (ms != milliseconds);
    /* the counter wrapped and its interrupt is not taken yet: that millisecond is over
       (a value still near 0 was read before the wrap) */
    if (pending && value > TICKS_PER_MS / 2) ms++;
    return ms * TICKS_PER_MS + (TICKS_PER_MS - 1u - value);
}

/* --- the link's UART: a receive ring filled by interrupt ------------------------------- */

/* A power of two: 355 ms of line at 115200 baud, 44 ms at 921600, longer than the longest
   step (5.3M instructions, about 32 ms at 168 MHz), during which the loop reads nothing. */
#define RING_BYTES 4096u
static volatile uint8_t ring[RING_BYTES];
static volatile uint32_t ring_head, ring_tail; /* written by the interrupt, by the loop */
static volatile uint32_t overruns;

void USART1_IRQHandler(void) {
    uint32_t status = REG(USART1 + USART_SR);
    if (status & (SR_RXNE | SR_ORE)) {
        uint8_t byte = (uint8_t)REG(USART1 + USART_DR); /* reading DR clears RXNE and ORE */
        if (status & SR_ORE) overruns++; /* the USART lost a byte before this one */
        uint32_t head = ring_head;
        if (head - ring_tail < RING_BYTES) {
            ring[head % RING_BYTES] = byte;
            ring_head = head + 1;
        } else {
            overruns++;
        }
    }
}

size_t board_link_read(uint8_t *out, size_t cap) {
    size_t n = 0;
    uint32_t tail = ring_tail, head = ring_head;
    while (n < cap && tail != head) out[n++] = ring[tail++ % RING_BYTES];
    ring_tail = tail;
    return n;
}

uint32_t board_link_overruns(void) { return overruns; }

static void usart_write(uint32_t usart, const uint8_t *bytes, size_t size) {
    for (size_t i = 0; i < size; i++) {
        while (!(REG(usart + USART_SR) & SR_TXE)) {
        }
        REG(usart + USART_DR) = bytes[i];
    }
}

void board_link_write(const uint8_t *bytes, size_t size) { usart_write(USART1, bytes, size); }

void board_idle(void) {
    /* a byte that came after the ring was read wakes the processor from WFI at once (its
       interrupt is pending), as does the clock's tick */
    __asm__ volatile("wfi");
}

void board_log(const char *line, size_t size) {
    usart_write(USART2, (const uint8_t *)line, size);
}

/* --- entropy ---------------------------------------------------------------------------- */

#if ENTROPY_RNG
/* The RNG peripheral (RM0090 24): a word when DRDY is set, unless a seed or clock error is
   flagged; the first word after enabling is discarded, and two equal words in a row are a
   failure (the continuous test the reference manual asks of software). */
#define RNG_TRIES 100000u
static int rng_word(uint32_t *word) {
    for (uint32_t i = 0; i < RNG_TRIES; i++) {
        uint32_t status = REG(RNG_SR);
        if (status & 0x66u) return -1; /* SEIS, CEIS, SECS, CECS */
        if (status & 1u) {
            *word = REG(RNG_DR);
            return 0;
        }
    }
    return -1; /* never ready: no generator */
}

int board_entropy(uint8_t *out, size_t size) {
    static int started;
    static uint32_t last;
    if (!started) {
        REG(RCC_AHB2ENR) |= 1u << 6; /* RNGEN */
        REG(RNG_CR) |= 1u << 2;      /* RNGEN */
        if (rng_word(&last) != 0) return -1;
        started = 1;
    }
    for (size_t i = 0; i < size; i += 4) {
        uint32_t word;
        if (rng_word(&word) != 0 || word == last) return -1;
        last = word;
        for (size_t k = 0; k < 4 && i + k < size; k++) out[i + k] = (uint8_t)(word >> (8 * k));
    }
    return 0;
}
#elif ENTROPY_SEMIHOST
/* Under emulation only: the host's generator, through semihosting. */
int board_entropy(uint8_t *out, size_t size) {
    return semihost_read_file("/dev/urandom", out, size);
}
#else
/* A board with no source of entropy: the robot refuses to start. */
int board_entropy(uint8_t *out, size_t size) {
    (void)out;
    (void)size;
    return -1;
}
#endif

/* --- the rest ------------------------------------------------------------------------- */

const uint8_t *board_key_record(size_t *size) {
    *size = KEY_RECORD_BYTES;
    return (const uint8_t *)KEY_RECORD_ADDRESS;
}

/* The Netduino has no wheels: the speeds are kept, where a robot's board sets its motor
   drivers' PWM. */
static volatile double wheel_left, wheel_right;

void board_motors(double left, double right) {
    wheel_left = left;
    wheel_right = right;
}

extern uint32_t __stack_start, _estack; /* the linker script's */
#define STACK_PATTERN 0xA5A5A5A5u

size_t board_stack_peak(void) {
    const uint32_t *word = &__stack_start;
    while (word < &_estack && *word == STACK_PATTERN) word++;
    return (size_t)((const uint8_t *)&_estack - (const uint8_t *)word);
}

void board_halt(int code) {
    board_motors(0.0, 0.0);
#if SEMIHOST
    semihost_exit(code);
#else
    (void)code;
    for (;;) __asm__ volatile("wfi");
#endif
}

static void usart_start(uint32_t usart, uint32_t pclk, uint32_t baud, uint32_t interrupts) {
    REG(usart + USART_BRR) = (pclk + baud / 2) / baud; /* 16x oversampling */
    REG(usart + USART_CR1) = CR1_UE | CR1_TE | CR1_RE | interrupts;
}

void board_init(void) {
    REG(RCC_APB2ENR) |= 1u << 4;  /* USART1EN */
    REG(RCC_APB1ENR) |= 1u << 17; /* USART2EN */
    usart_start(USART2, PCLK1_HZ, LOG_BAUD, 0);
    usart_start(USART1, PCLK2_HZ, LINK_BAUD, CR1_RXNEIE);
    REG(NVIC_ISER + 4 * (USART1_IRQ / 32)) = 1u << (USART1_IRQ % 32);
    REG(SYSTICK_LOAD) = TICKS_PER_MS - 1u;
    REG(SYSTICK_VAL) = 0;
    REG(SYSTICK_CTRL) = 7u; /* the processor's clock, its interrupt, on */
}
