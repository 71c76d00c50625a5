/* nte_frames.c -- see nte_frames.h. */
#include "nte_frames.h"

#include <math.h>
#include <string.h>

#include "generated/nte_can.h"

static const uint16_t nte_frames_offsets[nte_frames_kind_count] = {
    NTE_FRAMES_OFFSET_DEPTH,    NTE_FRAMES_OFFSET_FORCE,   NTE_FRAMES_OFFSET_COMMAND,
    NTE_FRAMES_OFFSET_ESTIMATE, NTE_FRAMES_OFFSET_PARAMS,  NTE_FRAMES_OFFSET_HEARTBEAT,
    NTE_FRAMES_OFFSET_CONTACT,  NTE_FRAMES_OFFSET_SETTING, NTE_FRAMES_OFFSET_HEALTH,
};

static const uint16_t nte_frames_data_ids[nte_frames_kind_count] = {
    NTE_FRAMES_DATA_ID_DEPTH,    NTE_FRAMES_DATA_ID_FORCE,   NTE_FRAMES_DATA_ID_COMMAND,
    NTE_FRAMES_DATA_ID_ESTIMATE, NTE_FRAMES_DATA_ID_PARAMS,  NTE_FRAMES_DATA_ID_HEARTBEAT,
    NTE_FRAMES_DATA_ID_CONTACT,  NTE_FRAMES_DATA_ID_SETTING, NTE_FRAMES_DATA_ID_HEALTH,
};

/* Raw value of log10(std) that means std = 0. */
#define NTE_FRAMES_STD_ZERO_RAW INT16_MIN

static bool nte_frames_kind_ok(nte_frames_kind_t kind)
{
    return (unsigned)kind < (unsigned)nte_frames_kind_count;
}

/* True if lo - tol <= x <= hi + tol and x is finite (tol: half a resolution step, so that a
 * value rounding to the range end is accepted; the raw value is checked again after encoding). */
static bool nte_frames_within(float x, float lo, float hi, float tol)
{
    return (x >= lo - tol) && (x <= hi + tol);
}

static float nte_frames_clamp(float x, float lo, float hi, bool* clamped)
{
    if (x < lo) {
        *clamped = true;
        return lo;
    }
    if (x > hi) {
        *clamped = true;
        return hi;
    }
    return x;
}

nte_frames_err_t nte_frames_offset(nte_frames_kind_t kind, uint32_t* offset)
{
    if (offset == NULL) {
        return nte_frames_err_null;
    }
    if (!nte_frames_kind_ok(kind)) {
        return nte_frames_err_bad_config;
    }
    *offset = nte_frames_offsets[kind];
    return nte_frames_ok;
}

nte_frames_err_t nte_frames_data_id(nte_frames_kind_t kind, uint16_t* data_id)
{
    if (data_id == NULL) {
        return nte_frames_err_null;
    }
    if (!nte_frames_kind_ok(kind)) {
        return nte_frames_err_bad_config;
    }
    *data_id = nte_frames_data_ids[kind];
    return nte_frames_ok;
}

nte_frames_err_t nte_frames_can_id(uint32_t base, nte_frames_kind_t kind, uint32_t* can_id)
{
    uint32_t id;
    if (can_id == NULL) {
        return nte_frames_err_null;
    }
    if (!nte_frames_kind_ok(kind) || (base > NTE_FRAMES_MAX_STD_ID)) {
        return nte_frames_err_bad_config;
    }
    id = base + nte_frames_offsets[kind];
    if (id > NTE_FRAMES_MAX_STD_ID) {
        return nte_frames_err_bad_config;
    }
    *can_id = id;
    return nte_frames_ok;
}

nte_frames_err_t nte_frames_kind_of(uint32_t base, uint32_t can_id, nte_frames_kind_t* kind)
{
    int k;
    if (kind == NULL) {
        return nte_frames_err_null;
    }
    if ((can_id < base) || (can_id > NTE_FRAMES_MAX_STD_ID)) {
        return nte_frames_err_unknown_id;
    }
    for (k = 0; k < (int)nte_frames_kind_count; ++k) {
        if (can_id - base == nte_frames_offsets[k]) {
            *kind = (nte_frames_kind_t)k;
            return nte_frames_ok;
        }
    }
    return nte_frames_err_unknown_id;
}

nte_frames_err_t nte_frames_tx_init(nte_e2e_tx_t* e2e, nte_frames_kind_t kind)
{
    if (e2e == NULL) {
        return nte_frames_err_null;
    }
    if (!nte_frames_kind_ok(kind)) {
        return nte_frames_err_bad_config;
    }
    (void)nte_e2e_tx_init(e2e, nte_frames_data_ids[kind], (uint8_t)NTE_FRAMES_LENGTH);
    return nte_frames_ok;
}

