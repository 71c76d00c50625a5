/* cmocka tests of firmware/can/nte_frames: ids, round trips at range ends and at one
 * resolution step, range and selector errors, NaN/inf, E2E failures, clamping of outputs, the
 * parameter log10 std encoding, the clock unwrapper. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "nte_frames.h"

#define assert_near(a, b, tol) assert_true(fabs((double)(a) - (double)(b)) <= (double)(tol))

typedef struct {
    nte_e2e_tx_t tx;
    nte_e2e_rx_t rx;
    uint8_t frame[8];
} link_t;

static void link_init(link_t* l, nte_frames_kind_t kind)
{
    assert_int_equal(nte_frames_tx_init(&l->tx, kind), nte_frames_ok);
    assert_int_equal(nte_frames_rx_init(&l->rx, kind), nte_frames_ok);
    memset(l->frame, 0xEE, sizeof l->frame);
}

static void test_ids(void** state)
{
    uint32_t id;
    nte_frames_kind_t kind;
    int k;
    const uint32_t offsets[9] = {0x00, 0x01, 0x02, 0x10, 0x11, 0x12, 0x13, 0x03, 0x14};
    (void)state;
    for (k = 0; k < (int)nte_frames_kind_count; ++k) {
        assert_int_equal(nte_frames_can_id(0x200u, (nte_frames_kind_t)k, &id), nte_frames_ok);
        assert_int_equal(id, 0x200u + offsets[k]);
        assert_int_equal(nte_frames_kind_of(0x200u, id, &kind), nte_frames_ok);
        assert_int_equal(kind, k);
        assert_int_equal(nte_frames_can_id(0x7EBu, (nte_frames_kind_t)k, &id), nte_frames_ok);
        assert_int_equal(nte_frames_kind_of(0x7EBu, id, &kind), nte_frames_ok);
        assert_int_equal(kind, k);
    }
    assert_int_equal(nte_frames_can_id(0x7ECu, nte_frames_kind_health, &id),
                     nte_frames_err_bad_config);
    assert_int_equal(nte_frames_can_id(0x7ECu, nte_frames_kind_contact, &id), nte_frames_ok);
    assert_int_equal(nte_frames_can_id(0x200u, nte_frames_kind_count, &id),
                     nte_frames_err_bad_config);
    assert_int_equal(nte_frames_kind_of(0x200u, 0x204u, &kind), nte_frames_err_unknown_id);
    assert_int_equal(nte_frames_kind_of(0x200u, 0x1FFu, &kind), nte_frames_err_unknown_id);
    assert_int_equal(nte_frames_kind_of(0x200u, 0x215u, &kind), nte_frames_err_unknown_id);
}

static void test_depth_round_trip(void** state)
{
    static const float depths[] = {0.0f, 0.001f, 0.002f, 123.456f, 499.999f, 500.0f};
    static const float vels[] = {-500.0f, -499.99f, -0.01f, 0.0f, 0.01f, 10.0f, 499.99f, 500.0f};
    static const uint16_t ticks[] = {0u, 1u, 32768u, 65535u};
    link_t l;
    size_t i;
    size_t j;
    (void)state;
    link_init(&l, nte_frames_kind_depth);
    for (i = 0; i < sizeof depths / sizeof depths[0]; ++i) {
        for (j = 0; j < sizeof vels / sizeof vels[0]; ++j) {
            nte_frames_depth_t in = {depths[i], vels[j], ticks[(i + j) % 4u]};
            nte_frames_depth_t out;
            nte_e2e_result_t r;
            memset(&out, 0, sizeof out);
            assert_int_equal(nte_frames_encode_depth(&in, &l.tx, l.frame), nte_frames_ok);
            assert_int_equal(nte_frames_decode_depth(&l.rx, l.frame, 8, &out, &r, NULL),
                             nte_frames_ok);
            assert_int_equal(r, nte_e2e_ok);
            /* float32 of the decoded multiple of 1 um: within 1e-4 of a um */
            assert_near(out.depth_mm, in.depth_mm, 1e-4);
            assert_near(out.velocity_mm_s, in.velocity_mm_s, 1e-4);
            assert_int_equal(out.time_ticks, in.time_ticks);
        }
    }
    /* resolution: half a step rounds, 0.4 step does not move */
    {
        nte_frames_depth_t in = {250.0004f, 0.004f, 7u};
        nte_frames_depth_t out;
        assert_int_equal(nte_frames_encode_depth(&in, &l.tx, l.frame), nte_frames_ok);
        assert_int_equal(nte_frames_decode_depth(&l.rx, l.frame, 8, &out, NULL, NULL),
                         nte_frames_ok);
        assert_near(out.depth_mm, 250.0, 1e-4);
        assert_near(out.velocity_mm_s, 0.0, 1e-6);
    }
}

