/*
 * The contact front end through the public API (black box): its configuration checks (every
 * field at and beyond its range), a synthetic record that starts 5 mm before the stage's zero
 * and enters the tissue twice (no sample rejected, each surface found, the air fed to the bank
 * as depth 0), a known surface, and the zeros published when it is off.  The front end on
 * phantom records, and its bit identity with the reference, are in
 * tests/python/test_contact.py.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "nte.h"

/* a == b without -Wfloat-equal's objection (NaN is equal to nothing) */
static bool same(const nte_real_t a, const nte_real_t b)
{
    return !(a < b) && !(a > b) && !isnan(a) && !isnan(b);
}

/* ----------------------------------------------------------------------------------------- */
/* Configuration: each case changes one field of an enabled default front end. */
typedef struct cfg_case_t {
    const char* what;
    void (*apply)(nte_contact_config_t* c);
    nte_err_t want;
} cfg_case_t;

static void k_zero(nte_contact_config_t* c) { c->k_sigma = (nte_real_t)0.0; }
static void k_max(nte_contact_config_t* c) { c->k_sigma = (nte_real_t)100.0; }
static void k_over(nte_contact_config_t* c) { c->k_sigma = (nte_real_t)100.5; }
static void k_nan(nte_contact_config_t* c) { c->k_sigma = (nte_real_t)NAN; }
static void floor_zero(nte_contact_config_t* c) { c->floor_n = (nte_real_t)0.0; }
static void floor_neg(nte_contact_config_t* c) { c->floor_n = (nte_real_t)-0.001; }
static void floor_over(nte_contact_config_t* c) { c->floor_n = (nte_real_t)50.5; }
static void run_zero(nte_contact_config_t* c) { c->run_samples = 0; }
static void run_max(nte_contact_config_t* c) { c->run_samples = 1000; }
static void run_over(nte_contact_config_t* c) { c->run_samples = 1001; }
static void tare_over(nte_contact_config_t* c) { c->tare_samples = 100001; }
static void learn_zero(nte_contact_config_t* c) { c->learn_samples = 0; }
static void learn_tare(nte_contact_config_t* c) { c->learn_samples = c->tare_samples; }
static void learn_over(nte_contact_config_t* c) { c->learn_samples = c->tare_samples + 1; }
static void gate_inf(nte_contact_config_t* c) { c->learn_gate_sigma = (nte_real_t)INFINITY; }
static void drift_neg(nte_contact_config_t* c) { c->cusum_drift_sigma = (nte_real_t)-0.5; }
static void surf_ok(nte_contact_config_t* c) { c->surface_mm = (nte_real_t)-500.0; }
static void surf_over(nte_contact_config_t* c) { c->surface_mm = (nte_real_t)500.5; }
static void surf_inf(nte_contact_config_t* c) { c->surface_mm = (nte_real_t)-INFINITY; }

