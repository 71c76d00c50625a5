/*
 * libFuzzer harness: the node loop (firmware/node) fed arbitrary CAN traffic through an in-memory
 * port.  The input is a sequence of 16-byte records:
 *   byte 0      kind selector: low 3 bits pick the id (0..2 = depth/force/command of the base,
 *               3..5 = the node's own output ids, 6 = arbitrary id from bytes 1..2, 7 = no frame,
 *               only a poll with the clock advanced); bit 3 = extended; bit 4 = remote;
 *               bit 5 = "fix the E2E CRC" (so that frames reach the decoders and the estimator);
 *               bit 6 = make send() fail; bit 7 = make receive() report an error
 *   byte 3      dlc (low 4 bits, 9..15 are passed as they are: the port contract says 0..8, the
 *               node must still not read past data[8])
 *   bytes 4..11 payload
 *   bytes 12..15 clock advance in microseconds (little endian, limited to 2^24)
 * Properties (abort() on violation): every Estimate frame the node sends passes its own decoder
 * with finite values; every node counter and every estimator counter is monotonic; the
 * estimator's state (u, z, P) stays finite; the node's rx budget bounds the frames per poll.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "nte_e2e.h"
#include "nte_frames.h"
#include "nte_node.h"

#define REC 16U
#define RX_QUEUE 8U

typedef struct {
    nte_node_frame_t rx[RX_QUEUE];
    unsigned rx_n;
    unsigned rx_pos;
    int rx_error;
    int send_fail;
    uint64_t now;
    unsigned sent;
    nte_e2e_rx_t est_rx;
    uint32_t base;
} fake_port_t;

static int fake_receive(void* ctx, nte_node_frame_t* frame)
{
    fake_port_t* p = (fake_port_t*)ctx;
    if (p->rx_error) {
        p->rx_error = 0;
        return -1;
    }
    if (p->rx_pos >= p->rx_n) {
        return 0;
    }
    *frame = p->rx[p->rx_pos++];
    return 1;
}

static void check_finite_f(float x)
{
    if (!isfinite(x)) {
        abort();
    }
}

static int fake_send(void* ctx, const nte_node_frame_t* frame)
{
    fake_port_t* p = (fake_port_t*)ctx;
    if ((frame->len > 8U) || frame->extended || frame->remote) {
        abort();
    }
    p->sent++;
    if (frame->id == p->base + 0x10U) {
        /* Every estimate is a valid frame of the DBC with finite values. */
        nte_frames_estimate_t e;
        nte_e2e_result_t r;
        nte_e2e_rx_reset(&p->est_rx); /* a failed send skips counters: check the CRC only */
        if (nte_frames_decode_estimate(&p->est_rx, frame->data, frame->len, &e, &r, NULL) !=
            nte_frames_ok) {
            abort();
        }
        check_finite_f(e.force_n);
        check_finite_f(e.innovation_n);
        check_finite_f(e.z);
    }
    if (p->send_fail) {
        return -1;
    }
    return 0;
}

static uint64_t fake_now(void* ctx) { return ((fake_port_t*)ctx)->now; }

static void check_state(const nte_node_t* n)
{
    const nte_t* e = &n->est;
    for (size_t i = 0U; i < sizeof e->u / sizeof e->u[0]; i++) {
        check_finite_f(e->u[i]);
    }
    check_finite_f(e->z);
    const nte_real_t* pp = &e->P[0][0][0];
    for (size_t i = 0U; i < sizeof e->P / sizeof e->P[0][0][0]; i++) {
        check_finite_f(pp[i]);
    }
    check_finite_f(e->last.force_hat_n);
    check_finite_f(e->last.z);
    check_finite_f(e->last.innovation_n);
    check_finite_f(n->last.force_n);
    check_finite_f(n->last.innovation_n);
    check_finite_f(n->last.z);
}