static void test_depth_range_errors(void** state)
{
    link_t l;
    nte_frames_depth_t bad[] = {
        {-0.001f, 0.0f, 0}, {500.001f, 0.0f, 0}, {0.0f, -500.01f, 0},
        {0.0f, 500.01f, 0}, {1e30f, 0.0f, 0},    {0.0f, -1e30f, 0},
    };
    size_t i;
    nte_frames_depth_t nan_in = {NAN, 0.0f, 0};
    nte_frames_depth_t inf_in = {0.0f, INFINITY, 0};
    (void)state;
    link_init(&l, nte_frames_kind_depth);
    for (i = 0; i < sizeof bad / sizeof bad[0]; ++i) {
        assert_int_equal(nte_frames_encode_depth(&bad[i], &l.tx, l.frame), nte_frames_err_range);
    }
    assert_int_equal(nte_frames_encode_depth(&nan_in, &l.tx, l.frame), nte_frames_err_not_finite);
    assert_int_equal(nte_frames_encode_depth(&inf_in, &l.tx, l.frame), nte_frames_err_not_finite);
    assert_int_equal(l.tx.counter, 0); /* failed encodes do not advance the counter */
    assert_int_equal(nte_frames_encode_depth(NULL, &l.tx, l.frame), nte_frames_err_null);
}

/* A frame with a right CRC but a raw value beyond the DBC range is rejected by decode. */
static void test_decode_range_error(void** state)
{
    link_t l;
    nte_frames_depth_t out;
    uint8_t lost;
    (void)state;
    link_init(&l, nte_frames_kind_depth);
    memset(l.frame, 0, 8);
    /* Depth raw = 2^19 - 1 = 524287 > 500000: bits 12..30 all ones */
    l.frame[1] = 0xF0u;
    l.frame[2] = 0xFFu;
    l.frame[3] = 0x7Fu;
    assert_int_equal(nte_e2e_protect(&l.tx, l.frame, 8), nte_e2e_ok);
    assert_int_equal(nte_frames_decode_depth(&l.rx, l.frame, 8, &out, NULL, &lost),
                     nte_frames_err_range);
    assert_true(l.rx.synced); /* it passed E2E */
}

static void test_decode_e2e_errors(void** state)
{
    link_t l;
    nte_frames_force_t in = {1.2345f, 100u, false};
    nte_frames_force_t out;
    nte_e2e_result_t r;
    uint8_t lost;
    uint8_t copy[8];
    nte_e2e_rx_t depth_rx;
    (void)state;
    link_init(&l, nte_frames_kind_force);
    assert_int_equal(nte_frames_encode_force(&in, &l.tx, l.frame), nte_frames_ok);
    memcpy(copy, l.frame, 8);
    copy[4] ^= 0x01u;
    assert_int_equal(nte_frames_decode_force(&l.rx, copy, 8, &out, &r, &lost), nte_frames_err_e2e);
    assert_int_equal(r, nte_e2e_err_bad_crc);
    assert_int_equal(nte_frames_decode_force(&l.rx, l.frame, 7, &out, &r, &lost),
                     nte_frames_err_e2e);
    assert_int_equal(r, nte_e2e_err_wrong_length);
    assert_int_equal(nte_frames_decode_force(&l.rx, l.frame, 8, &out, &r, &lost), nte_frames_ok);
    assert_near(out.force_n, 1.2345, 1e-6);
    assert_int_equal(nte_frames_decode_force(&l.rx, l.frame, 8, &out, &r, &lost),
                     nte_frames_err_e2e);
    assert_int_equal(r, nte_e2e_err_repeated);
    /* three frames lost */
    assert_int_equal(nte_frames_encode_force(&in, &l.tx, l.frame), nte_frames_ok);
    assert_int_equal(nte_frames_encode_force(&in, &l.tx, l.frame), nte_frames_ok);
    assert_int_equal(nte_frames_encode_force(&in, &l.tx, l.frame), nte_frames_ok);
    assert_int_equal(nte_frames_encode_force(&in, &l.tx, l.frame), nte_frames_ok);
    assert_int_equal(nte_frames_decode_force(&l.rx, l.frame, 8, &out, &r, &lost), nte_frames_ok);
    assert_int_equal(r, nte_e2e_skipped);
    assert_int_equal(lost, 3);
    /* an E2E state of another message is refused */
    assert_int_equal(nte_frames_rx_init(&depth_rx, nte_frames_kind_depth), nte_frames_ok);
    assert_int_equal(nte_frames_decode_force(&depth_rx, l.frame, 8, &out, &r, &lost),
                     nte_frames_err_wrong_kind);
}

static void test_force_ends(void** state)
{
    static const float forces[] = {-50.0f, -49.9999f, -0.0001f, 0.0f, 0.0001f, 49.9999f, 50.0f};
    link_t l;
    size_t i;
    nte_frames_force_t over = {50.0001f, 0, false};
    nte_frames_force_t under = {-50.0001f, 0, false};
    (void)state;
    link_init(&l, nte_frames_kind_force);
    for (i = 0; i < sizeof forces / sizeof forces[0]; ++i) {
        nte_frames_force_t in = {forces[i], (uint16_t)(i * 9000u), false};
        nte_frames_force_t out;
        assert_int_equal(nte_frames_encode_force(&in, &l.tx, l.frame), nte_frames_ok);
        assert_int_equal(nte_frames_decode_force(&l.rx, l.frame, 8, &out, NULL, NULL),
                         nte_frames_ok);
        assert_near(out.force_n, in.force_n, 5e-6);
        assert_int_equal(out.time_ticks, in.time_ticks);
    }
    assert_int_equal(nte_frames_encode_force(&over, &l.tx, l.frame), nte_frames_err_range);
    assert_int_equal(nte_frames_encode_force(&under, &l.tx, l.frame), nte_frames_err_range);
}