static void test_config_checks(void** state)
{
    (void)state;
    static const cfg_case_t cases[] = {
        {"k_sigma 0", k_zero, nte_err_bad_contact},
        {"k_sigma 100", k_max, nte_err_ok},
        {"k_sigma 100.5", k_over, nte_err_bad_contact},
        {"k_sigma NaN", k_nan, nte_err_bad_contact},
        {"floor_n 0", floor_zero, nte_err_ok},
        {"floor_n < 0", floor_neg, nte_err_bad_contact},
        {"floor_n 50.5", floor_over, nte_err_bad_contact},
        {"run_samples 0", run_zero, nte_err_bad_contact},
        {"run_samples 1000", run_max, nte_err_ok},
        {"run_samples 1001", run_over, nte_err_bad_contact},
        {"tare_samples 100001", tare_over, nte_err_bad_contact},
        {"learn_samples 0", learn_zero, nte_err_bad_contact},
        {"learn_samples = tare_samples", learn_tare, nte_err_ok},
        {"learn_samples > tare_samples", learn_over, nte_err_bad_contact},
        {"learn_gate_sigma inf", gate_inf, nte_err_bad_contact},
        {"cusum_drift_sigma < 0", drift_neg, nte_err_bad_contact},
        {"surface_mm -500", surf_ok, nte_err_ok},
        {"surface_mm 500.5", surf_over, nte_err_bad_contact},
        {"surface_mm -inf", surf_inf, nte_err_bad_contact},
    };
    for (size_t i = 0U; i < (sizeof cases / sizeof cases[0]); i++) {
        nte_config_t cfg;
        nte_config_default(&cfg, 2, nte_schedule_all);
        cfg.contact.enabled = true;
        cases[i].apply(&cfg.contact);
        if (nte_config_check(&cfg) != cases[i].want) {
            fail_msg("%s: got %d, want %d", cases[i].what, (int)nte_config_check(&cfg),
                     (int)cases[i].want);
        }
        /* off, its fields are not looked at */
        cfg.contact.enabled = false;
        assert_int_equal(nte_config_check(&cfg), nte_err_ok);
    }
    /* the defaults: off, the surface found from the force (NaN) */
    nte_config_t cfg;
    nte_config_default(&cfg, 1, nte_schedule_all);
    assert_false(cfg.contact.enabled);
    assert_true(isnan(cfg.contact.surface_mm));
    cfg.contact.enabled = true;
    assert_int_equal(nte_config_check(&cfg), nte_err_ok);
}

/* ----------------------------------------------------------------------------------------- */
/* A synthetic record: the stage from -5 mm inward at 2 mm/s to 20 mm, back to -5 mm, twice;
 * the tissue surface at stage 6 mm; force = tare + 0.3 N/mm (stage - 6) in the tissue (also
 * while retracting: the tissue pushes until the tip leaves), plus a deterministic +-10 mN
 * ripple; 100 Hz. */
#define RATE_HZ 100.0
#define SURFACE 6.0
#define TARE (-0.012)

static double stage_at(const int k, double* v)
{
    const int leg = (int)(25.0 / 2.0 * RATE_HZ); /* samples per leg */
    const int rest = 100;
    const int cycle = rest + (2 * leg);
    const int j = k % cycle;
    if (j < rest) {
        *v = 0.0;
        return -5.0;
    }
    if (j < (rest + leg)) {
        *v = 2.0;
        return -5.0 + ((double)(j - rest) * 2.0 / RATE_HZ);
    }
    *v = -2.0;
    return 20.0 - ((double)(j - rest - leg) * 2.0 / RATE_HZ);
}

static double force_at(const int k, const double x)
{
    const double ripple = 0.01 * (double)((k * 7) % 5 - 2) / 2.0;
    return TARE + ripple + ((x > SURFACE) ? (0.3 * (x - SURFACE)) : 0.0);
}

static void run_record(nte_t* est, const int n, int* contacts, double* surfaces, double* tare,
                       uint32_t* air_in_tissue_status)
{
    nte_contact_state_t prev = nte_contact_air;
    *contacts = 0;
    *air_in_tissue_status = 0U;
    for (int k = 0; k < n; k++) {
        double v = 0.0;
        const double x = stage_at(k, &v);
        nte_sample_t s;
        s.t_us = (int64_t)k * 10000;
        s.depth_mm = (nte_real_t)x;
        s.velocity_mm_s = (nte_real_t)v;
        s.force_n = (nte_real_t)force_at(k, x);
        nte_output_t o;
        assert_int_equal(nte_step(est, &s, &o), nte_err_ok);
        if ((o.contact == nte_contact_tissue) && (prev == nte_contact_air) && (*contacts < 2)) {
            surfaces[*contacts] = (double)o.surface_mm;
            tare[*contacts] = (double)o.tare_n;
            (*contacts)++;
        }
        /* in the air the bank sees depth 0: the sample is out of tissue */
        if ((o.contact == nte_contact_air) && ((o.status & NTE_STATUS_OUT_OF_TISSUE) == 0U)) {
            (*air_in_tissue_status)++;
        }
        prev = o.contact;
    }
}

