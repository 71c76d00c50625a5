/*
 * The robust estimator's pieces on tiny fake inputs: the LDL^T solve (a table of systems, the
 * pivot handling), the insertion buffer (decimation and compaction, sample by sample), the
 * refinement trigger (exactly at min_entries, rejected samples, reset), and its config checks.
 * The whole estimator is compared with the reference bit for bit in
 * tests/python/test_c_robust.py.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "nte.h"
#include "nte_robust.h"

static nte_sample_t sample(const int64_t t_us, const double l, const double v, const double f)
{
    nte_sample_t s;
    s.t_us = t_us;
    s.depth_mm = (nte_real_t)l;
    s.velocity_mm_s = (nte_real_t)v;
    s.force_n = (nte_real_t)f;
    return s;
}

/* ----------------------------------------------------------------------------------------- */
/* LDL^T: systems with small-integer factors have exact solutions in both precisions. */
typedef struct ldlt_case_t {
    size_t n;
    double M[3][3]; /* lower triangle used; the upper holds garbage (must be ignored) */
    double b[3];
    double x[3];
    bool ok;
} ldlt_case_t;

static void test_ldlt_table(void** state)
{
    (void)state;
    static const ldlt_case_t cases[] = {
        /* 1x1 */
        {1, {{4, 0, 0}, {0, 0, 0}, {0, 0, 0}}, {2, 0, 0}, {0.5, 0, 0}, true},
        /* 2x2: M = [[4, 2], [2, 5]] = L D L^T, L21 = 0.5, D = (4, 4) */
        {2, {{4, 99, 0}, {2, 5, 0}, {0, 0, 0}}, {6, 7, 0}, {1, 1, 0}, true},
        /* 3x3: L = [[1,0,0],[.5,1,0],[.25,.5,1]], D = (4, 2, 1), x = (1, -1, 2) */
        {3, {{4, -7, 13}, {2, 3, 42}, {1, 1.5, 1.75}}, {4, 2, 3}, {1, -1, 2}, true},
        /* diagonal */
        {3, {{1, 0, 0}, {0, 2, 0}, {0, 0, 8}}, {3, 4, 2}, {3, 2, 0.25}, true},
        /* zero pivot first: not positive definite, x = 0 */
        {2, {{0, 0, 0}, {1, 1, 0}, {0, 0, 0}}, {1, 1, 0}, {0, 0, 0}, false},
        /* indefinite: second pivot 1 - 4 < 0 */
        {2, {{1, 0, 0}, {2, 1, 0}, {0, 0, 0}}, {1, 1, 0}, {0, 0, 0}, false},
        /* negative last pivot of a 3x3 */
        {3, {{1, 0, 0}, {0, 1, 0}, {0, 0, -1}}, {1, 1, 1}, {0, 0, 0}, false},
        /* NaN on the diagonal: the pivot test is false, not positive */
        {1, {{(double)NAN, 0, 0}, {0, 0, 0}, {0, 0, 0}}, {1, 0, 0}, {0, 0, 0}, false},
    };
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        nte_robust_mat_t M;
        nte_real_t b[NTE_IDENTIFIED_MAX];
        nte_real_t x[NTE_IDENTIFIED_MAX];
        memset(M, 0, sizeof M);
        memset(x, 0x5A, sizeof x);
        for (size_t i = 0; i < cases[c].n; i++) {
            b[i] = (nte_real_t)cases[c].b[i];
            for (size_t j = 0; j < cases[c].n; j++) {
                M[i][j] = (nte_real_t)cases[c].M[i][j];
            }
        }
        const bool ok = nte_robust_ldlt_solve(cases[c].n, M, b, x);
        assert_int_equal(ok, cases[c].ok);
        for (size_t i = 0; i < cases[c].n; i++) {
            const nte_real_t want = (nte_real_t)cases[c].x[i];
            assert_memory_equal(&x[i], &want, sizeof want);
        }
    }
}

