/*
 * The public API through its front door: every error code (and that a refused config leaves
 * the instance untouched), every status flag and counter, every filter index of both models
 * under both schedules, reset and parameter read-out.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "nte.h"

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
typedef void (*spoil_fn)(nte_config_t*);
static void spoil_model(nte_config_t* c) { c->model = 4; }
/* Model III's fields */
static void spoil_branches(nte_config_t* c) { c->relax_branches = 3; }
static void spoil_presliding(nte_config_t* c) { c->presliding_mm = (nte_real_t)0; }
static void spoil_tau_big(nte_config_t* c) { c->tau_slow_s = (nte_real_t)3601; }
static void spoil_tau_nan(nte_config_t* c) { c->tau_fast_s = (nte_real_t)NAN; }
static void spoil_g_sum(nte_config_t* c)
{
    c->model = 3;
    c->nominal[nte_param_g_slow] = (nte_real_t)0.9;
}
static void spoil_g_zero(nte_config_t* c)
{
    c->model = 3;
    c->nominal[nte_param_g_fast] = (nte_real_t)0;
}
static void spoil_m3_robust(nte_config_t* c)
{
    c->model = 3;
    c->estimator = nte_estimator_robust;
}
/* Model III's layer sets (THE LAYER SETS): one good set, then each rule broken */
static void one_layer_set(nte_config_t* c)
{
    c->model = 3;
    c->layer_sets = 1U;
    c->layer_set[0].start_mm = (nte_real_t)4.0;
    c->layer_set[0].values[nte_layer_sigma0] = c->nominal[nte_param_sigma0];
    c->layer_set[0].values[nte_layer_f1] = c->nominal[nte_param_f1];
    c->layer_set[0].values[nte_layer_beta] = c->nominal[nte_param_beta];
    c->layer_set[0].values[nte_layer_sigma2] = c->nominal[nte_param_sigma2];
}
static void spoil_sets_model2(nte_config_t* c)
{
    one_layer_set(c);
    c->model = 2;
}
static void spoil_sets_count(nte_config_t* c)
{
    one_layer_set(c);
    c->layer_sets = NTE_LAYER_SETS_MAX + 1U;
}
static void spoil_sets_start0(nte_config_t* c)
{
    one_layer_set(c);
    c->layer_set[0].start_mm = (nte_real_t)0;
}
static void spoil_sets_order(nte_config_t* c)
{
    one_layer_set(c);
    c->layer_sets = 2U;
    c->layer_set[1] = c->layer_set[0]; /* the same start again: not deeper */
}
static void spoil_sets_deep(nte_config_t* c)
{
    one_layer_set(c);
    c->layer_set[0].start_mm = c->depth_max_mm * (nte_real_t)1.01;
}
static void spoil_sets_value(nte_config_t* c)
{
    one_layer_set(c);
    c->layer_set[0].values[nte_layer_sigma2] = (nte_real_t)NAN;
}
static void spoil_sets_g0(nte_config_t* c)
{
    one_layer_set(c);
    c->layer_set[0].values[nte_layer_f1] = -c->nominal[nte_param_f2] * (nte_real_t)0.9;
}
static void spoil_model0(nte_config_t* c) { c->model = 0; }
static void spoil_schedule(nte_config_t* c) { c->schedule = (nte_schedule_t)7; }
static void spoil_substeps0(nte_config_t* c) { c->substeps = 0; }
static void spoil_substeps17(nte_config_t* c) { c->substeps = 17; }
static void spoil_reopen0(nte_config_t* c) { c->gate_reopen_after = 0; }
static void spoil_reopen1001(nte_config_t* c) { c->gate_reopen_after = 1001; }
static void spoil_eps_nan(nte_config_t* c) { c->eps_mm_s = (nte_real_t)NAN; }
static void spoil_eps_zero(nte_config_t* c) { c->eps_mm_s = 0; }
static void spoil_eps_neg(nte_config_t* c) { c->eps_mm_s = -1; }
static void spoil_r_inf(nte_config_t* c) { c->r_n2 = (nte_real_t)INFINITY; }
static void spoil_r_zero(nte_config_t* c) { c->r_n2 = 0; }
static void spoil_p0z(nte_config_t* c) { c->p0_z = -1; }
static void spoil_gate(nte_config_t* c) { c->gate_sigma = 0; }
static void spoil_floor(nte_config_t* c) { c->var_floor_u = 0; }
static void spoil_qz(nte_config_t* c) { c->q_z = (nte_real_t)-1e-9f; }
static void spoil_qu_inf(nte_config_t* c) { c->q_u[2] = (nte_real_t)INFINITY; }
static void spoil_vstill(nte_config_t* c) { c->v_still_mm_s = (nte_real_t)NAN; }
static void spoil_dmin_nan(nte_config_t* c) { c->depth_min_mm = (nte_real_t)NAN; }
static void spoil_range(nte_config_t* c) { c->depth_min_mm = 600; }
static void spoil_nominal(nte_config_t* c) { c->nominal[1] = (nte_real_t)NAN; }
/* the upper bounds: past them a published estimate or its sd could overflow (fuzzer finding) */
static void spoil_nominal_big(nte_config_t* c) { c->nominal[nte_param_alpha] = (nte_real_t)1.5e3; }
static void spoil_umax(nte_config_t* c) { c->u_max = (nte_real_t)10.5; }
static void spoil_p0u(nte_config_t* c) { c->p0_u = (nte_real_t)101; }
static void spoil_f1_low(nte_config_t* c)
{
    c->f1_excess = 0;
    c->nominal[nte_param_f1] = (nte_real_t)0.01;
}
static void spoil_f1_neg(nte_config_t* c) { c->f1_excess = -1; }
static void spoil_f1_nan(nte_config_t* c) { c->f1_excess = (nte_real_t)NAN; }

