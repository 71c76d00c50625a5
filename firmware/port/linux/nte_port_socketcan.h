/*
 * nte_port_socketcan.h -- the node's port (nte_node_port_t) on Linux SocketCAN.
 *
 * A raw CAN socket bound to one interface, non-blocking, with kernel receive filters for the
 * node's input ids (or none: everything is received and the node counts foreign ids), error
 * frames not subscribed, own frames not looped back to itself.  The clock is CLOCK_MONOTONIC.
 * Not thread-safe; no allocation.
 */
#ifndef NTE_PORT_SOCKETCAN_H
#define NTE_PORT_SOCKETCAN_H

#include <stddef.h>
#include <stdint.h>

#include "nte_node.h"

/** Receive buffer requested, bytes (about 1 KiB of kernel memory per queued frame). */
#ifndef NTE_PORT_SOCKETCAN_RCVBUF
#define NTE_PORT_SOCKETCAN_RCVBUF (8 * 1024 * 1024)
#endif

/** Open results (0 = success). */
enum {
    nte_port_ok = 0,
    nte_port_err_other = -1,     /**< any other failure (message says which call) */
    nte_port_err_no_af_can = -2, /**< the kernel has no AF_CAN / CAN_RAW */
    nte_port_err_no_iface = -3   /**< no such interface, or it is not a CAN interface */
};

typedef struct nte_port_socketcan_t {
    int fd;
    int last_errno;               /**< errno of the last failed send or receive */
    uint32_t send_errors_enobufs; /**< failed sends with ENOBUFS (TX queue / bus full) */
} nte_port_socketcan_t;

/** Open `iface`; `ids` (n of them, standard 11-bit) become exact kernel filters, n = 0 means
 *  no filter.  On failure writes a one-line explanation to msg. */
int nte_port_socketcan_open(nte_port_socketcan_t* self, const char* iface, const uint32_t* ids,
                            size_t n, char* msg, size_t msg_size);
void nte_port_socketcan_close(nte_port_socketcan_t* self);
/** The nte_node_port_t functions over this socket (ctx = self). */
nte_node_port_t nte_port_socketcan_port(nte_port_socketcan_t* self);

#endif /* NTE_PORT_SOCKETCAN_H */