/* SensorFault: a flagged sample may carry any force (sent and decoded as 0 when unusable);
 * an unflagged out-of-range one is still refused; ForceSource 3 is a selector error. */
static void test_sensor_fault_and_force_source(void** state)
{
    link_t l;
    nte_frames_force_t out;
    (void)state;
    link_init(&l, nte_frames_kind_force);
    const nte_frames_force_t good = {1.5f, 7u, false};
    const nte_frames_force_t flagged = {2.5f, 8u, true};
    const nte_frames_force_t broken = {(float)NAN, 9u, true};
    const nte_frames_force_t over = {80.0f, 10u, true};
    const nte_frames_force_t over_unflagged = {80.0f, 11u, false};
    assert_int_equal(nte_frames_encode_force(&good, &l.tx, l.frame), nte_frames_ok);
    assert_int_equal(l.frame[6], 0u); /* bit 48 clear: the frame of a sender before the signal */
    assert_int_equal(nte_frames_decode_force(&l.rx, l.frame, 8, &out, NULL, NULL), nte_frames_ok);
    assert_false(out.sensor_fault);
    assert_int_equal(nte_frames_encode_force(&flagged, &l.tx, l.frame), nte_frames_ok);
    assert_int_equal(l.frame[6] & 1u, 1u);
    assert_int_equal(nte_frames_decode_force(&l.rx, l.frame, 8, &out, NULL, NULL), nte_frames_ok);
    assert_true(out.sensor_fault);
    assert_near(out.force_n, 2.5, 1e-6);
    assert_int_equal(out.time_ticks, 8u);
    assert_int_equal(nte_frames_encode_force(&broken, &l.tx, l.frame), nte_frames_ok);
    assert_int_equal(nte_frames_decode_force(&l.rx, l.frame, 8, &out, NULL, NULL), nte_frames_ok);
    assert_true(out.sensor_fault);
    assert_true(fabsf(out.force_n) < 1e-9f);
    assert_int_equal(nte_frames_encode_force(&over, &l.tx, l.frame), nte_frames_ok);
    assert_int_equal(nte_frames_decode_force(&l.rx, l.frame, 8, &out, NULL, NULL), nte_frames_ok);
    assert_true(out.sensor_fault);
    assert_true(fabsf(out.force_n) < 1e-9f);
    assert_int_equal(nte_frames_encode_force(&over_unflagged, &l.tx, l.frame),
                     nte_frames_err_range);
    /* a received raw force beyond the DBC range with SensorFault set is accepted (its value
     * is not used) */
    memset(l.frame, 0, 8);
    l.frame[3] = 0x7Fu; /* Force raw 0x7F << 12 = 520192 > 500000 */
    l.frame[6] = 0x01u;
    assert_int_equal(nte_e2e_protect(&l.tx, l.frame, 8), nte_e2e_ok);
    assert_int_equal(nte_frames_decode_force(&l.rx, l.frame, 8, &out, NULL, NULL), nte_frames_ok);
    assert_true(out.sensor_fault);
    assert_near(out.force_n, 52.0192, 1e-3);
    l.frame[6] = 0x00u;
    assert_int_equal(nte_e2e_protect(&l.tx, l.frame, 8), nte_e2e_ok);
    assert_int_equal(nte_frames_decode_force(&l.rx, l.frame, 8, &out, NULL, NULL),
                     nte_frames_err_range);
    {
        link_t c;
        const nte_frames_command_t bad = {false, 0u, 0u, 0u, 3u};
        nte_frames_command_t co;
        link_init(&c, nte_frames_kind_command);
        assert_int_equal(nte_frames_encode_command(&bad, &c.tx, c.frame), nte_frames_err_selector);
        memset(c.frame, 0, 8);
        c.frame[2] = 0x30u; /* ForceSource = 3 (bits 20..21) */
        assert_int_equal(nte_e2e_protect(&c.tx, c.frame, 8), nte_e2e_ok);
        assert_int_equal(nte_frames_decode_command(&c.rx, c.frame, 8, &co, NULL, NULL),
                         nte_frames_err_selector);
        c.frame[2] = 0x20u; /* ForceSource = 2: the model alone */
        assert_int_equal(nte_e2e_protect(&c.tx, c.frame, 8), nte_e2e_ok);
        assert_int_equal(nte_frames_decode_command(&c.rx, c.frame, 8, &co, NULL, NULL),
                         nte_frames_ok);
        assert_int_equal(co.force_source, NTE_FRAMES_FORCE_SOURCE_MODEL);
    }
}