static void test_two_insertions_from_the_air(void** state)
{
    (void)state;
    nte_config_t cfg;
    nte_config_default(&cfg, 2, nte_schedule_all);
    cfg.contact.enabled = true;
    static nte_t est;
    assert_int_equal(nte_init(&est, &cfg), nte_err_ok);
    int contacts = 0;
    double surfaces[2] = {0.0, 0.0};
    double tare[2] = {0.0, 0.0};
    uint32_t air_in_tissue = 0U;
    run_record(&est, 2 * (100 + 2 * 1250), &contacts, surfaces, tare, &air_in_tissue);
    assert_int_equal(contacts, 2);
    for (int i = 0; i < 2; i++) {
        assert_true(fabs(surfaces[i] - SURFACE) <= 0.5);
        assert_true(fabs(tare[i] - TARE) <= 0.005);
    }
    assert_int_equal(air_in_tissue, 0U);
    for (int c = 0; c < NTE_REJECT_CAUSES; c++) {
        assert_int_equal(est.counters.rejected[c], 0U); /* -5 mm of stage is no error */
    }
    /* without the front end the negative stage positions are rejected */
    cfg.contact.enabled = false;
    assert_int_equal(nte_init(&est, &cfg), nte_err_ok);
    run_record(&est, 100 + 2 * 1250, &contacts, surfaces, tare, &air_in_tissue);
    assert_int_equal(contacts, 0);
    assert_true(est.counters.rejected[NTE_REJECT_RANGE] > 0U);
}

static void test_known_surface(void** state)
{
    (void)state;
    nte_config_t cfg;
    nte_config_default(&cfg, 2, nte_schedule_all);
    cfg.contact.enabled = true;
    cfg.contact.surface_mm = (nte_real_t)4.0;
    static nte_t est;
    assert_int_equal(nte_init(&est, &cfg), nte_err_ok);
    const double xs[] = {-2.0, 3.0, 4.5, 9.0, 3.9};
    const nte_contact_state_t want[] = {nte_contact_air, nte_contact_air, nte_contact_tissue,
                                        nte_contact_tissue, nte_contact_air};
    for (size_t k = 0U; k < (sizeof xs / sizeof xs[0]); k++) {
        const nte_sample_t s = {(int64_t)k * 10000, (nte_real_t)xs[k], (nte_real_t)1.0,
                                (nte_real_t)0.01};
        nte_output_t o;
        assert_int_equal(nte_step(&est, &s, &o), nte_err_ok);
        assert_int_equal(o.contact, want[k]);
        if (k >= 2U) {
            assert_true(same(o.surface_mm, (nte_real_t)4.0));
        } else {
            assert_true(isnan(o.surface_mm)); /* not touched yet */
        }
    }
}

static void test_off_publishes_zeros(void** state)
{
    (void)state;
    nte_config_t cfg;
    nte_config_default(&cfg, 1, nte_schedule_rotate);
    static nte_t est;
    assert_int_equal(nte_init(&est, &cfg), nte_err_ok);
    const nte_sample_t s = {0, (nte_real_t)1.0, (nte_real_t)1.0, (nte_real_t)0.1};
    nte_output_t o;
    assert_int_equal(nte_step(&est, &s, &o), nte_err_ok);
    assert_true(same(o.surface_mm, (nte_real_t)0.0) && same(o.tare_n, (nte_real_t)0.0));
    assert_int_equal(o.contact, nte_contact_air);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_config_checks),
        cmocka_unit_test(test_two_insertions_from_the_air),
        cmocka_unit_test(test_known_surface),
        cmocka_unit_test(test_off_publishes_zeros),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