static void test_every_error_code_leaves_instance_untouched(void** state)
{
    (void)state;
    static const struct {
        spoil_fn fn;
        nte_err_t err;
    } cases[] = {
        {spoil_model, nte_err_bad_model},
        {spoil_model0, nte_err_bad_model},
        {spoil_schedule, nte_err_bad_schedule},
        {spoil_substeps0, nte_err_bad_substeps},
        {spoil_substeps17, nte_err_bad_substeps},
        {spoil_reopen0, nte_err_bad_gate_reopen},
        {spoil_reopen1001, nte_err_bad_gate_reopen},
        {spoil_eps_nan, nte_err_not_finite},
        {spoil_eps_zero, nte_err_not_positive},
        {spoil_eps_neg, nte_err_not_positive},
        {spoil_r_inf, nte_err_not_finite},
        {spoil_r_zero, nte_err_not_positive},
        {spoil_p0z, nte_err_not_positive},
        {spoil_gate, nte_err_not_positive},
        {spoil_floor, nte_err_not_positive},
        {spoil_qz, nte_err_not_positive},
        {spoil_qu_inf, nte_err_not_finite},
        {spoil_vstill, nte_err_not_finite},
        {spoil_dmin_nan, nte_err_not_finite},
        {spoil_range, nte_err_bad_range},
        {spoil_nominal, nte_err_bad_nominal},
        {spoil_f1_low, nte_err_bad_f1},
        {spoil_f1_neg, nte_err_bad_f1},
        {spoil_f1_nan, nte_err_bad_f1},
        {spoil_nominal_big, nte_err_bad_nominal},
        {spoil_umax, nte_err_bad_range},
        {spoil_p0u, nte_err_bad_range},
        {spoil_branches, nte_err_bad_range},
        {spoil_presliding, nte_err_not_positive},
        {spoil_tau_big, nte_err_bad_range},
        {spoil_tau_nan, nte_err_not_finite},
        {spoil_g_sum, nte_err_bad_nominal},
        {spoil_g_zero, nte_err_bad_nominal},
        {spoil_m3_robust, nte_err_bad_estimator},
        {spoil_sets_model2, nte_err_bad_layer_sets},
        {spoil_sets_count, nte_err_bad_layer_sets},
        {spoil_sets_start0, nte_err_bad_layer_sets},
        {spoil_sets_order, nte_err_bad_layer_sets},
        {spoil_sets_deep, nte_err_bad_layer_sets},
        {spoil_sets_value, nte_err_bad_layer_sets},
        {spoil_sets_g0, nte_err_bad_layer_sets},
    };
    static nte_t est;
    static nte_t snapshot;
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        nte_config_t cfg;
        nte_config_default(&cfg, 2, nte_schedule_all);
        cases[i].fn(&cfg);
        memset(&est, 0xA5, sizeof est);
        memcpy(&snapshot, &est, sizeof est);
        assert_int_equal(nte_config_check(&cfg), cases[i].err);
        assert_int_equal(nte_init(&est, &cfg), cases[i].err);
        assert_memory_equal(&est, &snapshot, sizeof est);
    }
    nte_config_t cfg;
    nte_config_default(&cfg, 2, nte_schedule_all);
    assert_int_equal(nte_init(NULL, &cfg), nte_err_null_argument);
    assert_int_equal(nte_init(&est, NULL), nte_err_null_argument);
    assert_int_equal(nte_config_check(NULL), nte_err_null_argument);
    assert_int_equal(nte_reset(NULL), nte_err_null_argument);
    nte_sample_t s = sample(0, 1, 1, 0);
    assert_int_equal(nte_step(NULL, &s, NULL), nte_err_null_argument);
    assert_int_equal(nte_init(&est, &cfg), nte_err_ok);
    assert_int_equal(nte_step(&est, NULL, NULL), nte_err_null_argument);
    /* the derived f1 excess is accepted when f1 > -f2 */
    cfg.f1_excess = 0;
    assert_int_equal(nte_init(&est, &cfg), nte_err_ok);
    /* a good layer set is accepted (Model III) */
    nte_config_default(&cfg, 3, nte_schedule_all);
    one_layer_set(&cfg);
    assert_int_equal(nte_init(&est, &cfg), nte_err_ok);
}