nte_frames_err_t nte_frames_rx_init(nte_e2e_rx_t* e2e, nte_frames_kind_t kind)
{
    if (e2e == NULL) {
        return nte_frames_err_null;
    }
    if (!nte_frames_kind_ok(kind)) {
        return nte_frames_err_bad_config;
    }
    (void)nte_e2e_rx_init(e2e, nte_frames_data_ids[kind], (uint8_t)NTE_FRAMES_LENGTH);
    return nte_frames_ok;
}

/* Common tail of every encoder: protect the packed frame. */
static nte_frames_err_t nte_frames_protect(nte_e2e_tx_t* e2e, nte_frames_kind_t kind, uint8_t* out)
{
    if (e2e->data_id != nte_frames_data_ids[kind]) {
        return nte_frames_err_wrong_kind;
    }
    if (nte_e2e_protect(e2e, out, NTE_FRAMES_LENGTH) != nte_e2e_ok) {
        return nte_frames_err_bad_config;
    }
    return nte_frames_ok;
}

/* Common head of every decoder: E2E check. */
static nte_frames_err_t nte_frames_check(nte_e2e_rx_t* e2e, nte_frames_kind_t kind,
                                         const uint8_t* data, size_t length,
                                         nte_e2e_result_t* e2e_result, uint8_t* lost)
{
    nte_e2e_result_t r;
    if (e2e->data_id != nte_frames_data_ids[kind]) {
        return nte_frames_err_wrong_kind;
    }
    r = nte_e2e_check(e2e, data, length, lost);
    if (e2e_result != NULL) {
        *e2e_result = r;
    }
    return ((int)r >= 0) ? nte_frames_ok : nte_frames_err_e2e;
}

/* ------------------------------------------------------------------------------- depth */

nte_frames_err_t nte_frames_encode_depth(const nte_frames_depth_t* in, nte_e2e_tx_t* e2e,
                                         uint8_t* out)
{
    struct nte_can_depth_t m;
    if ((in == NULL) || (e2e == NULL) || (out == NULL)) {
        return nte_frames_err_null;
    }
    if (!isfinite(in->depth_mm) || !isfinite(in->velocity_mm_s)) {
        return nte_frames_err_not_finite;
    }
    if (!nte_frames_within(in->depth_mm, 0.0f, NTE_FRAMES_DEPTH_MAX_MM, 0.0005f) ||
        !nte_frames_within(in->velocity_mm_s, -NTE_FRAMES_VELOCITY_MAX_MM_S,
                           NTE_FRAMES_VELOCITY_MAX_MM_S, 0.005f)) {
        return nte_frames_err_range;
    }
    (void)nte_can_depth_init(&m);
    m.depth = nte_can_depth_depth_encode(in->depth_mm);
    m.velocity = nte_can_depth_velocity_encode(in->velocity_mm_s);
    m.sensor_time = in->time_ticks;
    if (!nte_can_depth_depth_is_in_range(m.depth) ||
        !nte_can_depth_velocity_is_in_range(m.velocity)) {
        return nte_frames_err_range;
    }
    (void)nte_can_depth_pack(out, &m, NTE_FRAMES_LENGTH);
    return nte_frames_protect(e2e, nte_frames_kind_depth, out);
}

nte_frames_err_t nte_frames_decode_depth(nte_e2e_rx_t* e2e, const uint8_t* data, size_t length,
                                         nte_frames_depth_t* out, nte_e2e_result_t* e2e_result,
                                         uint8_t* lost)
{
    struct nte_can_depth_t m;
    nte_frames_err_t err;
    if ((e2e == NULL) || (data == NULL) || (out == NULL)) {
        return nte_frames_err_null;
    }
    err = nte_frames_check(e2e, nte_frames_kind_depth, data, length, e2e_result, lost);
    if (err != nte_frames_ok) {
        return err;
    }
    (void)nte_can_depth_unpack(&m, data, length);
    if (!nte_can_depth_depth_is_in_range(m.depth) ||
        !nte_can_depth_velocity_is_in_range(m.velocity)) {
        return nte_frames_err_range;
    }
    out->depth_mm = nte_can_depth_depth_decode(m.depth);
    out->velocity_mm_s = nte_can_depth_velocity_decode(m.velocity);
    out->time_ticks = m.sensor_time;
    return nte_frames_ok;
}

/* ------------------------------------------------------------------------------- force */

