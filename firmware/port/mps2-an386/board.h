/*
 * board.h -- the MPS2 AN386 (Cortex-M4F) support used by the images: semihosting, the
 * painted-stack high-water mark, the SysTick millisecond clock and a polled CMSDK UART.
 * Everything here is written for this project (no vendor SDK).  Not thread-safe, except
 * nte_board_now_us, which may be called while the SysTick interrupt runs.
 */
#ifndef NTE_BOARD_H
#define NTE_BOARD_H

#include <stdbool.h>
#include <stdint.h>

/* ---- semihosting (needs QEMU -semihosting-config enable=on,target=native) ------------- */
#define NTE_SH_SYS_WRITE0 0x04U
#define NTE_SH_SYS_EXIT_EXTENDED 0x20U
#define NTE_SH_ADP_STOPPED_APPLICATION_EXIT 0x20026U

/** The BKPT 0xAB call (startup.S): op in r0, arg in r1, result in r0. */
uint32_t nte_semihost(uint32_t op, const void* arg);
/** Writes a NUL-terminated string to the host (QEMU's stderr or its chardev). */
void nte_board_write0(const char* s);
/** Ends the run with SYS_EXIT_EXTENDED, QEMU's exit status = code.  Does not return. */
void nte_board_exit(int code);

/* ---- stack ---------------------------------------------------------------------------- */
/** Bytes of the stack region ever written since reset (startup.S painted it). */
uint32_t nte_board_stack_used(void);
/** Size of the stack region, bytes (linker script NTE_STACK_SIZE). */
uint32_t nte_board_stack_size(void);

/* ---- SysTick clock: 1 ms interrupt from the 25 MHz core clock ------------------------- */
#define NTE_BOARD_CPU_HZ 25000000U
void nte_board_clock_init(void);
/** Milliseconds since nte_board_clock_init (wraps after 49 days). */
uint32_t nte_board_now_ms(void);
/** Microseconds since nte_board_clock_init, monotonic, 64 bits. */
uint64_t nte_board_now_us(void);

/* ---- UART0 (CMSDK APB UART at 0x40004000, QEMU's first -serial), polled --------------- */
/** TX and RX on; bauddiv = core clock / baud (>= 16; 217 = 115200 Bd at 25 MHz). */
void nte_uart_init(uint32_t bauddiv);
/** Waits while the TX buffer is full, then writes one byte. */
void nte_uart_putc(uint8_t c);
void nte_uart_write(const char* s);
/** Non-blocking: true and *c set if a byte was received. */
bool nte_uart_getc(uint8_t* c);

#endif /* NTE_BOARD_H */
