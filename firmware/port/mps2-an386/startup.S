/*
 * startup.S -- reset handler, vector table and semihosting call for the Cortex-M4F of the
 * Arm MPS2 AN386 board (QEMU -M mps2-an386).  Written for this project; no vendor code.
 *
 * Reset: enable the FPU (CPACR CP10/CP11 full access, dsb, isb) BEFORE any C code -- with
 * -mfloat-abi=hard the compiler may place VFP instructions anywhere, and the first one would
 * fault with the FPU off -- then copy .data, zero .bss, paint the unused stack with
 * NTE_STACK_PAINT (for the high-water mark), call main() and pass its result to
 * nte_board_exit(), which does not return.
 */
    .syntax unified
    .cpu cortex-m4
    .fpu fpv4-sp-d16
    .thumb

    .equ CPACR, 0xE000ED88
    .equ NTE_STACK_PAINT, 0x5AA5C33C

/* ---- vector table: 16 system exceptions + 32 external interrupts (all unused) ---------- */
    .section .vectors, "a", %progbits
    .align 2
    .global nte_vectors
nte_vectors:
    .word __stack_top
    .word nte_reset_handler
    .word nte_fault_handler        /* NMI */
    .word nte_fault_handler        /* HardFault */
    .word nte_fault_handler        /* MemManage */
    .word nte_fault_handler        /* BusFault */
    .word nte_fault_handler        /* UsageFault */
    .word 0, 0, 0, 0               /* reserved */
    .word nte_fault_handler        /* SVCall */
    .word nte_fault_handler        /* DebugMonitor */
    .word 0                        /* reserved */
    .word nte_fault_handler        /* PendSV */
    .word nte_systick_handler      /* SysTick (weak default below) */
    .rept 32
    .word nte_fault_handler        /* IRQ 0..31 */
    .endr

/* ---- reset ---------------------------------------------------------------------------- */
    .section .text.nte_reset_handler, "ax", %progbits
    .align 2
    .global nte_reset_handler
    .type nte_reset_handler, %function
    .thumb_func
nte_reset_handler:
    /* FPU on: CPACR bits 20..23 (CP10, CP11 = full access) */
    ldr r0, =CPACR
    ldr r1, [r0]
    orr r1, r1, #(0xF << 20)
    str r1, [r0]
    dsb
    isb
    /* .data: copy its load image from flash */
    ldr r0, =__data_load
    ldr r1, =__data_start
    ldr r2, =__data_end
1:  cmp r1, r2
    bhs 2f
    ldr r3, [r0], #4
    str r3, [r1], #4
    b 1b
2:  /* .bss: zero */
    ldr r1, =__bss_start
    ldr r2, =__bss_end
    movs r3, #0
3:  cmp r1, r2
    bhs 4f
    str r3, [r1], #4
    b 3b
4:  /* paint the whole stack below the current (initial) stack pointer */
    ldr r1, =__stack_bottom
    mov r2, sp
    ldr r3, =NTE_STACK_PAINT
5:  cmp r1, r2
    bhs 6f
    str r3, [r1], #4
    b 5b
6:  bl main
    bl nte_board_exit
7:  b 7b
    .size nte_reset_handler, . - nte_reset_handler

/* ---- semihosting: uint32_t nte_semihost(uint32_t op, const void* arg) ------------------ */
    .section .text.nte_semihost, "ax", %progbits
    .align 2
    .global nte_semihost
    .type nte_semihost, %function
    .thumb_func
nte_semihost:
    bkpt 0xAB
    bx lr
    .size nte_semihost, . - nte_semihost

/* ---- default SysTick handler (the board image overrides it) --------------------------- */
    .section .text.nte_systick_default, "ax", %progbits
    .align 2
    .weak nte_systick_handler
    .type nte_systick_handler, %function
    .thumb_func
nte_systick_handler:
    bx lr
    .size nte_systick_handler, . - nte_systick_handler