nte_frames_err_t nte_frames_encode_force(const nte_frames_force_t* in, nte_e2e_tx_t* e2e,
                                         uint8_t* out)
{
    struct nte_can_force_t m;
    if ((in == NULL) || (e2e == NULL) || (out == NULL)) {
        return nte_frames_err_null;
    }
    /* a sample flagged faulty carries no force: a non-finite or out-of-range one is sent 0 */
    const bool usable = isfinite(in->force_n) &&
                        nte_frames_within(in->force_n, -NTE_FRAMES_FORCE_MAX_N,
                                          NTE_FRAMES_FORCE_MAX_N, 0.00005f);
    if (!in->sensor_fault && !isfinite(in->force_n)) {
        return nte_frames_err_not_finite;
    }
    if (!in->sensor_fault && !usable) {
        return nte_frames_err_range;
    }
    (void)nte_can_force_init(&m);
    m.force = nte_can_force_force_encode(usable ? in->force_n : 0.0f);
    m.sensor_time = in->time_ticks;
    m.sensor_fault = in->sensor_fault ? 1u : 0u;
    if (!nte_can_force_force_is_in_range(m.force)) {
        return nte_frames_err_range;
    }
    (void)nte_can_force_pack(out, &m, NTE_FRAMES_LENGTH);
    return nte_frames_protect(e2e, nte_frames_kind_force, out);
}

nte_frames_err_t nte_frames_decode_force(nte_e2e_rx_t* e2e, const uint8_t* data, size_t length,
                                         nte_frames_force_t* out, nte_e2e_result_t* e2e_result,
                                         uint8_t* lost)
{
    struct nte_can_force_t m;
    nte_frames_err_t err;
    if ((e2e == NULL) || (data == NULL) || (out == NULL)) {
        return nte_frames_err_null;
    }
    err = nte_frames_check(e2e, nte_frames_kind_force, data, length, e2e_result, lost);
    if (err != nte_frames_ok) {
        return err;
    }
    (void)nte_can_force_unpack(&m, data, length);
    out->sensor_fault = (m.sensor_fault != 0u);
    /* flagged faulty: its value is not used, its range not checked */
    if (!out->sensor_fault && !nte_can_force_force_is_in_range(m.force)) {
        return nte_frames_err_range;
    }
    out->force_n = nte_can_force_force_decode(m.force);
    out->time_ticks = m.sensor_time;
    return nte_frames_ok;
}

/* ----------------------------------------------------------------------------- command */

static bool nte_frames_command_ok(uint8_t model_sel, uint8_t estimator_sel, uint8_t adapt_cmd,
                                  uint8_t force_source)
{
    return (model_sel <= (uint8_t)NTE_FRAMES_MODEL_III) &&
           (estimator_sel <= (uint8_t)NTE_FRAMES_ESTIMATOR_ROBUST) &&
           (adapt_cmd <= (uint8_t)NTE_FRAMES_ADAPT_RESUME) &&
           (force_source <= (uint8_t)NTE_FRAMES_FORCE_SOURCE_MODEL);
}

nte_frames_err_t nte_frames_encode_command(const nte_frames_command_t* in, nte_e2e_tx_t* e2e,
                                           uint8_t* out)
{
    struct nte_can_command_t m;
    if ((in == NULL) || (e2e == NULL) || (out == NULL)) {
        return nte_frames_err_null;
    }
    if (!nte_frames_command_ok(in->model_sel, in->estimator_sel, in->adapt_cmd, in->force_source)) {
        return nte_frames_err_selector;
    }
    (void)nte_can_command_init(&m);
    m.reset = in->reset ? 1u : 0u;
    m.model_sel = in->model_sel;
    m.estimator_sel = in->estimator_sel;
    m.adapt_cmd = in->adapt_cmd;
    m.force_source = in->force_source;
    (void)nte_can_command_pack(out, &m, NTE_FRAMES_LENGTH);
    return nte_frames_protect(e2e, nte_frames_kind_command, out);
}

nte_frames_err_t nte_frames_decode_command(nte_e2e_rx_t* e2e, const uint8_t* data, size_t length,
                                           nte_frames_command_t* out, nte_e2e_result_t* e2e_result,
                                           uint8_t* lost)
{
    struct nte_can_command_t m;
    nte_frames_err_t err;
    if ((e2e == NULL) || (data == NULL) || (out == NULL)) {
        return nte_frames_err_null;
    }
    err = nte_frames_check(e2e, nte_frames_kind_command, data, length, e2e_result, lost);
    if (err != nte_frames_ok) {
        return err;
    }
    (void)nte_can_command_unpack(&m, data, length);
    if (!nte_frames_command_ok(m.model_sel, m.estimator_sel, m.adapt_cmd, m.force_source)) {
        return nte_frames_err_selector;
    }
    out->reset = (m.reset != 0u);
    out->model_sel = m.model_sel;
    out->estimator_sel = m.estimator_sel;
    out->adapt_cmd = m.adapt_cmd;
    out->force_source = m.force_source;
    return nte_frames_ok;
}

/* ----------------------------------------------------------------------------- setting */

