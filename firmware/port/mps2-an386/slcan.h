/*
 * slcan.h -- the node's CAN port over a serial line speaking SLCAN (Lawicel ASCII), on the
 * board's polled UART0.  The host side is e.g. python-can's "slcan" interface on QEMU's
 * -serial tcp:... socket.
 *
 * Received commands (each ends with '\r'):
 *   tIIIL<DD x L>  standard data frame -> handed to the node (no reply, to save the link)
 *   TIIIIIIIIL<DD> extended data frame -> handed to the node flagged extended (counted unknown)
 *   rIIIL / RIIIIIIIIL remote frames -> handed to the node flagged remote (counted unknown)
 *   O  open the channel (frames are sent only while open)     reply '\r'
 *   C  close the channel                                        reply '\r'
 *   Sn, sXXYY, L, Z0/Z1, F, X, M/m..., empty line: accepted     reply '\r'
 *   V  version                                                  reply "V0100\r"
 *   anything else, malformed frames, over-long lines            reply '\a' (BEL), counted
 * Sent frames: tIIIL<DD x L>'\r' (the node only sends standard data frames).
 */
#ifndef NTE_SLCAN_H
#define NTE_SLCAN_H

#include <stdbool.h>
#include <stdint.h>

#include "nte_node.h"

#define NTE_SLCAN_LINE_MAX 32U /* "T" + 8 + 1 + 16 = 26 characters at most */

typedef struct nte_slcan_t {
    char line[NTE_SLCAN_LINE_MAX];
    uint32_t len;
    bool overflow; /* current line too long: discard until '\r' */
    bool open;
    uint32_t bad_lines; /* malformed or unknown commands (answered with BEL) */
} nte_slcan_t;

void nte_slcan_init(nte_slcan_t* self);
/** nte_node_port_t.receive: ctx is the nte_slcan_t. */
int nte_slcan_receive(void* ctx, nte_node_frame_t* frame);
/** nte_node_port_t.send: ctx is the nte_slcan_t; -1 while the channel is closed. */
int nte_slcan_send(void* ctx, const nte_node_frame_t* frame);
/** Parses one line (without '\r'); 1 = frame filled, 0 = command handled, -1 = bad line.
 *  Writes the reply, if any, to reply (at least 8 bytes, NUL-terminated; "" = none). */
int nte_slcan_parse(nte_slcan_t* self, const char* line, uint32_t len, nte_node_frame_t* frame,
                    char* reply);

#endif /* NTE_SLCAN_H */