/* A random SPD 6x6 system (M = A A^T + I): the residual is at rounding level. */
static void test_ldlt_spd6_residual(void** state)
{
    (void)state;
    uint32_t seed = 12345U;
    for (int rep = 0; rep < 50; rep++) {
        double a[6][6];
        for (size_t i = 0; i < 6; i++) {
            for (size_t j = 0; j < 6; j++) {
                seed = seed * 1664525U + 1013904223U;
                a[i][j] = ((double)(seed >> 8) / 16777216.0) - 0.5;
            }
        }
        nte_robust_mat_t M;
        nte_real_t b[6];
        nte_real_t x[6];
        for (size_t i = 0; i < 6; i++) {
            for (size_t j = 0; j < 6; j++) {
                double s = (i == j) ? 1.0 : 0.0;
                for (size_t k = 0; k < 6; k++) {
                    s += a[i][k] * a[j][k];
                }
                M[i][j] = (nte_real_t)s;
            }
            b[i] = (nte_real_t)(1.0 + (double)i);
        }
        assert_true(nte_robust_ldlt_solve(6, M, b, x));
        for (size_t i = 0; i < 6; i++) {
            double r = (double)b[i];
            for (size_t j = 0; j < 6; j++) {
                r -= (double)M[i][j] * (double)x[j];
            }
            assert_true(fabs(r) < 1e-4);
        }
    }
}

/* ----------------------------------------------------------------------------------------- */
static void robust_config(nte_config_t* cfg, const int32_t buffer_len, const int32_t min_entries)
{
    nte_config_default(cfg, 2, nte_schedule_all);
    cfg->estimator = nte_estimator_robust;
    cfg->robust.buffer_len = buffer_len;
    cfg->robust.min_entries = min_entries;
    cfg->robust.fit_iterations = 2;
    cfg->robust.fit_substeps = 1;
    /* the whole fit in the step that ends the insertion: these tests are about when a
     * refinement starts and what it adopts; the slicing has its own (test_c_robust.py) */
    cfg->robust.slice_entries = 0;
}

/* Decimation and compaction, sample by sample, with buffer_len 4: the kept depths (the depth
 * of sample k is k mm, k = 0 at the surface) must stay uniformly spaced. */
static void test_buffer_decimation_and_compaction(void** state)
{
    (void)state;
    static const struct {
        uint32_t count;
        uint32_t decim;
        double depths[4]; /* the first `count` entries */
    } want[] = {
        /* k = 1 enters: the anchor (k = 0) and k = 1 */
        {2, 1, {0, 1, 0, 0}},
        {3, 1, {0, 1, 2, 0}},
        {4, 1, {0, 1, 2, 3}},
        /* k = 4: full -> keep 0, 2; decim 2; phase 4 is even: k = 4 kept */
        {3, 2, {0, 2, 4, 0}},
        {3, 2, {0, 2, 4, 0}},
        {4, 2, {0, 2, 4, 6}},
        {4, 2, {0, 2, 4, 6}},
        /* k = 8: full -> keep 0, 4; decim 4; phase 8 divisible by 4: kept */
        {3, 4, {0, 4, 8, 0}},
        {3, 4, {0, 4, 8, 0}},
        {3, 4, {0, 4, 8, 0}},
        {3, 4, {0, 4, 8, 0}},
        {4, 4, {0, 4, 8, 12}},
    };
    static nte_t est;
    nte_config_t cfg;
    robust_config(&cfg, 4, 4);
    assert_int_equal(nte_init(&est, &cfg), nte_err_ok);
    const int64_t t0 = 1000000;
    nte_sample_t s = sample(t0, 0.0, 0.0, 0.0);
    assert_int_equal(nte_step(&est, &s, NULL), nte_err_ok);
    assert_int_equal(est.robust.count, 0);
    for (size_t k = 1; k <= sizeof want / sizeof want[0]; k++) {
        const int64_t t = t0 + (int64_t)k * 5000;
        s = sample(t, (double)k, 10.0, 0.01 * (double)k);
        assert_int_equal(nte_step(&est, &s, NULL), nte_err_ok);
        assert_int_equal(est.robust.count, want[k - 1].count);
        assert_int_equal(est.robust.decim, want[k - 1].decim);
        assert_int_equal(est.robust.phase, k + 1);
        for (uint32_t i = 0; i < want[k - 1].count; i++) {
            const double d = want[k - 1].depths[i];
            const nte_real_t l = (nte_real_t)d;
            const nte_real_t f = (nte_real_t)(0.01 * d);
            /* t - t0 of the sample of depth d, s, converted as the reference does */
            const nte_real_t tr = (nte_real_t)((int64_t)(d * 5000.0)) / (nte_real_t)1.0e6;
            assert_memory_equal(&est.robust.buf[1][i], &l, sizeof l);
            assert_memory_equal(&est.robust.buf[3][i], &f, sizeof f);
            assert_memory_equal(&est.robust.buf[0][i], &tr, sizeof tr);
            if (d > 0.0) {
                const nte_real_t v = (nte_real_t)10.0;
                assert_memory_equal(&est.robust.buf[2][i], &v, sizeof v);
            }
        }
    }
    /* a rejected sample (time not increasing) changes nothing */
    const uint32_t count = est.robust.count;
    const uint32_t phase = est.robust.phase;
    s = sample(t0, 3.0, 10.0, 0.0);
    nte_output_t o;
    assert_int_equal(nte_step(&est, &s, &o), nte_err_ok);
    assert_true((o.status & NTE_STATUS_REJECTED) != 0U);
    assert_int_equal(est.robust.count, count);
    assert_int_equal(est.robust.phase, phase);
}

