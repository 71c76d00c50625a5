/*
 * Fault injection on the paper scenario tests/data/c_scenarios/p10_d50.csv (Model II, both
 * schedules): NaN, +-inf, huge values, negative dt and a 10 s gap, each injected at t = 3 s
 * (mid-insertion).  Each case asserts its counters and flags, finite outputs on every sample,
 * and recovery: 2 s after the fault the mean absolute error against the noise-free force is
 * back within 1.5x the clean run's error over the same window + 1 mN.
 * The reversal at full speed (+10 -> -10 mm/s between two samples at 30 mm) is a scenario of
 * its own, tests/data/c_faults/reversal.csv (simulated by tests/python/c_twin.py reversal):
 * no sample is rejected, outputs stay finite, and 2 s after the reversal the error is back
 * within 1.5x the error of the 0.5 s before it + 1 mN.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "nte.h"

#define MAX_N 4000
#define FAULT_K 600 /* t = 3.0 s */
#define WINDOW 100  /* 0.5 s at 200 Hz */

static int n_rows;
static double t_s[MAX_N], depth[MAX_N], vel[MAX_N], force[MAX_N], truth[MAX_N];

/* Rows of t_s,depth_mm,velocity_mm_s,force_n,force_true_n; comment and header lines skipped. */
static int load_file(const char* path)
{
    FILE* fh = fopen(path, "r");
    if (fh == NULL) {
        return -1;
    }
    char line[512];
    n_rows = 0;
    while ((n_rows < MAX_N) && (fgets(line, sizeof line, fh) != NULL)) {
        if (sscanf(line, "%lf,%lf,%lf,%lf,%lf", &t_s[n_rows], &depth[n_rows], &vel[n_rows],
                   &force[n_rows], &truth[n_rows]) == 5) {
            n_rows++;
        }
    }
    (void)fclose(fh);
    return (n_rows > FAULT_K + 600) ? 0 : -1;
}

static int load(void** state)
{
    (void)state;
    return load_file(NTE_TEST_DATA "/c_scenarios/p10_d50.csv");
}

typedef enum fault_t {
    fault_none,
    fault_nan,
    fault_inf,
    fault_huge,
    fault_negative_dt,
    fault_gap
} fault_t;

typedef struct result_t {
    double err[MAX_N]; /* |force_hat - truth| */
    uint32_t status[MAX_N];
    nte_counters_t counters;
    int all_finite;
} result_t;

static void run(const fault_t fault, const nte_schedule_t sch, result_t* r)
{
    static nte_t est;
    nte_config_t cfg;
    nte_config_default(&cfg, 2, sch);
    assert_int_equal(nte_init(&est, &cfg), nte_err_ok);
    r->all_finite = 1;
    for (int k = 0; k < n_rows; k++) {
        double t = t_s[k];
        double l = depth[k];
        double v = vel[k];
        double f = force[k];
        if (fault == fault_gap && k >= FAULT_K) {
            t += 10.0;
        }
        if (k == FAULT_K) {
            switch (fault) {
            case fault_nan: f = (double)NAN; break;
            case fault_inf: l = (double)INFINITY; break;
            case fault_huge: f = 1e30; break;
            case fault_negative_dt: t = t_s[k - 1] - 0.5; break;
            default: break;
            }
        }
        if (fault == fault_inf && k == FAULT_K + 1) {
            v = -(double)INFINITY;
        }
        if (fault == fault_huge && k == FAULT_K + 1) {
            f = 40.0; /* in range, absurd: gated */
        }
        nte_sample_t s;
        nte_output_t o;
        s.t_us = (int64_t)floor(t * 1e6 + 0.5);
        s.depth_mm = (nte_real_t)l;
        s.velocity_mm_s = (nte_real_t)v;
        s.force_n = (nte_real_t)f;
        nte_step(&est, &s, &o);
        r->status[k] = o.status;
        r->err[k] = fabs((double)o.force_hat_n - truth[k]);
        nte_param_estimate_t p[NTE_IDENTIFIED_MAX];
        const size_t np = nte_get_params(&est, p, NTE_IDENTIFIED_MAX);
        int fin = isfinite(o.force_hat_n) && isfinite(o.z) && isfinite(o.innovation_n) &&
                  isfinite(o.nis);
        for (size_t j = 0; j < np; j++) {
            fin = fin && isfinite(p[j].value) && isfinite(p[j].sd);
        }
        r->all_finite = r->all_finite && fin;
    }
    r->counters = est.counters;
}

