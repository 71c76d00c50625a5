/*
 * libFuzzer harness: configuration validation (nte_config_check / nte_init) with arbitrary field
 * values, then a short run of samples derived from the input.  Built twice (float and double
 * library).  Input: records of 9 bytes patching the default configuration:
 *   byte 0      field selector (modulo the field count below); bit 7 set = take the value from
 *               a table of edge values (bytes 1 picks it) instead of the raw bytes
 *   bytes 1..8  the value: an nte_real_t (4 or 8 bytes) or an int32_t (4 bytes), little endian
 * A record whose selector byte is 0xFF ends the patches; the remaining bytes are samples of
 * 8 bytes each: dt (uint8, x 100 us, 0 allowed), depth (int16 / 100 mm), velocity (int16 / 10
 * mm/s), force (int16 / 1000 N), NaN/inf injected by flags in dt's top bits.
 * Properties (abort() on violation): a refused configuration leaves the instance untouched; an
 * accepted one gives a finite initial state; every output of every step is finite and its
 * force within +-force_max_n; the DIVERGED status bit is set exactly when the diverged counter
 * moves; counters are monotonic; the identified parameters and standard deviations are finite,
 * sd >= 0.  With NTE_FUZZ_REPORT set in the environment, each input ends with one line on
 * stderr: "report: steps=N diverged=D max_force=F" (the regression tests read it).
 */
#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nte.h"

static int finite_r(nte_real_t x) { return isfinite(x) ? 1 : 0; }

static nte_real_t nte_abs_r(nte_real_t x) { return (x < (nte_real_t)0) ? -x : x; }

/* A violated property: say which one (file:line), then abort() so libFuzzer keeps the input. */
#define need(ok) need_at((ok) ? 1 : 0, __LINE__)
static void need_at(int ok, int line)
{
    if (!ok) {
        (void)fprintf(stderr, "%s:%d: property violated\n", __FILE__, line);
        abort();
    }
}

static void check_state(const nte_t* e)
{
    for (size_t i = 0U; i < NTE_PARAM_COUNT; i++) {
        need(finite_r(e->u[i]));
    }
    need(finite_r(e->z));
    const nte_real_t* pp = &e->P[0][0][0];
    for (size_t i = 0U; i < sizeof e->P / sizeof e->P[0][0][0]; i++) {
        need(finite_r(pp[i]));
    }
    need(finite_r(e->last.force_hat_n) && finite_r(e->last.z) && finite_r(e->last.innovation_n));
}