/* One insertion of `inside` samples in the tissue, then a sample at the surface; returns the
 * status of that last sample.  The buffer then holds anchor + inside + the leaving sample. */
static uint32_t insertion(nte_t* est, int64_t* t, const int inside, uint32_t* count_at_exit)
{
    nte_output_t o;
    nte_sample_t s = sample(*t, 0.0, 0.0, 0.001);
    assert_int_equal(nte_step(est, &s, &o), nte_err_ok);
    *t += 5000;
    for (int k = 1; k <= inside; k++) {
        const double l = 0.05 * (double)k;
        s = sample(*t, l, 10.0, 0.002 * l);
        assert_int_equal(nte_step(est, &s, &o), nte_err_ok);
        assert_int_equal(o.status & NTE_STATUS_REFINED, 0U);
        *t += 5000;
    }
    *count_at_exit = est->robust.count + 1U;
    s = sample(*t, 0.0, -10.0, 0.0);
    assert_int_equal(nte_step(est, &s, &o), nte_err_ok);
    *t += 5000;
    assert_int_equal(est->robust.count, 0);
    assert_false(est->robust.inside);
    return o.status;
}

static void test_refinement_trigger(void** state)
{
    (void)state;
    static nte_t est;
    nte_config_t cfg;
    for (int32_t min_entries = 3; min_entries <= 8; min_entries++) {
        robust_config(&cfg, 8, min_entries);
        assert_int_equal(nte_init(&est, &cfg), nte_err_ok);
        int64_t t = 0;
        /* anchor + k inside + the leaving sample = k + 2 entries (k >= 1): k = min_entries - 3
         * is one short, k = min_entries - 2 is exactly enough */
        uint32_t count = 0;
        if (min_entries >= 4) {
            const uint32_t st = insertion(&est, &t, min_entries - 3, &count);
            assert_int_equal(count, (uint32_t)min_entries - 1U);
            assert_int_equal(st & NTE_STATUS_REFINED, 0U);
            assert_false(est.robust.has_refined);
        }
        nte_output_t o;
        uint32_t st = insertion(&est, &t, min_entries - 2, &count);
        assert_int_equal(count, (uint32_t)min_entries);
        assert_int_equal(st & NTE_STATUS_REFINED, NTE_STATUS_REFINED);
        assert_true(est.robust.has_refined);
        const nte_real_t conf = est.robust.confidence;
        assert_true((conf > 0) && (conf <= 1));
        /* the flag belongs to the refining sample only; the confidence persists */
        nte_sample_t s = sample(t, 0.0, 0.0, 0.0);
        assert_int_equal(nte_step(&est, &s, &o), nte_err_ok);
        t += 5000;
        assert_int_equal(o.status & NTE_STATUS_REFINED, 0U);
        assert_memory_equal(&o.confidence, &conf, sizeof conf);
        /* a rejected sample at the surface ends nothing */
        st = insertion(&est, &t, 6, &count);
        assert_int_equal(st & NTE_STATUS_REFINED, NTE_STATUS_REFINED);
        s = sample(t, 0.3, 10.0, 0.0);
        assert_int_equal(nte_step(&est, &s, &o), nte_err_ok);
        s = sample(t - 1, 0.0, 0.0, 0.0); /* time goes back: rejected */
        assert_int_equal(nte_step(&est, &s, &o), nte_err_ok);
        assert_true((o.status & NTE_STATUS_REJECTED) != 0U);
        assert_int_equal(o.status & NTE_STATUS_REFINED, 0U);
        assert_true(est.robust.inside);
        /* reset: the configured nominal, an empty buffer, no refinement yet */
        assert_int_equal(nte_reset(&est), nte_err_ok);
        assert_false(est.robust.inside);
        assert_false(est.robust.has_refined);
        assert_int_equal(est.robust.count, 0);
        const nte_real_t zero = 0;
        assert_memory_equal(&est.robust.confidence, &zero, sizeof zero);
        assert_memory_equal(est.nominal, cfg.nominal, sizeof est.nominal);
    }
}