static double mean_err(const result_t* r, const int from)
{
    double s = 0.0;
    for (int k = from; k < from + WINDOW; k++) {
        s += r->err[k];
    }
    return s / WINDOW;
}

static result_t clean;
static result_t faulty;

static void check_fault(const fault_t fault, const int fault_len)
{
    for (int sch = 0; sch < 2; sch++) {
        run(fault_none, (nte_schedule_t)sch, &clean);
        run(fault, (nte_schedule_t)sch, &faulty);
        assert_true(faulty.all_finite);
        const int after = FAULT_K + fault_len + 400; /* 2 s after the fault ends */
        const double e_clean = mean_err(&clean, after);
        const double e_fault = mean_err(&faulty, after);
        const double e_before = mean_err(&clean, FAULT_K - WINDOW);
        print_message("fault %d schedule %d: error before %.3g mN, 2 s after %.3g mN "
                      "(clean run %.3g mN)\n",
                      (int)fault, sch, e_before * 1e3, e_fault * 1e3, e_clean * 1e3);
        assert_true(e_fault <= (1.5 * e_clean) + 1e-3);
    }
}

static void test_nan(void** state)
{
    (void)state;
    check_fault(fault_nan, 1);
    assert_true(faulty.status[FAULT_K] == NTE_STATUS_REJECTED);
    assert_int_equal(faulty.counters.rejected[NTE_REJECT_NONFINITE], 1);
    assert_int_equal(faulty.counters.rejected[NTE_REJECT_RANGE], 0);
}

static void test_infinities(void** state)
{
    (void)state;
    check_fault(fault_inf, 2);
    assert_true(faulty.status[FAULT_K] == NTE_STATUS_REJECTED);
    assert_true(faulty.status[FAULT_K + 1] == NTE_STATUS_REJECTED);
    assert_int_equal(faulty.counters.rejected[NTE_REJECT_NONFINITE], 2);
}

static void test_huge_values(void** state)
{
    (void)state;
    check_fault(fault_huge, 2);
    assert_true(faulty.status[FAULT_K] == NTE_STATUS_REJECTED);
    assert_int_equal(faulty.counters.rejected[NTE_REJECT_RANGE], 1);
    assert_true(faulty.status[FAULT_K + 1] & NTE_STATUS_GATED);
    assert_true(faulty.counters.gated >= 1U);
}

static void test_negative_dt(void** state)
{
    (void)state;
    check_fault(fault_negative_dt, 1);
    assert_true(faulty.status[FAULT_K] == NTE_STATUS_REJECTED);
    assert_int_equal(faulty.counters.rejected[NTE_REJECT_TIME], 1);
}

static void test_ten_second_gap(void** state)
{
    (void)state;
    check_fault(fault_gap, 1);
    assert_true(faulty.status[FAULT_K] & NTE_STATUS_GAP);
    assert_int_equal(faulty.counters.gaps, 1);
    assert_int_equal(clean.counters.gaps, 0);
}

static void test_reversal_at_full_speed(void** state)
{
    (void)state;
    assert_int_equal(load_file(NTE_TEST_DATA "/c_faults/reversal.csv"), 0);
    for (int sch = 0; sch < 2; sch++) {
        run(fault_none, (nte_schedule_t)sch, &faulty);
        assert_true(faulty.all_finite);
        assert_int_equal(faulty.counters.rejected[0] + faulty.counters.rejected[1] +
                             faulty.counters.rejected[2],
                         0);
        const double e_before = mean_err(&faulty, FAULT_K - WINDOW);
        const double e_after = mean_err(&faulty, FAULT_K + 400);
        print_message("reversal schedule %d: error before %.3g mN, 2 s after %.3g mN\n", sch,
                      e_before * 1e3, e_after * 1e3);
        assert_true(e_after <= (1.5 * e_before) + 1e-3);
    }
    assert_int_equal(load_file(NTE_TEST_DATA "/c_scenarios/p10_d50.csv"), 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_nan),
        cmocka_unit_test(test_infinities),
        cmocka_unit_test(test_huge_values),
        cmocka_unit_test(test_negative_dt),
        cmocka_unit_test(test_ten_second_gap),
        cmocka_unit_test(test_reversal_at_full_speed),
    };
    return cmocka_run_group_tests(tests, load, NULL);
}