static void test_command_all_values(void** state)
{
    link_t l;
    unsigned reset;
    unsigned m;
    unsigned e;
    unsigned a;
    (void)state;
    link_init(&l, nte_frames_kind_command);
    for (reset = 0; reset < 2u; ++reset) {
        for (m = 0; m < 4u; ++m) {
            for (e = 0; e < 4u; ++e) {
                for (a = 0; a < 4u; ++a) {
                    nte_frames_command_t in = {reset != 0u, (uint8_t)m, (uint8_t)e, (uint8_t)a,
                                               (uint8_t)((m + e + a) % 3u)};
                    nte_frames_command_t out;
                    nte_frames_err_t err = nte_frames_encode_command(&in, &l.tx, l.frame);
                    if ((e == 3u) || (a == 3u)) { /* ModelSel 3 = Model III is valid */
                        assert_int_equal(err, nte_frames_err_selector);
                        continue;
                    }
                    assert_int_equal(err, nte_frames_ok);
                    assert_int_equal(nte_frames_decode_command(&l.rx, l.frame, 8, &out, NULL, NULL),
                                     nte_frames_ok);
                    assert_int_equal(out.reset, in.reset);
                    assert_int_equal(out.model_sel, m);
                    assert_int_equal(out.estimator_sel, e);
                    assert_int_equal(out.adapt_cmd, a);
                    assert_int_equal(out.force_source, in.force_source);
                }
            }
        }
    }
    /* a received ModelSel = 3 (bits 13..14) is Model III; EstimatorSel = 3 (bits 16..17) is a
     * selector error */
    memset(l.frame, 0, 8);
    l.frame[1] = 0x60u;
    assert_int_equal(nte_e2e_protect(&l.tx, l.frame, 8), nte_e2e_ok);
    {
        nte_frames_command_t out;
        assert_int_equal(nte_frames_decode_command(&l.rx, l.frame, 8, &out, NULL, NULL),
                         nte_frames_ok);
        assert_int_equal(out.model_sel, NTE_FRAMES_MODEL_III);
        memset(l.frame, 0, 8);
        l.frame[2] = 0x03u;
        assert_int_equal(nte_e2e_protect(&l.tx, l.frame, 8), nte_e2e_ok);
        assert_int_equal(nte_frames_decode_command(&l.rx, l.frame, 8, &out, NULL, NULL),
                         nte_frames_err_selector);
    }
}

static void test_setting(void** state)
{
    link_t l;
    nte_frames_setting_t out;
    static const uint8_t items[] = {0u, 1u, 2u, 11u, 19u, 20u, 59u, 255u};
    static const float values[] = {0.0f, 1.0f, -0.0211f, 434.90018f, 3.999999e-06f, 1e30f};
    size_t i;
    size_t j;
    (void)state;
    link_init(&l, nte_frames_kind_setting);
    for (i = 0; i < sizeof items; ++i) {
        for (j = 0; j < sizeof values / sizeof values[0]; ++j) {
            nte_frames_setting_t in = {items[i], values[j]};
            assert_int_equal(nte_frames_encode_setting(&in, &l.tx, l.frame), nte_frames_ok);
            assert_int_equal(nte_frames_decode_setting(&l.rx, l.frame, 8, &out, NULL, NULL),
                             nte_frames_ok);
            assert_int_equal(out.item, in.item);
            assert_memory_equal(&out.value, &in.value, sizeof(float)); /* float32 exactly */
        }
    }
    {
        /* item 60..254 is no item; a value must be finite */
        nte_frames_setting_t beyond = {60u, 1.0f};
        nte_frames_setting_t below_commit = {254u, 1.0f};
        nte_frames_setting_t nan_value = {1u, NAN};
        nte_frames_setting_t inf_value = {1u, INFINITY};
        assert_int_equal(nte_frames_encode_setting(&beyond, &l.tx, l.frame),
                         nte_frames_err_selector);
        assert_int_equal(nte_frames_encode_setting(&below_commit, &l.tx, l.frame),
                         nte_frames_err_selector);
        assert_int_equal(nte_frames_encode_setting(&nan_value, &l.tx, l.frame),
                         nte_frames_err_not_finite);
        assert_int_equal(nte_frames_encode_setting(&inf_value, &l.tx, l.frame),
                         nte_frames_err_not_finite);
        /* received: the same refusals after a valid E2E check */
        memset(l.frame, 0, 8);
        l.frame[2] = 60u;
        assert_int_equal(nte_e2e_protect(&l.tx, l.frame, 8), nte_e2e_ok);
        assert_int_equal(nte_frames_decode_setting(&l.rx, l.frame, 8, &out, NULL, NULL),
                         nte_frames_err_selector);
        memset(l.frame, 0, 8);
        l.frame[2] = 1u;
        l.frame[3] = 0x00u; /* Value bits 24..55: 0x7FC00000, a quiet NaN */
        l.frame[4] = 0x00u;
        l.frame[5] = 0xC0u;
        l.frame[6] = 0x7Fu;
        assert_int_equal(nte_e2e_protect(&l.tx, l.frame, 8), nte_e2e_ok);
        assert_int_equal(nte_frames_decode_setting(&l.rx, l.frame, 8, &out, NULL, NULL),
                         nte_frames_err_not_finite);
    }
}