static bool nte_frames_setting_ok(uint8_t item)
{
    return (item <= (uint8_t)NTE_FRAMES_SETTING_LAST_VALUE) ||
           (item == (uint8_t)NTE_FRAMES_SETTING_COMMIT);
}

nte_frames_err_t nte_frames_encode_setting(const nte_frames_setting_t* in, nte_e2e_tx_t* e2e,
                                           uint8_t* out)
{
    struct nte_can_setting_t m;
    if ((in == NULL) || (e2e == NULL) || (out == NULL)) {
        return nte_frames_err_null;
    }
    if (!nte_frames_setting_ok(in->item)) {
        return nte_frames_err_selector;
    }
    if (!isfinite(in->value)) {
        return nte_frames_err_not_finite;
    }
    (void)nte_can_setting_init(&m);
    m.item = in->item;
    m.value = in->value;
    (void)nte_can_setting_pack(out, &m, NTE_FRAMES_LENGTH);
    return nte_frames_protect(e2e, nte_frames_kind_setting, out);
}

nte_frames_err_t nte_frames_decode_setting(nte_e2e_rx_t* e2e, const uint8_t* data, size_t length,
                                           nte_frames_setting_t* out, nte_e2e_result_t* e2e_result,
                                           uint8_t* lost)
{
    struct nte_can_setting_t m;
    nte_frames_err_t err;
    if ((e2e == NULL) || (data == NULL) || (out == NULL)) {
        return nte_frames_err_null;
    }
    err = nte_frames_check(e2e, nte_frames_kind_setting, data, length, e2e_result, lost);
    if (err != nte_frames_ok) {
        return err;
    }
    (void)nte_can_setting_unpack(&m, data, length);
    if (!nte_frames_setting_ok(m.item)) {
        return nte_frames_err_selector;
    }
    if (!isfinite(m.value)) {
        return nte_frames_err_not_finite;
    }
    out->item = m.item;
    out->value = m.value;
    return nte_frames_ok;
}

/* ---------------------------------------------------------------------------- estimate */

nte_frames_err_t nte_frames_encode_estimate(const nte_frames_estimate_t* in, nte_e2e_tx_t* e2e,
                                            uint8_t* out)
{
    struct nte_can_estimate_t m;
    bool clamped = false;
    if ((in == NULL) || (e2e == NULL) || (out == NULL)) {
        return nte_frames_err_null;
    }
    if (!isfinite(in->force_n) || !isfinite(in->innovation_n) || !isfinite(in->z)) {
        return nte_frames_err_not_finite;
    }
    (void)nte_can_estimate_init(&m);
    m.force_est = nte_can_estimate_force_est_encode(
        nte_frames_clamp(in->force_n, -NTE_FRAMES_FORCE_MAX_N, NTE_FRAMES_FORCE_MAX_N, &clamped));
    m.innovation = nte_can_estimate_innovation_encode(nte_frames_clamp(
        in->innovation_n, NTE_FRAMES_INNOVATION_MIN_N, NTE_FRAMES_INNOVATION_MAX_N, &clamped));
    m.z = nte_can_estimate_z_encode(
        nte_frames_clamp(in->z, NTE_FRAMES_Z_MIN, NTE_FRAMES_Z_MAX, &clamped));
    m.in_tissue = in->in_tissue ? 1u : 0u;
    m.adapting = in->adapting ? 1u : 0u;
    m.saturated = (in->saturated || clamped) ? 1u : 0u;
    m.fault = in->fault ? 1u : 0u;
    m.stale = in->stale ? 1u : 0u;
    (void)nte_can_estimate_pack(out, &m, NTE_FRAMES_LENGTH);
    return nte_frames_protect(e2e, nte_frames_kind_estimate, out);
}

nte_frames_err_t nte_frames_decode_estimate(nte_e2e_rx_t* e2e, const uint8_t* data, size_t length,
                                            nte_frames_estimate_t* out,
                                            nte_e2e_result_t* e2e_result, uint8_t* lost)
{
    struct nte_can_estimate_t m;
    nte_frames_err_t err;
    if ((e2e == NULL) || (data == NULL) || (out == NULL)) {
        return nte_frames_err_null;
    }
    err = nte_frames_check(e2e, nte_frames_kind_estimate, data, length, e2e_result, lost);
    if (err != nte_frames_ok) {
        return err;
    }
    (void)nte_can_estimate_unpack(&m, data, length);
    if (!nte_can_estimate_force_est_is_in_range(m.force_est) ||
        !nte_can_estimate_innovation_is_in_range(m.innovation) ||
        !nte_can_estimate_z_is_in_range(m.z)) {
        return nte_frames_err_range;
    }
    out->force_n = nte_can_estimate_force_est_decode(m.force_est);
    out->innovation_n = nte_can_estimate_innovation_decode(m.innovation);
    out->z = nte_can_estimate_z_decode(m.z);
    out->in_tissue = (m.in_tissue != 0u);
    out->adapting = (m.adapting != 0u);
    out->saturated = (m.saturated != 0u);
    out->fault = (m.fault != 0u);
    out->stale = (m.stale != 0u);
    return nte_frames_ok;
}

