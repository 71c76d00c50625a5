/*
 * board.c -- see board.h.  Register maps from the Arm Cortex-M4 (SCB, SysTick) and CMSDK APB
 * UART documentation, as summarised in the project's platform notes.
 */
#include "board.h"

#include <stddef.h>

#define REG32(addr) (*(volatile uint32_t*)(uintptr_t)(addr))

/* ---- semihosting ---------------------------------------------------------------------- */
void nte_board_write0(const char* s) { (void)nte_semihost(NTE_SH_SYS_WRITE0, s); }

void nte_board_exit(int code)
{
    uint32_t block[2];
    block[0] = NTE_SH_ADP_STOPPED_APPLICATION_EXIT;
    block[1] = (uint32_t)code;
    for (;;) {
        (void)nte_semihost(NTE_SH_SYS_EXIT_EXTENDED, block);
    }
}

/* ---- faults: report CFSR/HFSR and the stacked PC, exit 3 ------------------------------ */
static char* put_hex(char* p, uint32_t v)
{
    static const char HEX[] = "0123456789abcdef";
    for (int i = 7; i >= 0; i--) {
        *p = HEX[(v >> (4U * (uint32_t)i)) & 0xFU];
        p++;
    }
    return p;
}

void nte_fault_handler(void);
void nte_fault_handler(void)
{
    char msg[64];
    char* p = msg;
    const char* head = "FAULT cfsr=";
    while (*head != '\0') {
        *p = *head;
        p++;
        head++;
    }
    p = put_hex(p, REG32(0xE000ED28U)); /* CFSR */
    *p = ' ';
    p++;
    p = put_hex(p, REG32(0xE000ED2CU)); /* HFSR */
    *p = ' ';
    p++;
    p = put_hex(p, REG32(0xE000ED04U)); /* ICSR (VECTACTIVE in bits 0..8) */
    *p = '\n';
    p[1] = '\0';
    nte_board_write0(msg);
    nte_board_exit(3);
}

/* ---- stack high-water mark ------------------------------------------------------------ */
extern uint32_t __stack_bottom[];
extern uint32_t __stack_top[];
#define NTE_STACK_PAINT 0x5AA5C33CU

uint32_t nte_board_stack_size(void)
{
    return (uint32_t)((uintptr_t)__stack_top - (uintptr_t)__stack_bottom);
}

uint32_t nte_board_stack_used(void)
{
    const volatile uint32_t* w = __stack_bottom;
    while (((uintptr_t)w < (uintptr_t)__stack_top) && (*w == NTE_STACK_PAINT)) {
        w++;
    }
    return (uint32_t)((uintptr_t)__stack_top - (uintptr_t)w);
}

/* ---- SysTick -------------------------------------------------------------------------- */
#define SYST_CSR 0xE000E010U
#define SYST_RVR 0xE000E014U
#define SYST_CVR 0xE000E018U
#define SYST_CSR_ENABLE (1U << 0U)
#define SYST_CSR_TICKINT (1U << 1U)
#define SYST_CSR_CLKSOURCE (1U << 2U) /* processor clock */
#define SYST_RELOAD ((NTE_BOARD_CPU_HZ / 1000U) - 1U)

static volatile uint32_t g_ms;

void nte_systick_handler(void);
void nte_systick_handler(void) { g_ms = g_ms + 1U; }

void nte_board_clock_init(void)
{
    REG32(SYST_CSR) = 0U;
    REG32(SYST_RVR) = SYST_RELOAD;
    REG32(SYST_CVR) = 0U;
    g_ms = 0U;
    REG32(SYST_CSR) = SYST_CSR_ENABLE | SYST_CSR_TICKINT | SYST_CSR_CLKSOURCE;
}

uint32_t nte_board_now_ms(void) { return g_ms; }

uint64_t nte_board_now_us(void)
{
    /* extend the 32-bit millisecond count to 64 bits; the caller polls far more often than
       every 49 days, so one wrap between calls is all that can happen */
    static uint32_t last_ms;
    static uint32_t wraps;
    uint32_t ms;
    uint32_t cvr;
    do {
        ms = g_ms;
        cvr = REG32(SYST_CVR);
    } while (ms != g_ms);
    if (ms < last_ms) {
        wraps++;
    }
    last_ms = ms;
    const uint32_t sub_us = (SYST_RELOAD - (cvr & 0xFFFFFFU)) / (NTE_BOARD_CPU_HZ / 1000000U);
    return ((((uint64_t)wraps << 32U) | ms) * 1000U) + (sub_us < 1000U ? sub_us : 999U);
}

/* ---- CMSDK APB UART0 ------------------------------------------------------------------ */
#define UART0_BASE 0x40004000U
#define UART_DATA (UART0_BASE + 0x00U)
#define UART_STATE (UART0_BASE + 0x04U)
#define UART_CTRL (UART0_BASE + 0x08U)
#define UART_BAUDDIV (UART0_BASE + 0x10U)
#define UART_STATE_TXFULL (1U << 0U)
#define UART_STATE_RXFULL (1U << 1U)
#define UART_CTRL_TXEN (1U << 0U)
#define UART_CTRL_RXEN (1U << 1U)

void nte_uart_init(uint32_t bauddiv)
{
    REG32(UART_CTRL) = 0U;
    REG32(UART_BAUDDIV) = (bauddiv < 16U) ? 16U : bauddiv;
    REG32(UART_CTRL) = UART_CTRL_TXEN | UART_CTRL_RXEN;
}

void nte_uart_putc(uint8_t c)
{
    while ((REG32(UART_STATE) & UART_STATE_TXFULL) != 0U) {
    }
    REG32(UART_DATA) = c;
}

void nte_uart_write(const char* s)
{
    while (*s != '\0') {
        nte_uart_putc((uint8_t)*s);
        s++;
    }
}

bool nte_uart_getc(uint8_t* c)
{
    if ((REG32(UART_STATE) & UART_STATE_RXFULL) == 0U) {
        return false;
    }
    *c = (uint8_t)(REG32(UART_DATA) & 0xFFU);
    return true;
}
