/*
 * nte_port_socketcan.c -- SocketCAN port of the node (see nte_port_socketcan.h).
 */
/* linux/can.h declares struct can_frame with an anonymous union (len / can_dlc), which ISO C99
 * does not have: this file alone is compiled without the pedantic diagnostic for it. */
#pragma GCC diagnostic ignored "-Wpedantic"

#include "nte_port_socketcan.h"

#include <errno.h>
#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

static int port_receive(void* ctx, nte_node_frame_t* frame)
{
    nte_port_socketcan_t* self = (nte_port_socketcan_t*)ctx;
    struct can_frame cf;
    const ssize_t n = recv(self->fd, &cf, sizeof cf, MSG_DONTWAIT);
    if (n < 0) {
        if ((errno == EAGAIN) || (errno == EWOULDBLOCK) || (errno == EINTR)) {
            return 0;
        }
        self->last_errno = errno;
        return -1;
    }
    if ((size_t)n != sizeof cf) {
        self->last_errno = EMSGSIZE;
        return -1;
    }
    frame->extended = (cf.can_id & CAN_EFF_FLAG) != 0u;
    frame->remote = (cf.can_id & (CAN_RTR_FLAG | CAN_ERR_FLAG)) != 0u;
    frame->id = cf.can_id & (frame->extended ? CAN_EFF_MASK : CAN_SFF_MASK);
    frame->len = (cf.len <= 8u) ? cf.len : 8u;
    memcpy(frame->data, cf.data, 8u);
    return 1;
}

static int port_send(void* ctx, const nte_node_frame_t* frame)
{
    nte_port_socketcan_t* self = (nte_port_socketcan_t*)ctx;
    struct can_frame cf;
    memset(&cf, 0, sizeof cf);
    cf.can_id = frame->id & CAN_SFF_MASK;
    cf.len = frame->len;
    memcpy(cf.data, frame->data, 8u);
    const ssize_t n = send(self->fd, &cf, sizeof cf, MSG_DONTWAIT);
    if (n != (ssize_t)sizeof cf) {
        self->last_errno = (n < 0) ? errno : EMSGSIZE;
        if (self->last_errno == ENOBUFS) {
            self->send_errors_enobufs++;
        }
        return -1;
    }
    return 0;
}

static uint64_t port_now_us(void* ctx)
{
    struct timespec ts;
    (void)ctx;
    (void)clock_gettime(CLOCK_MONOTONIC, &ts);
    return ((uint64_t)ts.tv_sec * 1000000u) + ((uint64_t)ts.tv_nsec / 1000u);
}

nte_node_port_t nte_port_socketcan_port(nte_port_socketcan_t* self)
{
    nte_node_port_t p;
    p.ctx = self;
    p.receive = port_receive;
    p.send = port_send;
    p.now_us = port_now_us;
    return p;
}

int nte_port_socketcan_open(nte_port_socketcan_t* self, const char* iface, const uint32_t* ids,
                            size_t n, char* msg, size_t msg_size)
{
    struct sockaddr_can addr;
    struct can_filter filters[8];
    self->fd = -1;
    self->last_errno = 0;
    self->send_errors_enobufs = 0u;
    const int fd = socket(PF_CAN, SOCK_RAW, CAN_RAW);
    if (fd < 0) {
        const int e = errno;
        (void)snprintf(msg, msg_size,
                       "AF_CAN (SocketCAN) is not available in this kernel: socket(PF_CAN, "
                       "SOCK_RAW, CAN_RAW): %s. Load the can and can-raw modules, or run "
                       "inside host_bench/with-vcan (a user-mode kernel with vcan0).",
                       strerror(e));
        return ((e == EAFNOSUPPORT) || (e == EPROTONOSUPPORT) || (e == EINVAL))
                   ? nte_port_err_no_af_can
                   : nte_port_err_other;
    }
    const unsigned idx = if_nametoindex(iface);
    if (idx == 0u) {
        (void)snprintf(msg, msg_size,
                       "no CAN interface '%s' (%s); create one with: ip link add dev %s type "
                       "vcan && ip link set up %s",
                       iface, strerror(errno), iface, iface);
        (void)close(fd);
        return nte_port_err_no_iface;
    }
    if (n > 0u) {
        const size_t m = (n < 8u) ? n : 8u;
        for (size_t i = 0u; i < m; i++) {
            filters[i].can_id = ids[i] & CAN_SFF_MASK;
            filters[i].can_mask = CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG;
        }
        if (setsockopt(fd, SOL_CAN_RAW, CAN_RAW_FILTER, filters,
                       (socklen_t)(m * sizeof filters[0])) != 0) {
            (void)snprintf(msg, msg_size, "setsockopt(CAN_RAW_FILTER): %s", strerror(errno));
            (void)close(fd);
            return nte_port_err_other;
        }
    }
    /* A deep receive queue: a loaded host may not schedule the node for a while (1 kHz depth
     * + 200 Hz force fill the default ~200-frame queue in 150 ms).  SO_RCVBUFFORCE needs
     * CAP_NET_ADMIN; otherwise SO_RCVBUF, capped by net.core.rmem_max. */
    {
        const int rcvbuf = NTE_PORT_SOCKETCAN_RCVBUF;
        if (setsockopt(fd, SOL_SOCKET, SO_RCVBUFFORCE, &rcvbuf, (socklen_t)sizeof rcvbuf) != 0) {
            (void)setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, (socklen_t)sizeof rcvbuf);
        }
    }
    memset(&addr, 0, sizeof addr);
    addr.can_family = AF_CAN;
    addr.can_ifindex = (int)idx;
    if (bind(fd, (struct sockaddr*)&addr, sizeof addr) != 0) {
        const int e = errno;
        (void)snprintf(msg, msg_size, "cannot bind a CAN socket to '%s': %s%s", iface, strerror(e),
                       (e == EINVAL) ? " (not a CAN interface?)" : "");
        (void)close(fd);
        return (e == ENODEV || e == EINVAL) ? nte_port_err_no_iface : nte_port_err_other;
    }
    self->fd = fd;
    return nte_port_ok;
}

void nte_port_socketcan_close(nte_port_socketcan_t* self)
{
    if (self->fd >= 0) {
        (void)close(self->fd);
        self->fd = -1;
    }
}