static const double edge[16] = {
    0.0,    -0.0,    1.0,   -1.0, 1e-30,  -1e-30,           1e30,       -1e30, 1e-45,
    3.4e38, -3.4e38, 1e300, 0.5,  1000.0, (double)INFINITY, (double)NAN};

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    static nte_t est;
    static nte_t before;
    nte_config_t cfg;
    nte_config_default(&cfg, 1 + (int32_t)(size & 1U), nte_schedule_all);

    nte_real_t* reals[] = {&cfg.eps_mm_s,
                           &cfg.beta0,
                           &cfg.r_n2,
                           &cfg.q_z,
                           &cfg.q_u[0],
                           &cfg.q_u[1],
                           &cfg.q_u[2],
                           &cfg.q_u[3],
                           &cfg.q_u[4],
                           &cfg.q_u[5],
                           &cfg.q_u[6],
                           &cfg.q_u_default,
                           &cfg.p0_z,
                           &cfg.p0_u,
                           &cfg.gate_sigma,
                           &cfg.u_max,
                           &cfg.var_floor_z,
                           &cfg.var_floor_u,
                           &cfg.v_still_mm_s,
                           &cfg.dt_max_s,
                           &cfg.depth_min_mm,
                           &cfg.depth_max_mm,
                           &cfg.speed_max_mm_s,
                           &cfg.force_max_n,
                           &cfg.nominal[0],
                           &cfg.nominal[1],
                           &cfg.nominal[2],
                           &cfg.nominal[3],
                           &cfg.nominal[4],
                           &cfg.nominal[5],
                           &cfg.nominal[6],
                           &cfg.f1_excess,
                           &cfg.robust.restart_p0_u,
                           &cfg.robust.lm_lambda0,
                           &cfg.robust.converged_confidence,
                           &cfg.robust.converged_change};
    int32_t* ints[] = {&cfg.model,
                       &cfg.substeps,
                       &cfg.gate_reopen_after,
                       &cfg.robust.buffer_len,
                       &cfg.robust.fit_substeps,
                       &cfg.robust.fit_iterations,
                       &cfg.robust.min_entries};
    const size_t n_reals = sizeof reals / sizeof reals[0];
    const size_t n_ints = sizeof ints / sizeof ints[0];
    const size_t n_fields = n_reals + n_ints + 4U; /* + schedule, estimator, sign_inflation,
                                                      a raw int32 into the enums */
    size_t off = 0U;
    while (off + 9U <= size) {
        const uint8_t sel = data[off];
        if (sel == 0xFFU) {
            off += 1U;
            break;
        }
        const uint8_t* v = data + off + 1U;
        off += 9U;
        const size_t field = (size_t)(sel & 0x7FU) % n_fields;
        if (field < n_reals) {
            nte_real_t x;
            if ((sel & 0x80U) != 0U) {
                x = (nte_real_t)edge[v[0] & 15U];
            } else {
                memcpy(&x, v, sizeof x);
            }
            *reals[field] = x;
        } else if (field < n_reals + n_ints) {
            int32_t i;
            memcpy(&i, v, sizeof i);
            if ((sel & 0x80U) != 0U) {
                i = (int32_t)(int8_t)v[0]; /* small values near the limits */
            }
            *ints[field - n_reals] = i;
        } else {
            int32_t i;
            memcpy(&i, v, sizeof i);
            switch (field - n_reals - n_ints) {
            case 0U: cfg.schedule = (nte_schedule_t)(i & 3); break;
            case 1U: cfg.estimator = (nte_estimator_t)(i & 3); break;
            case 2U: cfg.sign_inflation = (i & 1) != 0; break;
            default: cfg.substeps = i; break;
            }
        }
    }
    /* The robust refinement's cost grows with these: keep one input's run short (the
     * validation still sees every value above). */
    memset(&est, 0xA5, sizeof est);
    memcpy(&before, &est, sizeof before);
    const nte_err_t check = nte_config_check(&cfg);
    const nte_err_t r = nte_init(&est, &cfg);
    need(check == r);
    if (r != nte_err_ok) {
        need(r < 0);
        need(memcmp(&est, &before, sizeof est) == 0);
        return 0;
    }
    if ((cfg.estimator == nte_estimator_robust) &&
        ((cfg.robust.fit_iterations > 40) || (cfg.robust.fit_substeps > 8))) {
        return 0;
    }
    check_state(&est);

    static int report = -1;
    if (report < 0) {
        report = (getenv("NTE_FUZZ_REPORT") != NULL) ? 1 : 0;
    }
    unsigned steps = 0U;
    unsigned diverged = 0U;
    double max_force = 0.0;
    int64_t t_us = 0;
    nte_counters_t c0 = est.counters;
    for (; off + 8U <= size; off += 8U) {
        const uint8_t* s = data + off;
        nte_sample_t smp;
        t_us += (int64_t)(s[0] & 0x3FU) * 100;
        smp.t_us = t_us;
        smp.depth_mm = (nte_real_t)(int16_t)(s[1] | (s[2] << 8)) / (nte_real_t)100;
        smp.velocity_mm_s = (nte_real_t)(int16_t)(s[3] | (s[4] << 8)) / (nte_real_t)10;
        smp.force_n = (nte_real_t)(int16_t)(s[5] | (s[6] << 8)) / (nte_real_t)1000;
        if ((s[0] & 0xC0U) == 0xC0U) {
            smp.force_n = (nte_real_t)((s[7] & 1U) ? NAN : INFINITY);
        }
        nte_output_t out;
        need(nte_step(&est, &smp, &out) == nte_err_ok);
        need(finite_r(out.force_hat_n) && finite_r(out.z) && finite_r(out.innovation_n) &&
             finite_r(out.nis) && finite_r(out.confidence));
        /* the published force never leaves its physical range */
        need(nte_abs_r(out.force_hat_n) <= est.cfg.force_max_n);
        /* the flag and the counter tell the same story */
        const int flagged = (out.status & NTE_STATUS_DIVERGED) != 0U;
        need(flagged == (est.counters.diverged != c0.diverged));
        steps++;
        diverged += (unsigned)flagged;
        if ((double)nte_abs_r(out.force_hat_n) > max_force) {
            max_force = (double)nte_abs_r(out.force_hat_n);
        }
        check_state(&est);
        const uint32_t* a = (const uint32_t*)&c0;
        const uint32_t* b = (const uint32_t*)&est.counters;
        for (size_t i = 0U; i < sizeof c0 / sizeof(uint32_t); i++) {
            need(b[i] >= a[i]);
        }
        c0 = est.counters;
    }
    nte_param_estimate_t p[NTE_PARAM_COUNT];
    const size_t np = nte_get_params(&est, p, NTE_PARAM_COUNT);
    need(np <= NTE_PARAM_COUNT);
    for (size_t i = 0U; i < np; i++) {
        need(finite_r(p[i].value) && finite_r(p[i].sd) && (p[i].sd >= (nte_real_t)0));
    }
    if (report == 1) {
        fprintf(stderr, "report: steps=%u diverged=%u max_force=%.9g\n", steps, diverged,
                max_force);
    }
    return 0;
}