static void test_estimate_clamp_and_flags(void** state)
{
    link_t l;
    nte_frames_estimate_t out;
    nte_frames_estimate_t in = {0.2231f, -0.0042f, 0.1801f, true, true, false, false, false};
    nte_frames_estimate_t big = {80.0f, -3.0f, 9.0f, false, false, false, true, false};
    nte_frames_estimate_t nan_in = {NAN, 0.0f, 0.0f, false, false, false, true, false};
    unsigned flags;
    (void)state;
    link_init(&l, nte_frames_kind_estimate);
    assert_int_equal(nte_frames_encode_estimate(&in, &l.tx, l.frame), nte_frames_ok);
    assert_int_equal(nte_frames_decode_estimate(&l.rx, l.frame, 8, &out, NULL, NULL),
                     nte_frames_ok);
    assert_near(out.force_n, 0.2231, 5e-5 + 1e-6);
    assert_near(out.innovation_n, -0.0042, 2e-4 + 1e-6);
    assert_near(out.z, 0.1801, 2.5e-4 + 1e-6);
    assert_true(out.in_tissue);
    assert_true(out.adapting);
    assert_false(out.saturated);
    assert_false(out.fault);
    assert_int_equal(nte_frames_encode_estimate(&big, &l.tx, l.frame), nte_frames_ok);
    assert_int_equal(nte_frames_decode_estimate(&l.rx, l.frame, 8, &out, NULL, NULL),
                     nte_frames_ok);
    assert_near(out.force_n, 50.0, 1e-4);
    assert_near(out.innovation_n, -0.8192, 1e-5);
    assert_near(out.z, 8.1915, 1e-5);
    assert_true(out.saturated);
    assert_true(out.fault);
    assert_int_equal(nte_frames_encode_estimate(&nan_in, &l.tx, l.frame),
                     nte_frames_err_not_finite);
    /* every combination of the five status bits survives */
    for (flags = 0; flags < 32u; ++flags) {
        nte_frames_estimate_t f = {0.0f,
                                   0.0f,
                                   0.0f,
                                   (flags & 1u) != 0u,
                                   (flags & 2u) != 0u,
                                   (flags & 4u) != 0u,
                                   (flags & 8u) != 0u,
                                   (flags & 16u) != 0u};
        assert_int_equal(nte_frames_encode_estimate(&f, &l.tx, l.frame), nte_frames_ok);
        assert_int_equal(nte_frames_decode_estimate(&l.rx, l.frame, 8, &out, NULL, NULL),
                         nte_frames_ok);
        assert_int_equal(out.in_tissue, f.in_tissue);
        assert_int_equal(out.adapting, f.adapting);
        assert_int_equal(out.saturated, f.saturated);
        assert_int_equal(out.fault, f.fault);
        assert_int_equal(out.stale, f.stale);
    }
}

static void test_params(void** state)
{
    /* Model II nominal values (reference_py/MODEL.md §3) and a spread of standard deviations */
    static const float values[10] = {7.9e-3f,  2.46f, 4.14e-3f, 5.59e-2f, -2.11e-2f, 5.25e-2f,
                                     2.55e-2f, 0.15f, 0.25f,    2.5f}; /* + Model III's g_fast,
                                                                           g_slow, delta */
    static const float stds[] = {0.0f, 1e-30f, 3.3e-7f, 1e-4f, 0.0123f, 1.0f, 517.0f, 1e30f};
    link_t l;
    unsigned i;
    size_t j;
    nte_frames_param_t out;
    (void)state;
    link_init(&l, nte_frames_kind_params);
    for (i = 0; i < 10u; ++i) {
        for (j = 0; j < sizeof stds / sizeof stds[0]; ++j) {
            nte_frames_param_t in = {(uint8_t)i, values[i], stds[j]};
            assert_int_equal(nte_frames_encode_param(&in, &l.tx, l.frame), nte_frames_ok);
            assert_int_equal(l.frame[1] >> 4, i);
            assert_int_equal(nte_frames_decode_param(&l.rx, l.frame, 8, &out, NULL, NULL),
                             nte_frames_ok);
            assert_int_equal(out.index, i);
            assert_true(memcmp(&out.value, &in.value, sizeof(float)) == 0); /* bit exact */
            if (stds[j] > 0.0f) {
                /* half a 0.001-decade step is 0.115 %; allow float rounding on top */
                assert_near(out.std / in.std, 1.0, 1.2e-3);
            } else {
                assert_true(out.std <= 0.0f && out.std >= 0.0f);
            }
        }
    }
    {
        nte_frames_param_t bad_index = {10u, 1.0f, 1.0f};
        nte_frames_param_t neg_std = {0u, 1.0f, -1e-3f};
        nte_frames_param_t nan_value = {0u, NAN, 1.0f};
        nte_frames_param_t inf_std = {0u, 1.0f, INFINITY};
        nte_frames_param_t tiny = {0u, 1.0f, 1e-38f};
        nte_frames_param_t huge = {0u, 1.0f, 3e38f};
        assert_int_equal(nte_frames_encode_param(&bad_index, &l.tx, l.frame),
                         nte_frames_err_selector);
        assert_int_equal(nte_frames_encode_param(&neg_std, &l.tx, l.frame), nte_frames_err_range);
        assert_int_equal(nte_frames_encode_param(&nan_value, &l.tx, l.frame),
                         nte_frames_err_not_finite);
        assert_int_equal(nte_frames_encode_param(&inf_std, &l.tx, l.frame),
                         nte_frames_err_not_finite);
        /* beyond 10^+-32.767: clamped to the range end, not confused with "fixed" */
        assert_int_equal(nte_frames_encode_param(&tiny, &l.tx, l.frame), nte_frames_ok);
        assert_int_equal(nte_frames_decode_param(&l.rx, l.frame, 8, &out, NULL, NULL),
                         nte_frames_ok);
        assert_near(log10((double)out.std), -32.767, 1e-3);
        assert_int_equal(nte_frames_encode_param(&huge, &l.tx, l.frame), nte_frames_ok);
        assert_int_equal(nte_frames_decode_param(&l.rx, l.frame, 8, &out, NULL, NULL),
                         nte_frames_ok);
        assert_near(log10((double)out.std), 32.767, 1e-3);
    }
    /* a received index 9..15 is a selector error */
    memset(l.frame, 0, 8);
    l.frame[1] = 0xF0u;
    assert_int_equal(nte_e2e_protect(&l.tx, l.frame, 8), nte_e2e_ok);
    assert_int_equal(nte_frames_decode_param(&l.rx, l.frame, 8, &out, NULL, NULL),
                     nte_frames_err_selector);
}