static void test_profiles_are_valid(void** state)
{
    (void)state;
    static nte_t est;
    for (int32_t model = 1; model <= 2; model++) {
        for (int sch = 0; sch < 2; sch++) {
            nte_config_t cfg;
            nte_config_default(&cfg, model, (nte_schedule_t)sch);
            assert_int_equal(nte_init(&est, &cfg), nte_err_ok);
            nte_config_paper(&cfg, model, (nte_schedule_t)sch);
            assert_int_equal(nte_init(&est, &cfg), nte_err_ok);
        }
    }
}

/* ----------------------------------------------------------------------------------------- */
/* A steady insertion at 10 mm/s, 200 Hz, with a plausible force; returns the next time. */
static int64_t insert(nte_t* est, int64_t t, const int n, double* depth, uint32_t* status_or)
{
    for (int k = 0; k < n; k++) {
        nte_output_t o;
        nte_sample_t s = sample(t, *depth, 10.0, 0.004 * *depth);
        assert_int_equal(nte_step(est, &s, &o), nte_err_ok);
        assert_true(isfinite(o.force_hat_n) && isfinite(o.z) && isfinite(o.innovation_n));
        *status_or |= o.status;
        t += 5000;
        *depth += 0.05;
    }
    return t;
}

static void test_every_status_flag_and_counter(void** state)
{
    (void)state;
    static nte_t est;
    nte_config_t cfg;
    nte_output_t o;
    nte_sample_t s;
    nte_config_default(&cfg, 2, nte_schedule_all);
    assert_int_equal(nte_init(&est, &cfg), nte_err_ok);

    /* INIT and OUT_OF_TISSUE */
    s = sample(0, 0.0, 0.0, 0.0);
    nte_step(&est, &s, &o);
    assert_int_equal(o.status, NTE_STATUS_INIT | NTE_STATUS_OUT_OF_TISSUE);
    double depth = 0.05;
    uint32_t seen = 0;
    int64_t t = insert(&est, 5000, 400, &depth, &seen);
    assert_true((seen & NTE_STATUS_INIT) == 0U);

    /* REJECTED, by each cause: outputs hold, counters count */
    const nte_output_t before = est.last;
    const double bad[3][3] = {
        {(double)NAN, 10, 0.1}, {depth, (double)INFINITY, 0.1}, {depth, 10, -(double)INFINITY}};
    for (int i = 0; i < 3; i++) {
        s = sample(t, bad[i][0], bad[i][1], bad[i][2]);
        nte_step(&est, &s, &o);
        assert_int_equal(o.status, NTE_STATUS_REJECTED);
        assert_memory_equal(&o.force_hat_n, &before.force_hat_n, sizeof o.force_hat_n);
    }
    assert_int_equal(est.counters.rejected[NTE_REJECT_NONFINITE], 3);
    s = sample(t, 600.0, 10, 0.1); /* depth beyond depth_max_mm */
    nte_step(&est, &s, &o);
    s = sample(t, depth, 10, 80.0); /* force beyond force_max_n */
    nte_step(&est, &s, &o);
    s = sample(t, depth, 900.0, 0.1); /* speed beyond speed_max_mm_s */
    nte_step(&est, &s, &o);
    assert_int_equal(est.counters.rejected[NTE_REJECT_RANGE], 3);
    s = sample(t - 5000, depth, 10, 0.1); /* time not increasing */
    nte_step(&est, &s, &o);
    assert_int_equal(o.status, NTE_STATUS_REJECTED);
    assert_int_equal(est.counters.rejected[NTE_REJECT_TIME], 1);

    /* GATED: a 10 N spike */
    s = sample(t, depth, 10, 10.0);
    nte_step(&est, &s, &o);
    assert_true(o.status & NTE_STATUS_GATED);
    assert_true(est.counters.gated >= 1U);
    t += 5000;
    depth += 0.05;

    /* GAP: one second without samples */
    t += 1000000;
    s = sample(t, depth, 10, 0.004 * depth);
    nte_step(&est, &s, &o);
    assert_true(o.status & NTE_STATUS_GAP);
    assert_int_equal(est.counters.gaps, 1);
    t += 5000;

    /* SIGN_UNCERTAIN: moving slowly inside the tissue, |s| well below 1 */
    seen = 0;
    for (int k = 0; k < 20; k++) {
        s = sample(t, depth, 0.3, 0.004 * depth);
        nte_step(&est, &s, &o);
        seen |= o.status;
        t += 5000;
    }
    assert_true(seen & NTE_STATUS_SIGN_UNCERTAIN);

    /* FILTER_RESET: a covariance made non-finite (white-box) is detected and repaired */
    est.P[1][0][0] = (nte_real_t)NAN;
    s = sample(t, depth, 10, 0.004 * depth);
    nte_step(&est, &s, &o);
    assert_true(o.status & NTE_STATUS_FILTER_RESET);
    assert_int_equal(est.counters.filter_resets, 1);
    assert_true(isfinite(o.force_hat_n));
    t += 5000;

    /* CLIPPED and FLOORED: a tight clip and a high variance floor */
    nte_config_default(&cfg, 2, nte_schedule_all);
    cfg.u_max = (nte_real_t)1e-3;
    cfg.var_floor_u = (nte_real_t)0.5;
    assert_int_equal(nte_init(&est, &cfg), nte_err_ok);
    depth = 0.05;
    seen = 0;
    (void)insert(&est, 0, 200, &depth, &seen);
    assert_true(seen & NTE_STATUS_CLIPPED);
    assert_true(seen & NTE_STATUS_FLOORED);

    /* nte_reset clears counters and starts over */
    assert_int_equal(nte_reset(&est), nte_err_ok);
    assert_int_equal(est.counters.gated + est.counters.gaps + est.counters.filter_resets, 0);
    s = sample(0, 1.0, 10, 0.01);
    nte_step(&est, &s, &o);
    assert_true(o.status & NTE_STATUS_INIT);
}