/* ------------------------------------------------------------------------------ params */

/* The generated struct has one field pair per parameter; these select them by index. */
static void nte_frames_param_set(struct nte_can_params_t* m, uint8_t index, float value,
                                 int16_t std_raw)
{
    switch (index) {
    case NTE_FRAMES_PARAM_SIGMA0:
        m->sigma0 = value;
        m->sigma0_std_log10 = std_raw;
        break;
    case NTE_FRAMES_PARAM_SIGMA1:
        m->sigma1 = value;
        m->sigma1_std_log10 = std_raw;
        break;
    case NTE_FRAMES_PARAM_SIGMA2:
        m->sigma2 = value;
        m->sigma2_std_log10 = std_raw;
        break;
    case NTE_FRAMES_PARAM_F1:
        m->f1 = value;
        m->f1_std_log10 = std_raw;
        break;
    case NTE_FRAMES_PARAM_F2:
        m->f2 = value;
        m->f2_std_log10 = std_raw;
        break;
    case NTE_FRAMES_PARAM_ALPHA:
        m->alpha = value;
        m->alpha_std_log10 = std_raw;
        break;
    case NTE_FRAMES_PARAM_BETA:
        m->beta = value;
        m->beta_std_log10 = std_raw;
        break;
    case NTE_FRAMES_PARAM_G_FAST:
        m->g_fast = value;
        m->g_fast_std_log10 = std_raw;
        break;
    case NTE_FRAMES_PARAM_G_SLOW:
        m->g_slow = value;
        m->g_slow_std_log10 = std_raw;
        break;
    default:
        m->delta = value;
        m->delta_std_log10 = std_raw;
        break;
    }
}

static void nte_frames_param_get(const struct nte_can_params_t* m, uint8_t index, float* value,
                                 int16_t* std_raw)
{
    switch (index) {
    case NTE_FRAMES_PARAM_SIGMA0:
        *value = m->sigma0;
        *std_raw = m->sigma0_std_log10;
        break;
    case NTE_FRAMES_PARAM_SIGMA1:
        *value = m->sigma1;
        *std_raw = m->sigma1_std_log10;
        break;
    case NTE_FRAMES_PARAM_SIGMA2:
        *value = m->sigma2;
        *std_raw = m->sigma2_std_log10;
        break;
    case NTE_FRAMES_PARAM_F1:
        *value = m->f1;
        *std_raw = m->f1_std_log10;
        break;
    case NTE_FRAMES_PARAM_F2:
        *value = m->f2;
        *std_raw = m->f2_std_log10;
        break;
    case NTE_FRAMES_PARAM_ALPHA:
        *value = m->alpha;
        *std_raw = m->alpha_std_log10;
        break;
    case NTE_FRAMES_PARAM_BETA:
        *value = m->beta;
        *std_raw = m->beta_std_log10;
        break;
    case NTE_FRAMES_PARAM_G_FAST:
        *value = m->g_fast;
        *std_raw = m->g_fast_std_log10;
        break;
    case NTE_FRAMES_PARAM_G_SLOW:
        *value = m->g_slow;
        *std_raw = m->g_slow_std_log10;
        break;
    default:
        *value = m->delta;
        *std_raw = m->delta_std_log10;
        break;
    }
}

/* log10 of a positive, finite standard deviation in float arithmetic alone.  libm's log10f,
 * with the logf it calls, is 0.8 KiB of the board's 32 KiB flash, and the frame keeps only
 * 0.001 of a decade.  std = 2^e * m with m in [sqrt(1/2), sqrt(2)); ln m = 2 atanh(t) with
 * t = (m - 1) / (m + 1), |t| <= 0.1716, summed up to t^9: the first term left out,
 * 2 t^11 / 11, is below 3.4e-10, so the error is a few float ulps of the result.  Below 1e-33
 * (subnormals included, whose exponent field is not their scale) the answer is the frame's
 * range end, where log10f's value would be clamped anyway.  host_bench/node_mirror.py's
 * std_log10 repeats every float operation in this order: Params frames match it bit for bit. */
