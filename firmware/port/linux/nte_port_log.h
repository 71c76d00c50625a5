/*
 * nte_port_log.h -- the node's port (nte_node_port_t) over candump log files: replay without a
 * CAN interface.
 *
 * receive() reads the next frame of a `candump -L` log ("(SEC.USEC) IFACE ID#DATA", 3 hex
 * digits for a standard id, 8 for an extended one, "ID#R" for a remote frame); send() appends
 * the frame in the same format, stamped with the time of the last frame read; now_us() is that
 * time (the log's clock), so heartbeats fall where they would have on the bus.  Results are
 * deterministic: the same log gives the same output file, byte for byte.  Malformed lines are
 * counted and skipped.  Not thread-safe; no allocation.
 */
#ifndef NTE_PORT_LOG_H
#define NTE_PORT_LOG_H

#include <stdint.h>
#include <stdio.h>

#include "nte_node.h"

typedef struct nte_port_log_t {
    FILE* in;
    FILE* out;           /**< NULL: sent frames are discarded (but counted) */
    const char* iface;   /**< interface name written on output lines */
    uint64_t now_us;     /**< time of the last frame read */
    uint32_t lines_bad;  /**< input lines that are not a CAN frame */
    uint32_t frames_in;  /**< frames read */
    uint32_t frames_out; /**< frames written */
    int eof;             /**< 1 once the input is exhausted */
} nte_port_log_t;

/** The nte_node_port_t functions over these files (ctx = self). */
nte_node_port_t nte_port_log_port(nte_port_log_t* self);

#endif /* NTE_PORT_LOG_H */