/* The frame's own log10 (no libm) against the C library's, over the whole range in steps of
 * 0.0059 decade and at the edges: the sent value is log10(std) rounded to 0.001, so the
 * received std's log10 is within half a step of the true one (+ 1e-5 for both roundings). */
static void test_params_std_log10_over_the_range(void** state)
{
    static const float edges[] = {1.0e-45f, 1.17549435e-38f, 9.9e-34f,   1.0e-33f, 1.71e-33f,
                                  1.0f,     1.41421356f,     1.4142137f, 5.8e32f,  3.4e38f};
    link_t l;
    size_t j;
    double s;
    nte_frames_param_t out;
    (void)state;
    link_init(&l, nte_frames_kind_params);
    for (j = 0; j < sizeof edges / sizeof edges[0] + 11000u; ++j) {
        nte_frames_param_t in = {0u, 1.0f, 0.0f};
        double expected;
        in.std = (j < sizeof edges / sizeof edges[0])
                     ? edges[j]
                     : (float)(1e-33 * pow(1.0137, (double)(j - sizeof edges / sizeof edges[0])));
        assert_int_equal(nte_frames_encode_param(&in, &l.tx, l.frame), nte_frames_ok);
        assert_int_equal(nte_frames_decode_param(&l.rx, l.frame, 8, &out, NULL, NULL),
                         nte_frames_ok);
        expected = log10((double)in.std);
        expected = expected < -32.767 ? -32.767 : (expected > 32.767 ? 32.767 : expected);
        s = log10((double)out.std);
        assert_near(s, expected, 0.0005 + 1e-5);
    }
}

static void test_heartbeat(void** state)
{
    link_t l;
    nte_frames_heartbeat_t out;
    nte_frames_heartbeat_t in = {NTE_FRAMES_STATE_RUNNING, 1u, 0u, 3600.3f, 259u, 17u, 0.000734f};
    nte_frames_heartbeat_t wrap = {NTE_FRAMES_STATE_FAULT,
                                   2u,
                                   1u,
                                   52428.8f + 12.5f,
                                   0u,
                                   255u,
                                   0.5f}; /* Model III; Uptime wraps at 2^19 x 0.1 s */
    nte_frames_heartbeat_t bad_model = {0u, 3u, 0u, 0.0f, 0u, 0u, 0.0f};
    nte_frames_heartbeat_t bad_state = {3u, 0u, 0u, 0.0f, 0u, 0u, 0.0f};
    nte_frames_heartbeat_t neg = {0u, 0u, 0u, -1.0f, 0u, 0u, 0.0f};
    nte_frames_heartbeat_t many = {0u, 0u, 0u, (10.0f * 52428.8f) + 3.0f, 0u, 0u, 0.0f};
    nte_frames_heartbeat_t beyond = {0u, 0u, 0u, 2.0f * NTE_FRAMES_UPTIME_MAX_S, 0u, 0u, 0.0f};
    (void)state;
    link_init(&l, nte_frames_kind_heartbeat);
    /* the wrap without fmodf: ten wraps off (float32 at 5e5 s: 0.03 s ulp) */
    assert_int_equal(nte_frames_encode_heartbeat(&many, &l.tx, l.frame), nte_frames_ok);
    assert_int_equal(nte_frames_decode_heartbeat(&l.rx, l.frame, 8, &out, NULL, NULL),
                     nte_frames_ok);
    assert_near(out.uptime_s, 3.0, 0.05 + 0.07);
    assert_int_equal(nte_frames_encode_heartbeat(&beyond, &l.tx, l.frame), nte_frames_err_range);
    assert_int_equal(nte_frames_encode_heartbeat(&in, &l.tx, l.frame), nte_frames_ok);
    assert_int_equal(nte_frames_decode_heartbeat(&l.rx, l.frame, 8, &out, NULL, NULL),
                     nte_frames_ok);
    assert_int_equal(out.node_state, NTE_FRAMES_STATE_RUNNING);
    assert_int_equal(out.active_model, 1);
    assert_int_equal(out.active_estimator, 0);
    assert_near(out.uptime_s, 3600.3, 0.05 + 1e-3);
    assert_int_equal(out.e2e_errors, 259u & 0xFFu);
    assert_int_equal(out.range_errors, 17u);
    assert_near(out.step_time_s, 0.000734, 1e-6 + 1e-9);
    assert_int_equal(nte_frames_encode_heartbeat(&wrap, &l.tx, l.frame), nte_frames_ok);
    assert_int_equal(nte_frames_decode_heartbeat(&l.rx, l.frame, 8, &out, NULL, NULL),
                     nte_frames_ok);
    assert_near(out.uptime_s, 12.5, 0.05 + 0.01); /* float32 at 5e4 s: 0.004 s ulp */
    assert_int_equal(out.active_model, 2);
    assert_int_equal(out.active_estimator, 1);
    /* layout: ActiveModel bits 14..15, Uptime 16..34, ActiveEstimator bit 35 */
    assert_int_equal((l.frame[1] >> 6) & 3u, 2u);
    assert_int_equal((l.frame[4] >> 3) & 1u, 1u);
    assert_int_equal(nte_frames_encode_heartbeat(&bad_model, &l.tx, l.frame),
                     nte_frames_err_selector);
    assert_near(out.step_time_s, 0.00819, 1e-9 + 1e-7);
    assert_int_equal(out.node_state, NTE_FRAMES_STATE_FAULT);
    assert_int_equal(nte_frames_encode_heartbeat(&bad_state, &l.tx, l.frame),
                     nte_frames_err_selector);
    assert_int_equal(nte_frames_encode_heartbeat(&neg, &l.tx, l.frame), nte_frames_err_range);
}