/* Every field of the counters is a uint32_t: compare them as an array. */
#define NODE_WORDS (sizeof(nte_node_counters_t) / sizeof(uint32_t))
#define EST_WORDS (sizeof(nte_counters_t) / sizeof(uint32_t))

static void check_monotonic(const uint32_t* before, const uint32_t* after, size_t words)
{
    for (size_t i = 0U; i < words; i++) {
        if (after[i] < before[i]) {
            abort();
        }
    }
}

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    static nte_node_t node; /* large: keep it off the stack */
    fake_port_t port;
    memset(&port, 0, sizeof port);
    port.now = 1000000U;
    nte_node_config_t cfg;
    nte_node_config_default(&cfg, 1);
    cfg.rx_budget = 4U;
    cfg.params_per_step = 7U;
    const nte_node_port_t pif = {&port, fake_receive, fake_send, fake_now};
    if (nte_node_init(&node, &cfg, &pif) != nte_node_ok) {
        abort();
    }
    port.base = cfg.base_id;
    if (nte_frames_rx_init(&port.est_rx, nte_frames_kind_estimate) != nte_frames_ok) {
        abort();
    }
    static const uint16_t data_id[6] = {19968U, 19969U, 19970U, 19984U, 19985U, 19986U};
    static const uint32_t offset[6] = {0x00U, 0x01U, 0x02U, 0x10U, 0x11U, 0x12U};

    for (size_t off = 0U; off + REC <= size; off += REC) {
        const uint8_t* r = data + off;
        const unsigned sel = r[0] & 7U;
        nte_node_frame_t f;
        memset(&f, 0, sizeof f);
        f.extended = (r[0] & 0x08U) != 0U;
        f.remote = (r[0] & 0x10U) != 0U;
        f.len = (uint8_t)(r[3] & 0x0FU);
        memcpy(f.data, r + 4, 8U);
        if (sel < 6U) {
            f.id = cfg.base_id + offset[sel];
            if (((r[0] & 0x20U) != 0U) && (f.len >= 2U) && (f.len <= 8U)) {
                f.data[0] = nte_e2e_frame_crc(data_id[sel], f.data, f.len);
            }
        } else {
            f.id = ((uint32_t)r[1] | ((uint32_t)r[2] << 8U)) & (f.extended ? 0x1FFFFFFFU : 0x7FFU);
        }
        if (f.len > 8U) {
            f.len = 8U; /* the port contract: len is 0..8 */
        }
        port.rx_n = 0U;
        port.rx_pos = 0U;
        if (sel != 7U) {
            port.rx[port.rx_n++] = f;
        }
        port.send_fail = (r[0] & 0x40U) != 0U;
        port.rx_error = (r[0] & 0x80U) != 0U;
        const uint32_t adv = ((uint32_t)r[12] | ((uint32_t)r[13] << 8U) | ((uint32_t)r[14] << 16U));
        port.now += adv;

        nte_node_counters_t c0 = node.counters;
        nte_counters_t e0 = node.est.counters;
        const int32_t model0 = node.model;
        const int32_t got = nte_node_poll(&node);
        if ((got < 0) || ((uint32_t)got > cfg.rx_budget) || ((uint32_t)got > port.rx_n)) {
            abort();
        }
        check_monotonic((const uint32_t*)&c0, (const uint32_t*)&node.counters, NODE_WORDS);
        /* The estimator clears its counters on reset and model change (documented): compare only
         * while no command was accepted in this poll. */
        if ((node.counters.rx_accepted[2] == c0.rx_accepted[2]) && (node.model == model0)) {
            check_monotonic((const uint32_t*)&e0, (const uint32_t*)&node.est.counters, EST_WORDS);
        }
        check_state(&node);
        if ((nte_node_model(&node) < 1) || (nte_node_model(&node) > 3)) { /* I, II, III */
            abort();
        }
        if (nte_node_next_deadline_us(&node) < port.now) {
            abort();
        }
    }
    return 0;
}