static float nte_frames_std_log10(float std)
{
    uint32_t bits;
    int32_t e;
    float m;
    float t;
    float t2;
    float ln_m;
    if (std < 1.0e-33f) {
        return NTE_FRAMES_STD_LOG10_MIN;
    }
    (void)memcpy(&bits, &std, sizeof bits);
    e = (int32_t)((bits >> 23) & 0xffu) - 127;
    bits = (bits & 0x007fffffu) | 0x3f800000u; /* the mantissa as a float in [1, 2) */
    (void)memcpy(&m, &bits, sizeof m);
    if (m > 1.41421356f) {
        m = m * 0.5f;
        e = e + 1;
    }
    t = (m - 1.0f) / (m + 1.0f);
    t2 = t * t;
    ln_m = 2.0f * t *
           (1.0f +
            t2 * (1.0f / 3.0f + t2 * (1.0f / 5.0f + t2 * (1.0f / 7.0f + t2 * (1.0f / 9.0f)))));
    return ((float)e * 0.693147181f + ln_m) * 0.434294482f;
}

nte_frames_err_t nte_frames_encode_param(const nte_frames_param_t* in, nte_e2e_tx_t* e2e,
                                         uint8_t* out)
{
    struct nte_can_params_t m;
    int16_t std_raw;
    bool clamped = false;
    if ((in == NULL) || (e2e == NULL) || (out == NULL)) {
        return nte_frames_err_null;
    }
    if (in->index >= (uint8_t)NTE_FRAMES_PARAM_COUNT) {
        return nte_frames_err_selector;
    }
    if (!isfinite(in->value) || !isfinite(in->std)) {
        return nte_frames_err_not_finite;
    }
    if (in->std < 0.0f) {
        return nte_frames_err_range;
    }
    if (!(in->std > 0.0f)) {
        std_raw = NTE_FRAMES_STD_ZERO_RAW;
    } else {
        std_raw = nte_can_params_sigma0_std_log10_encode(
            nte_frames_clamp(nte_frames_std_log10(in->std), NTE_FRAMES_STD_LOG10_MIN,
                             NTE_FRAMES_STD_LOG10_MAX, &clamped));
    }
    (void)nte_can_params_init(&m);
    m.param_index = in->index;
    nte_frames_param_set(&m, in->index, in->value, std_raw);
    (void)nte_can_params_pack(out, &m, NTE_FRAMES_LENGTH);
    return nte_frames_protect(e2e, nte_frames_kind_params, out);
}

nte_frames_err_t nte_frames_decode_param(nte_e2e_rx_t* e2e, const uint8_t* data, size_t length,
                                         nte_frames_param_t* out, nte_e2e_result_t* e2e_result,
                                         uint8_t* lost)
{
    struct nte_can_params_t m;
    nte_frames_err_t err;
    float value;
    int16_t std_raw;
    if ((e2e == NULL) || (data == NULL) || (out == NULL)) {
        return nte_frames_err_null;
    }
    err = nte_frames_check(e2e, nte_frames_kind_params, data, length, e2e_result, lost);
    if (err != nte_frames_ok) {
        return err;
    }
    (void)nte_can_params_init(&m);
    (void)nte_can_params_unpack(&m, data, length);
    if (m.param_index >= (uint8_t)NTE_FRAMES_PARAM_COUNT) {
        return nte_frames_err_selector;
    }
    nte_frames_param_get(&m, m.param_index, &value, &std_raw);
    if (!isfinite(value)) {
        return nte_frames_err_not_finite;
    }
    out->index = m.param_index;
    out->value = value;
    if (std_raw == NTE_FRAMES_STD_ZERO_RAW) {
        out->std = 0.0f;
    } else {
        out->std = powf(10.0f, nte_can_params_sigma0_std_log10_decode(std_raw));
    }
    return nte_frames_ok;
}

/* --------------------------------------------------------------------------- heartbeat */

nte_frames_err_t nte_frames_encode_heartbeat(const nte_frames_heartbeat_t* in, nte_e2e_tx_t* e2e,
                                             uint8_t* out)
{
    struct nte_can_heartbeat_t m;
    bool clamped = false;
    float uptime;
    uint32_t uptime_raw;
    if ((in == NULL) || (e2e == NULL) || (out == NULL)) {
        return nte_frames_err_null;
    }
    if ((in->node_state > (uint8_t)NTE_FRAMES_STATE_FAULT) || (in->active_model > 2u) ||
        (in->active_estimator > 1u)) {
        return nte_frames_err_selector;
    }
    if (!isfinite(in->uptime_s) || !isfinite(in->step_time_s)) {
        return nte_frames_err_not_finite;
    }
    if ((in->uptime_s < 0.0f) || (in->uptime_s > NTE_FRAMES_UPTIME_MAX_S) ||
        (in->step_time_s < 0.0f)) {
        return nte_frames_err_range;
    }
    /* modulo the wrap without fmodf (600 B of the board's 32 KiB): k whole wraps, exact in
     * float below 2^24; the subtraction's rounding is below the 0.1 s resolution up to
     * 2^24 s (194 days; a float uptime is no finer there anyway) */
    {
        const float k = (float)(uint32_t)(in->uptime_s / NTE_FRAMES_UPTIME_WRAP_S);
        uptime = in->uptime_s - (k * NTE_FRAMES_UPTIME_WRAP_S);
        uptime = (uptime < 0.0f) ? 0.0f : uptime;
    }
    uptime_raw = nte_can_heartbeat_uptime_encode(uptime);
    if (!nte_can_heartbeat_uptime_is_in_range(uptime_raw)) {
        uptime_raw = 0u; /* rounded up to the wrap value */
    }
    (void)nte_can_heartbeat_init(&m);
    m.node_state = in->node_state;
    m.active_model = in->active_model;
    m.active_estimator = in->active_estimator;
    m.uptime = uptime_raw;
    m.e2e_errors = (uint8_t)(in->e2e_errors & 0xFFu);
    m.range_errors = (uint8_t)(in->range_errors & 0xFFu);
    m.step_time = nte_can_heartbeat_step_time_encode(
        nte_frames_clamp(in->step_time_s, 0.0f, NTE_FRAMES_STEP_TIME_MAX_S, &clamped));
    if (m.step_time > 4095u) {
        m.step_time = 4095u;
    }
    (void)nte_can_heartbeat_pack(out, &m, NTE_FRAMES_LENGTH);
    return nte_frames_protect(e2e, nte_frames_kind_heartbeat, out);
}