static void test_contact(void** state)
{
    static const float surfaces[] = {-500.0f, -0.001f, 0.0f, 6.481f, 123.456f, 500.0f};
    static const float tares[] = {-50.0f, -0.0123f, 0.0f, 0.0042f, 50.0f};
    link_t l;
    nte_frames_contact_t out;
    size_t i;
    size_t j;
    (void)state;
    link_init(&l, nte_frames_kind_contact);
    for (i = 0; i < sizeof surfaces / sizeof surfaces[0]; ++i) {
        for (j = 0; j < sizeof tares / sizeof tares[0]; ++j) {
            nte_frames_contact_t in = {(uint8_t)(j % 2u),
                                       (i % 3u) != 0u,
                                       2u,
                                       surfaces[i],
                                       tares[j],
                                       (uint8_t)((i + j) % (NTE_FRAMES_LAYER_MAX + 1u))};
            assert_int_equal(nte_frames_encode_contact(&in, &l.tx, l.frame), nte_frames_ok);
            assert_int_equal(nte_frames_decode_contact(&l.rx, l.frame, 8, &out, NULL, NULL),
                             nte_frames_ok);
            assert_int_equal(out.contact_state, in.contact_state);
            assert_int_equal(out.surface_valid, in.surface_valid);
            assert_int_equal(out.active_model, 2u);
            assert_int_equal(out.layer, in.layer);
            /* half a 1 um step, half a 0.1 mN step, plus float rounding */
            assert_near(out.surface_mm, in.surface_valid ? in.surface_mm : 0.0f, 5e-4 + 5e-5);
            assert_near(out.tare_n, in.tare_n, 5e-5 + 5e-6);
        }
    }
    {
        nte_frames_contact_t far = {0u, true, 2u, 500.01f, 0.0f, 0u};
        nte_frames_contact_t nan_surface = {0u, true, 2u, NAN, 0.0f, 0u};
        nte_frames_contact_t nan_ignored = {0u, false, 2u, NAN, 0.01f, 0u};
        nte_frames_contact_t nan_tare = {0u, false, 2u, 0.0f, NAN, 0u};
        nte_frames_contact_t big_tare = {1u, false, 2u, 0.0f, 80.0f, 0u};
        nte_frames_contact_t bad_state = {2u, false, 2u, 0.0f, 0.0f, 0u};
        nte_frames_contact_t bad_model = {0u, false, 3u, 0.0f, 0.0f, 0u};
        nte_frames_contact_t bad_layer = {0u, false, 2u, 0.0f, 0.0f, NTE_FRAMES_LAYER_MAX + 1u};
        assert_int_equal(nte_frames_encode_contact(&bad_layer, &l.tx, l.frame),
                         nte_frames_err_range);
        assert_int_equal(nte_frames_encode_contact(&far, &l.tx, l.frame), nte_frames_err_range);
        assert_int_equal(nte_frames_encode_contact(&nan_surface, &l.tx, l.frame),
                         nte_frames_err_not_finite);
        assert_int_equal(nte_frames_encode_contact(&nan_tare, &l.tx, l.frame),
                         nte_frames_err_not_finite);
        assert_int_equal(nte_frames_encode_contact(&bad_state, &l.tx, l.frame),
                         nte_frames_err_selector);
        assert_int_equal(nte_frames_encode_contact(&bad_model, &l.tx, l.frame),
                         nte_frames_err_selector);
        assert_int_equal(nte_frames_encode_contact(&nan_ignored, &l.tx, l.frame), nte_frames_ok);
        assert_int_equal(nte_frames_decode_contact(&l.rx, l.frame, 8, &out, NULL, NULL),
                         nte_frames_ok);
        assert_false(out.surface_valid);
        assert_near(out.surface_mm, 0.0, 1e-9);
        assert_int_equal(nte_frames_encode_contact(&big_tare, &l.tx, l.frame), nte_frames_ok);
        assert_int_equal(nte_frames_decode_contact(&l.rx, l.frame, 8, &out, NULL, NULL),
                         nte_frames_ok);
        assert_near(out.tare_n, 50.0, 1e-6); /* clamped */
        assert_int_equal(out.contact_state, NTE_FRAMES_CONTACT_TISSUE);
    }
}

