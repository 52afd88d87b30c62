/*
 * startup.c - bare-metal start of the embedded test program on a Cortex-M4F (QEMU
 * mps2-an386): vector table, reset handler (FPU on, .data copied, .bss zeroed), fault
 * handler, and semihosting (SYS_WRITE0 for output, SYS_EXIT_EXTENDED so that QEMU exits
 * with the program's status). Nothing here comes from a vendor or C library start file.
 */
#include <stdint.h>

#include "platform.h"

extern uint32_t __data_load, __data_start, __data_end, __bss_start, __bss_end, __stack_top;
extern int main(void);
void embedded_reset(void);
void embedded_fault(void);

/* ARM semihosting on M-profile: BKPT 0xAB, operation in r0, argument in r1, result in r0. */
static int semihost(int op, const void *arg)
{
    register int r0 __asm__("r0") = op;
    register const void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xAB" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}

#define SYS_WRITE0 0x04
#define SYS_EXIT_EXTENDED 0x20
#define ADP_STOPPED_APPLICATION_EXIT 0x20026

void platform_write(const char *text)
{
    semihost(SYS_WRITE0, text);
}

void platform_exit(int status)
{
    uint32_t block[2];
    block[0] = ADP_STOPPED_APPLICATION_EXIT;
    block[1] = (uint32_t)status;
    semihost(SYS_EXIT_EXTENDED, block);
    for (;;) {
    }
}

void embedded_fault(void)
{
    platform_write("FAULT: hard fault or unexpected exception\n");
    platform_exit(99);
}

void embedded_reset(void)
{
    uint32_t *src = &__data_load, *dst;
    /* CPACR: full access to coprocessors 10 and 11 (the FPU), before any FP instruction */
    *(volatile uint32_t *)0xE000ED88u |= (0xFu << 20);
    __asm__ volatile("dsb\n\tisb" ::: "memory");
    for (dst = &__data_start; dst < &__data_end;) {
        *dst++ = *src++;
    }
    for (dst = &__bss_start; dst < &__bss_end;) {
        *dst++ = 0u;
    }
    platform_exit(main());
}

typedef void (*vector)(void);

/* Initial stack pointer, reset, then NMI, HardFault, MemManage, BusFault, UsageFault. */
__attribute__((section(".vectors"), used)) static const vector vectors[16] = {
    (vector)(uintptr_t)&__stack_top, embedded_reset, embedded_fault, embedded_fault,
    embedded_fault, embedded_fault, embedded_fault, 0, 0, 0, 0, embedded_fault,
    embedded_fault, 0, embedded_fault, embedded_fault,
};