/* The bank alone never sets the robust bits and reports confidence 0. */
static void test_bank_has_no_robust_bits(void** state)
{
    (void)state;
    static nte_t est;
    nte_config_t cfg;
    robust_config(&cfg, 8, 4);
    cfg.estimator = nte_estimator_bank;
    assert_int_equal(nte_init(&est, &cfg), nte_err_ok);
    int64_t t = 0;
    for (int cycle = 0; cycle < 2; cycle++) {
        uint32_t count = 0;
        const uint32_t st = insertion(&est, &t, 20, &count);
        assert_int_equal(st & (NTE_STATUS_REFINED | NTE_STATUS_CONVERGED), 0U);
    }
}

typedef void (*spoil_fn)(nte_config_t*);
static void spoil_estimator(nte_config_t* c) { c->estimator = (nte_estimator_t)2; }
static void spoil_len_odd(nte_config_t* c) { c->robust.buffer_len = 95; }
static void spoil_len_big(nte_config_t* c) { c->robust.buffer_len = NTE_ROBUST_BUFFER_LEN + 2; }
static void spoil_len_zero(nte_config_t* c) { c->robust.buffer_len = 0; }
static void spoil_substeps(nte_config_t* c) { c->robust.fit_substeps = 0; }
static void spoil_iters(nte_config_t* c) { c->robust.fit_iterations = -1; }
static void spoil_min0(nte_config_t* c) { c->robust.min_entries = 0; }
static void spoil_min_big(nte_config_t* c) { c->robust.min_entries = 97; }
static void spoil_p0u(nte_config_t* c) { c->robust.restart_p0_u = 0; }
static void spoil_p0u_big(nte_config_t* c) { c->robust.restart_p0_u = 101; }
static void spoil_lambda(nte_config_t* c) { c->robust.lm_lambda0 = (nte_real_t)NAN; }
static void spoil_conf(nte_config_t* c) { c->robust.converged_confidence = (nte_real_t)INFINITY; }
static void spoil_change(nte_config_t* c) { c->robust.converged_change = -1; }

static void test_robust_config_errors(void** state)
{
    (void)state;
    static const struct {
        spoil_fn fn;
        nte_err_t err;
    } cases[] = {
        {spoil_estimator, nte_err_bad_estimator}, {spoil_len_odd, nte_err_bad_robust},
        {spoil_len_big, nte_err_bad_robust},      {spoil_len_zero, nte_err_bad_robust},
        {spoil_substeps, nte_err_bad_robust},     {spoil_iters, nte_err_bad_robust},
        {spoil_min0, nte_err_bad_robust},         {spoil_min_big, nte_err_bad_robust},
        {spoil_p0u, nte_err_bad_robust},          {spoil_lambda, nte_err_bad_robust},
        {spoil_conf, nte_err_bad_robust},         {spoil_change, nte_err_bad_robust},
        {spoil_p0u_big, nte_err_bad_robust},
    };
    static nte_t est;
    static nte_t snapshot;
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        nte_config_t cfg;
        nte_config_default(&cfg, 2, nte_schedule_all);
        cfg.estimator = nte_estimator_robust;
        assert_int_equal(nte_config_check(&cfg), nte_err_ok);
        cases[i].fn(&cfg);
        memset(&est, 0xA5, sizeof est);
        memcpy(&snapshot, &est, sizeof est);
        assert_int_equal(nte_init(&est, &cfg), cases[i].err);
        assert_memory_equal(&est, &snapshot, sizeof est);
        /* the bank ignores the robust fields */
        if (cases[i].err == nte_err_bad_robust) {
            cfg.estimator = nte_estimator_bank;
            assert_int_equal(nte_config_check(&cfg), nte_err_ok);
        }
    }
}