nte_frames_err_t nte_frames_decode_heartbeat(nte_e2e_rx_t* e2e, const uint8_t* data, size_t length,
                                             nte_frames_heartbeat_t* out,
                                             nte_e2e_result_t* e2e_result, uint8_t* lost)
{
    struct nte_can_heartbeat_t m;
    nte_frames_err_t err;
    if ((e2e == NULL) || (data == NULL) || (out == NULL)) {
        return nte_frames_err_null;
    }
    err = nte_frames_check(e2e, nte_frames_kind_heartbeat, data, length, e2e_result, lost);
    if (err != nte_frames_ok) {
        return err;
    }
    (void)nte_can_heartbeat_unpack(&m, data, length);
    if ((m.node_state > (uint8_t)NTE_FRAMES_STATE_FAULT) || (m.active_model > 2u)) {
        return nte_frames_err_selector;
    }
    if (!nte_can_heartbeat_uptime_is_in_range(m.uptime) ||
        !nte_can_heartbeat_step_time_is_in_range(m.step_time)) {
        return nte_frames_err_range;
    }
    out->node_state = m.node_state;
    out->active_model = m.active_model;
    out->active_estimator = m.active_estimator;
    out->uptime_s = nte_can_heartbeat_uptime_decode(m.uptime);
    out->e2e_errors = m.e2e_errors;
    out->range_errors = m.range_errors;
    out->step_time_s = nte_can_heartbeat_step_time_decode(m.step_time);
    return nte_frames_ok;
}

/* ----------------------------------------------------------------------------- contact */

nte_frames_err_t nte_frames_encode_contact(const nte_frames_contact_t* in, nte_e2e_tx_t* e2e,
                                           uint8_t* out)
{
    struct nte_can_contact_t m;
    bool clamped = false;
    if ((in == NULL) || (e2e == NULL) || (out == NULL)) {
        return nte_frames_err_null;
    }
    if ((in->contact_state > (uint8_t)NTE_FRAMES_CONTACT_TISSUE) || (in->active_model > 2u)) {
        return nte_frames_err_selector;
    }
    if (in->layer > NTE_FRAMES_LAYER_MAX) {
        return nte_frames_err_range;
    }
    if (!isfinite(in->tare_n) || (in->surface_valid && !isfinite(in->surface_mm))) {
        return nte_frames_err_not_finite;
    }
    if (in->surface_valid && !nte_frames_within(in->surface_mm, -NTE_FRAMES_SURFACE_MAX_MM,
                                                NTE_FRAMES_SURFACE_MAX_MM, 0.0005f)) {
        return nte_frames_err_range;
    }
    (void)nte_can_contact_init(&m);
    m.contact_state = in->contact_state;
    m.surface_valid = in->surface_valid ? 1u : 0u;
    m.active_model = in->active_model;
    m.layer = in->layer;
    m.surface = in->surface_valid ? nte_can_contact_surface_encode(in->surface_mm) : 0;
    if (!nte_can_contact_surface_is_in_range(m.surface)) {
        return nte_frames_err_range;
    }
    m.tare = nte_can_contact_tare_encode(
        nte_frames_clamp(in->tare_n, -NTE_FRAMES_FORCE_MAX_N, NTE_FRAMES_FORCE_MAX_N, &clamped));
    (void)nte_can_contact_pack(out, &m, NTE_FRAMES_LENGTH);
    return nte_frames_protect(e2e, nte_frames_kind_contact, out);
}

