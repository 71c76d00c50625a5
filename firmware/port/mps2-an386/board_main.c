/*
 * board_main.c -- nte-board.elf: the estimator node on the MPS2 AN386 board.  The node loop
 * (firmware/node) runs over SLCAN on UART0 (slcan.h), with the SysTick clock as its port
 * clock.  Run it under QEMU with UART0 on a TCP socket:
 *
 *   qemu-system-arm -M mps2-an386 -cpu cortex-m4 -display none -monitor none \
 *       -serial tcp:127.0.0.1:5555,server=on,wait=off,nodelay=on -kernel nte-board.elf
 *
 * and talk to it with python-can: can.Bus(interface="slcan",
 * channel="socket://127.0.0.1:5555", bitrate=500000, sleep_after_open=0).
 * The image uses no semihosting unless it faults (then QEMU stops: "Lockup" without it).
 */
#include "board.h"
#include "nte_node.h"
#include "slcan.h"

#define NTE_UART_BAUDDIV 217U /* 115200 Bd at 25 MHz */

static nte_node_t g_node;
static nte_slcan_t g_slcan;

static uint64_t port_now_us(void* ctx)
{
    (void)ctx;
    return nte_board_now_us();
}

/* The node's configuration (one estimator configuration per model, ~0.8 KiB) is needed only
 * while the node starts: kept in this function's frame, which is gone before the loop runs,
 * rather than in main's, which would hold it under the deepest path of every step (the stack
 * budget, figures.py) or in RAM for good. */
static int start_node(void) __attribute__((noinline));
static int start_node(void)
{
    nte_node_config_t cfg;
    nte_node_config_default(&cfg, 2);
    nte_node_port_t port;
    port.ctx = &g_slcan;
    port.receive = nte_slcan_receive;
    port.send = nte_slcan_send;
    port.now_us = port_now_us;
    return (nte_node_init(&g_node, &cfg, &port) == nte_node_ok) ? 0 : -1;
}

int main(void);
int main(void)
{
    nte_board_clock_init();
    nte_uart_init(NTE_UART_BAUDDIV);
    nte_slcan_init(&g_slcan);
    if (start_node() != 0) {
        for (;;) {
            nte_uart_write("\a"); /* configuration refused: nothing else to do */
        }
    }
    for (;;) {
        (void)nte_node_poll(&g_node);
    }
}