/* The integer ranges nte_config_check applies are the generated ones (NTE_RANGE_*, from
 * reference_py/config.py): each bound accepted, one past it refused. */
typedef struct range_case_t {
    int32_t* field;
    int32_t lo;
    int32_t hi;
    nte_err_t err;
} range_case_t;

static void check_bounds(nte_config_t* cfg, const range_case_t* rc)
{
    const int32_t keep = *rc->field;
    *rc->field = rc->lo;
    assert_int_equal(nte_config_check(cfg), nte_err_ok);
    *rc->field = rc->lo - 1;
    assert_int_equal(nte_config_check(cfg), rc->err);
    *rc->field = rc->hi;
    assert_int_equal(nte_config_check(cfg), nte_err_ok);
    *rc->field = rc->hi + 1;
    assert_int_equal(nte_config_check(cfg), rc->err);
    *rc->field = keep;
}

static void test_generated_ranges(void** state)
{
    (void)state;
    nte_config_t cfg;
    nte_config_default(&cfg, 2, nte_schedule_all);
    cfg.estimator = nte_estimator_robust;
    cfg.robust.min_entries = NTE_RANGE_ROB_MIN_ENTRIES_MIN;
    const int32_t len_max = (NTE_ROBUST_BUFFER_LEN < NTE_RANGE_ROB_BUFFER_LEN_MAX)
                                ? NTE_ROBUST_BUFFER_LEN
                                : NTE_RANGE_ROB_BUFFER_LEN_MAX;
    const range_case_t cases[] = {
        {&cfg.substeps, NTE_RANGE_SUBSTEPS_MIN, NTE_RANGE_SUBSTEPS_MAX, nte_err_bad_substeps},
        {&cfg.gate_reopen_after, NTE_RANGE_GATE_REOPEN_AFTER_MIN, NTE_RANGE_GATE_REOPEN_AFTER_MAX,
         nte_err_bad_gate_reopen},
        {&cfg.robust.fit_substeps, NTE_RANGE_ROB_FIT_SUBSTEPS_MIN, NTE_RANGE_ROB_FIT_SUBSTEPS_MAX,
         nte_err_bad_robust},
        {&cfg.robust.fit_iterations, NTE_RANGE_ROB_FIT_ITERATIONS_MIN,
         NTE_RANGE_ROB_FIT_ITERATIONS_MAX, nte_err_bad_robust},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        check_bounds(&cfg, &cases[i]);
    }
    /* buffer_len: even, so one past a bound is two past it (odd values are refused anyway) */
    cfg.robust.buffer_len = NTE_RANGE_ROB_BUFFER_LEN_MIN;
    assert_int_equal(nte_config_check(&cfg), nte_err_ok);
    cfg.robust.buffer_len = NTE_RANGE_ROB_BUFFER_LEN_MIN - 2;
    assert_int_equal(nte_config_check(&cfg), nte_err_bad_robust);
    cfg.robust.buffer_len = len_max;
    assert_int_equal(nte_config_check(&cfg), nte_err_ok);
    /* min_entries up to buffer_len */
    cfg.robust.min_entries = len_max;
    assert_int_equal(nte_config_check(&cfg), nte_err_ok);
    cfg.robust.min_entries = NTE_RANGE_ROB_MIN_ENTRIES_MIN - 1;
    assert_int_equal(nte_config_check(&cfg), nte_err_bad_robust);
    cfg.robust.buffer_len = len_max + 2;
    assert_int_equal(nte_config_check(&cfg), nte_err_bad_robust);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ldlt_table),
        cmocka_unit_test(test_ldlt_spd6_residual),
        cmocka_unit_test(test_buffer_decimation_and_compaction),
        cmocka_unit_test(test_refinement_trigger),
        cmocka_unit_test(test_bank_has_no_robust_bits),
        cmocka_unit_test(test_robust_config_errors),
        cmocka_unit_test(test_generated_ranges),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