nte_frames_err_t nte_frames_decode_contact(nte_e2e_rx_t* e2e, const uint8_t* data, size_t length,
                                           nte_frames_contact_t* out, nte_e2e_result_t* e2e_result,
                                           uint8_t* lost)
{
    struct nte_can_contact_t m;
    nte_frames_err_t err;
    if ((e2e == NULL) || (data == NULL) || (out == NULL)) {
        return nte_frames_err_null;
    }
    err = nte_frames_check(e2e, nte_frames_kind_contact, data, length, e2e_result, lost);
    if (err != nte_frames_ok) {
        return err;
    }
    (void)nte_can_contact_unpack(&m, data, length);
    if (m.active_model > 2u) {
        return nte_frames_err_selector;
    }
    if (!nte_can_contact_surface_is_in_range(m.surface) ||
        !nte_can_contact_tare_is_in_range(m.tare)) {
        return nte_frames_err_range;
    }
    out->contact_state = m.contact_state;
    out->surface_valid = (m.surface_valid != 0u);
    out->active_model = m.active_model;
    out->layer = m.layer;
    out->surface_mm = nte_can_contact_surface_decode(m.surface);
    out->tare_n = nte_can_contact_tare_decode(m.tare);
    return nte_frames_ok;
}

/* ------------------------------------------------------------------------------ health */

nte_frames_err_t nte_frames_encode_health(const nte_frames_health_t* in, nte_e2e_tx_t* e2e,
                                          uint8_t* out)
{
    struct nte_can_health_t m;
    if ((in == NULL) || (e2e == NULL) || (out == NULL)) {
        return nte_frames_err_null;
    }
    if (!isfinite(in->confidence)) {
        return nte_frames_err_not_finite;
    }
    if (!nte_frames_within(in->confidence, 0.0f, 1.0f, 0.00005f)) {
        return nte_frames_err_range;
    }
    for (unsigned i = 0u; i < NTE_FRAMES_FILTERS; ++i) {
        if ((in->filter_flags[i] & ~(unsigned)NTE_FRAMES_FILTER_FLAGS) != 0u) {
            return nte_frames_err_range;
        }
    }
    (void)nte_can_health_init(&m);
    m.refined = in->refined ? 1u : 0u;
    m.converged = in->converged ? 1u : 0u;
    m.refining = in->refining ? 1u : 0u;
    m.confidence = nte_can_health_confidence_encode(in->confidence);
    m.filter0_flags = in->filter_flags[0];
    m.filter1_flags = in->filter_flags[1];
    m.filter2_flags = in->filter_flags[2];
    (void)nte_can_health_pack(out, &m, NTE_FRAMES_LENGTH);
    return nte_frames_protect(e2e, nte_frames_kind_health, out);
}

nte_frames_err_t nte_frames_decode_health(nte_e2e_rx_t* e2e, const uint8_t* data, size_t length,
                                          nte_frames_health_t* out, nte_e2e_result_t* e2e_result,
                                          uint8_t* lost)
{
    struct nte_can_health_t m;
    nte_frames_err_t err;
    if ((e2e == NULL) || (data == NULL) || (out == NULL)) {
        return nte_frames_err_null;
    }
    err = nte_frames_check(e2e, nte_frames_kind_health, data, length, e2e_result, lost);
    if (err != nte_frames_ok) {
        return err;
    }
    (void)nte_can_health_unpack(&m, data, length);
    if (!nte_can_health_confidence_is_in_range(m.confidence) ||
        (((m.filter0_flags | m.filter1_flags | m.filter2_flags) &
          ~(unsigned)NTE_FRAMES_FILTER_FLAGS) != 0u)) {
        return nte_frames_err_range;
    }
    out->refined = (m.refined != 0u);
    out->converged = (m.converged != 0u);
    out->refining = (m.refining != 0u);
    out->confidence = nte_can_health_confidence_decode(m.confidence);
    out->filter_flags[0] = m.filter0_flags;
    out->filter_flags[1] = m.filter1_flags;
    out->filter_flags[2] = m.filter2_flags;
    return nte_frames_ok;
}

/* ------------------------------------------------------------------------------- clock */

void nte_frames_clock_reset(nte_frames_clock_t* self)
{
    if (self != NULL) {
        self->ticks = 0u;
        self->last_raw = 0u;
        self->started = false;
    }
}

uint32_t nte_frames_clock_unwrap(nte_frames_clock_t* self, uint16_t raw)
{
    if (self == NULL) {
        return 0u;
    }
    if (!self->started) {
        self->started = true;
        self->ticks = (uint32_t)raw + 65536u;
    } else {
        const uint16_t diff = (uint16_t)(raw - self->last_raw);
        if (diff < 0x8000u) {
            self->ticks += diff;
        } else {
            self->ticks -= (uint32_t)(0x10000u - (uint32_t)diff);
        }
    }
    self->last_raw = raw;
    return self->ticks;
}
