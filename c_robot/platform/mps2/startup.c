/* The unit tests on qemu's mps2-an386 (a Cortex-M4 with 4 + 4 + 16 MB of RAM): a vector
   table whose reset turns the FPU on and hands over to newlib's semihosting start
   (rdimon.specs: the command line, standard output and the vector files come from the
   host through semihosting). */
#include <stdint.h>

extern uint32_t __stack_top;
extern void _start(void);
void Reset_Handler(void);

static void Fault_Handler(void) {
    for (;;) {
    }
}

__attribute__((section(".isr_vector"), used)) static void (*const vectors[16])(void) = {
    [0] = (void (*)(void))&__stack_top,
    [1] = Reset_Handler,
    [2] = Fault_Handler,
    [3] = Fault_Handler,
    [4] = Fault_Handler,
    [5] = Fault_Handler,
    [6] = Fault_Handler,
};

void Reset_Handler(void) {
    *(volatile uint32_t *)0xE000ED88u |= 0xFu << 20; /* CPACR: the FPU */
    __asm__ volatile("dsb\n isb");
    _start();
}