/* ----------------------------------------------------------------------------------------- */
static void params_now(const nte_t* est, nte_param_estimate_t* p, size_t* n)
{
    *n = nte_get_params(est, p, NTE_IDENTIFIED_MAX);
}

static int filter_of(const int32_t model, const nte_param_id_t id)
{
    /* Table I */
    if (model == 1) {
        return (id == nte_param_f2 || id == nte_param_sigma0)   ? 0
               : (id == nte_param_f1 || id == nte_param_sigma1) ? 1
                                                                : 2;
    }
    return (id == nte_param_sigma0) ? 0 : (id == nte_param_f1 || id == nte_param_sigma1) ? 1 : 2;
}

static void test_every_filter_under_both_schedules(void** state)
{
    (void)state;
    static nte_t est;
    static const nte_param_id_t m1[] = {nte_param_sigma0, nte_param_sigma1, nte_param_sigma2,
                                        nte_param_f1,     nte_param_f2,     nte_param_alpha};
    static const nte_param_id_t m2[] = {nte_param_sigma0, nte_param_sigma1, nte_param_sigma2,
                                        nte_param_f1, nte_param_beta};
    for (int32_t model = 1; model <= 2; model++) {
        for (int sch = 0; sch < 2; sch++) {
            nte_config_t cfg;
            nte_config_default(&cfg, model, (nte_schedule_t)sch);
            assert_int_equal(nte_init(&est, &cfg), nte_err_ok);
            nte_param_estimate_t p0[NTE_IDENTIFIED_MAX];
            nte_param_estimate_t p1[NTE_IDENTIFIED_MAX];
            size_t n = 0;
            params_now(&est, p0, &n);
            assert_int_equal(n, (model == 1) ? 6 : 5);
            for (size_t j = 0; j < n; j++) {
                assert_int_equal(p0[j].id, (model == 1) ? m1[j] : m2[j]);
                assert_true(!(p0[j].value < 0) && !(p0[j].value > 0) && !(p0[j].sd > 0));
            }
            assert_int_equal(nte_get_params(&est, p0, 2), n); /* capacity respected */
            double depth = 5.0;
            uint32_t seen = 0;
            int64_t t = insert(&est, 0, 100, &depth, &seen);
            params_now(&est, p0, &n);
            for (int k = 0; k < 6; k++) {
                /* which filter updates at this sample: all (schedule all) or k mod 3 */
                const int active = (int)est.k_mod3;
                nte_output_t o;
                nte_sample_t s = sample(t, depth, 10.0, 0.004 * depth + 0.02);
                nte_step(&est, &s, &o);
                params_now(&est, p1, &n);
                for (size_t j = 0; j < n; j++) {
                    const int f = filter_of(model, p1[j].id);
                    const int moved = memcmp(&p0[j].value, &p1[j].value, sizeof(nte_real_t)) != 0;
                    const int f1_follows_f2 = (model == 1) && (p1[j].id == nte_param_f1) &&
                                              ((sch == 0) || (active == 0));
                    if ((sch == 0) || (f == active) || f1_follows_f2) {
                        assert_true(moved);
                    } else {
                        assert_false(moved);
                    }
                    assert_true(isfinite(p1[j].sd) && p1[j].sd > 0);
                }
                memcpy(p0, p1, sizeof p0);
                t += 5000;
                depth += 0.05;
            }
        }
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_every_error_code_leaves_instance_untouched),
        cmocka_unit_test(test_profiles_are_valid),
        cmocka_unit_test(test_every_status_flag_and_counter),
        cmocka_unit_test(test_every_filter_under_both_schedules),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