static void test_health(void** state)
{
    static const float confidences[] = {0.0f, 0.0001f, 0.0042f, 0.5f, 0.75f, 0.99995f, 1.0f};
    link_t l;
    nte_frames_health_t out;
    size_t i;
    (void)state;
    link_init(&l, nte_frames_kind_health);
    for (i = 0; i < sizeof confidences / sizeof confidences[0]; ++i) {
        nte_frames_health_t in = {
            (i % 2u) == 0u,
            (i % 3u) == 1u,
            confidences[i],
            {(uint8_t)(1u << (i % 6u)), (uint8_t)NTE_FRAMES_FILTER_FLAGS, (uint8_t)(i * 7u % 64u)},
            (i % 4u) == 2u};
        assert_int_equal(nte_frames_encode_health(&in, &l.tx, l.frame), nte_frames_ok);
        assert_int_equal(nte_frames_decode_health(&l.rx, l.frame, 8, &out, NULL, NULL),
                         nte_frames_ok);
        assert_int_equal(out.refined, in.refined);
        assert_int_equal(out.converged, in.converged);
        assert_int_equal(out.refining, in.refining);
        assert_near(out.confidence, in.confidence, 5e-5 + 1e-7); /* half a 1e-4 step */
        assert_memory_equal(out.filter_flags, in.filter_flags, sizeof in.filter_flags);
    }
    {
        nte_frames_health_t above = {false, false, 1.0001f, {0u, 0u, 0u}, false};
        nte_frames_health_t below = {false, false, -0.0001f, {0u, 0u, 0u}, false};
        nte_frames_health_t nan_conf = {false, false, NAN, {0u, 0u, 0u}, false};
        nte_frames_health_t bad_bits = {false, false, 0.5f, {0u, 0u, 1u << 6}, false};
        assert_int_equal(nte_frames_encode_health(&above, &l.tx, l.frame), nte_frames_err_range);
        assert_int_equal(nte_frames_encode_health(&below, &l.tx, l.frame), nte_frames_err_range);
        assert_int_equal(nte_frames_encode_health(&nan_conf, &l.tx, l.frame),
                         nte_frames_err_not_finite);
        assert_int_equal(nte_frames_encode_health(&bad_bits, &l.tx, l.frame), nte_frames_err_range);
    }
}

static void test_clock_unwrap(void** state)
{
    nte_frames_clock_t c;
    uint32_t t0;
    uint32_t t;
    uint32_t k;
    uint16_t raw;
    (void)state;
    nte_frames_clock_reset(&c);
    t0 = nte_frames_clock_unwrap(&c, 65000u);
    assert_int_equal(t0, 65000u + 65536u);
    /* 10 s of 1 kHz samples (10 ticks each) across wraps, with one sample out of order */
    raw = 65000u;
    for (k = 1; k <= 10000u; ++k) {
        raw = (uint16_t)(raw + 10u);
        t = nte_frames_clock_unwrap(&c, raw);
        assert_int_equal(t - t0, k * 10u);
    }
    t = nte_frames_clock_unwrap(&c, (uint16_t)(raw - 50u)); /* 5 ms older sample */
    assert_int_equal(t - t0, 10000u * 10u - 50u);
    t = nte_frames_clock_unwrap(&c, (uint16_t)(raw + 10u));
    assert_int_equal(t - t0, 10001u * 10u);
    /* an older sample right after the start stays non-negative */
    nte_frames_clock_reset(&c);
    t0 = nte_frames_clock_unwrap(&c, 5u);
    t = nte_frames_clock_unwrap(&c, 65530u); /* 11 ticks before */
    assert_int_equal(t0 - t, 11u);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ids),
        cmocka_unit_test(test_depth_round_trip),
        cmocka_unit_test(test_depth_range_errors),
        cmocka_unit_test(test_decode_range_error),
        cmocka_unit_test(test_decode_e2e_errors),
        cmocka_unit_test(test_force_ends),
        cmocka_unit_test(test_command_all_values),
        cmocka_unit_test(test_sensor_fault_and_force_source),
        cmocka_unit_test(test_setting),
        cmocka_unit_test(test_estimate_clamp_and_flags),
        cmocka_unit_test(test_params),
        cmocka_unit_test(test_params_std_log10_over_the_range),
        cmocka_unit_test(test_heartbeat),
        cmocka_unit_test(test_contact),
        cmocka_unit_test(test_health),
        cmocka_unit_test(test_clock_unwrap),
    };
    return cmocka_run_group_tests_name("nte_frames", tests, NULL, NULL);
}
