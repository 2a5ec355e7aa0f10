/* Reset and the vector table of the STM32F405: the FPU on, .data copied and .bss zeroed,
   the stack filled with a pattern (board_stack_peak reads how deep it went), then main. */
#include <stdint.h>

extern uint32_t _sidata, _sdata, _edata, _sbss, _ebss, __stack_start, _estack;
extern int main(void);
extern void __libc_init_array(void);
void Reset_Handler(void);
void SysTick_Handler(void);
void USART1_IRQHandler(void);

static void Fault_Handler(void) {
    for (;;) {
    }
}

#define IRQS 82
__attribute__((section(".isr_vector"), used)) static void (*const vectors[16 + IRQS])(void) = {
    [0] = (void (*)(void))&_estack,
    [1] = Reset_Handler,
    [2] = Fault_Handler, /* NMI */
    [3] = Fault_Handler, /* HardFault */
    [4] = Fault_Handler, /* MemManage */
    [5] = Fault_Handler, /* BusFault */
    [6] = Fault_Handler, /* UsageFault */
    [11] = Fault_Handler, /* SVCall */
    [14] = Fault_Handler, /* PendSV */
    [15] = SysTick_Handler,
    [16 + 37] = USART1_IRQHandler,
};

__attribute__((noreturn)) void Reset_Handler(void) {
    *(volatile uint32_t *)0xE000ED88u |= 0xFu << 20; /* CPACR: CP10 and CP11, full access */
    __asm__ volatile("dsb\n isb");
    for (uint32_t *from = &_sidata, *to = &_sdata; to < &_edata;) *to++ = *from++;
    for (uint32_t *to = &_sbss; to < &_ebss;) *to++ = 0;
    uint32_t *sp;
    __asm__ volatile("mov %0, sp" : "=r"(sp));
    for (uint32_t *word = &__stack_start; word < sp - 16;) *word++ = 0xA5A5A5A5u;
    __libc_init_array();
    main();
    for (;;) {
    }
}
