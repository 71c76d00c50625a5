/*
 * Model, exp/tanh and RK3 against reference vectors (bit for bit), and the hand-derived
 * Jacobians (reference_py/JACOBIANS.md) against finite differences.  White-box: uses the
 * library's internal model header.
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "nte_model.h"
#include "model_vectors.h"

/* the seven force-model parameters (Models I and II); the model functions know nothing of
 * Model III's relaxation strengths, which follow them in nte_param_id_t */
#define NP 7

#define NOMINAL_F1 5.59e-2
#define NOMINAL_F2 -2.11e-2

static const double nominal_d[NP] = {7.9e-3, 2.46, 4.14e-3, 5.59e-2, -2.11e-2, 5.25e-2, 2.55e-2};

static int same_bits(const nte_real_t a, const nte_real_t b)
{
    return memcmp(&a, &b, sizeof a) == 0;
}

static void make_theta(nte_theta_t* th, const double* u_d)
{
    nte_real_t nominal[NTE_PARAM_COUNT] = {0};
    nte_real_t u[NTE_PARAM_COUNT] = {0};
    for (int j = 0; j < NP; j++) {
        nominal[j] = (nte_real_t)nominal_d[j];
        u[j] = (nte_real_t)u_d[j];
    }
    const nte_real_t kappa = (nte_real_t)1;
    const nte_real_t ex = (nte_real_t)(NOMINAL_F1 - (1.0 * (-NOMINAL_F2)));
    nte_model_theta(th, nominal, ex, kappa, u);
}

/* Every model quantity in the generator's order. */
static size_t model_row(const mv_point_t* p, nte_real_t* row)
{
    static const uint8_t all[NP] = {0, 1, 2, 3, 4, 5, 6};
    nte_theta_t th;
    make_theta(&th, p->u);
    size_t k = 0;
    for (int j = 0; j < NP; j++) {
        row[k++] = th.v[j];
    }
    row[k++] = th.ex;
    row[k++] = th.mkf2;
    const nte_real_t z = (nte_real_t)p->z;
    nte_depth_terms_t d;
    nte_output_terms_t o;
    nte_model_depth_terms(&d, &th, nte_model_clamp_depth((nte_real_t)p->l));
    const nte_real_t s = nte_model_smooth_sign((nte_real_t)p->v, (nte_real_t)MV_EPS);
    nte_model_output(&o, &th, &d, z, s);
    row[k++] = d.e;
    row[k++] = d.g;
    row[k++] = d.inv_g;
    row[k++] = d.b;
    row[k++] = d.dg_dalpha;
    row[k++] = s;
    row[k++] = o.m;
    row[k++] = o.fr;
    row[k++] = o.sl;
    row[k++] = o.h;
    row[k++] = nte_model_output_dz(&th, &d, &o);
    for (uint8_t j = 0; j < NP; j++) {
        row[k++] = nte_model_output_du(&th, &d, z, &o, j);
    }
    row[k++] = nte_model_rate(&th, &d, z);
    row[k++] = nte_model_rate_dz(&d);
    for (uint8_t j = 0; j < NP; j++) {
        bool present = false;
        const nte_real_t r = nte_model_rate_du(&th, &d, z, j, &present);
        row[k++] = present ? r : (nte_real_t)0;
    }
    row[k++] = nte_model_steady_state_z(&th, &d);
    nte_rk3_result_t res;
    const nte_real_t l_a = nte_model_clamp_depth((nte_real_t)p->l);
    const nte_real_t l_b = nte_model_clamp_depth((nte_real_t)p->l_b);
    nte_model_rk3(&res, &th, z, l_a, l_b, (nte_real_t)p->dt, p->substeps, all, NP, NULL);
    /* the same step twice more sharing its stage exponentials, as the bank's filters do: the
     * first fills them, the second reads them; every result has the same bits, and the last
     * stage's depth and exponential are the step's end */
    nte_stage_exps_t stage;
    stage.ready = false;
    nte_rk3_result_t filled;
    nte_rk3_result_t shared;
    nte_model_rk3(&filled, &th, z, l_a, l_b, (nte_real_t)p->dt, p->substeps, all, NP, &stage);
    const int was_ready = stage.ready;
    nte_model_rk3(&shared, &th, z, l_a, l_b, (nte_real_t)p->dt, p->substeps, all, NP, &stage);
    int same = was_ready && same_bits(stage.l_end, res.end.l) &&
               same_bits(stage.e[2 * p->substeps], res.end.e);
    for (int r = 0; r < 2; r++) {
        const nte_rk3_result_t* q = (r == 0) ? &filled : &shared;
        same = same && same_bits(q->z, res.z) && same_bits(q->dz_dz0, res.dz_dz0);
        for (int j = 0; j < NP; j++) {
            same = same && same_bits(q->dz_du[j], res.dz_du[j]);
        }
    }
    if (!same) {
        fail_msg("rk3 with shared stage exponentials differs (l %.9g, substeps %d)", (double)p->l,
                 (int)p->substeps);
    }
    row[k++] = res.z;
    row[k++] = res.dz_dz0;
    for (int j = 0; j < NP; j++) {
        row[k++] = res.dz_du[j];
    }
    return k;
}

static void test_exp_tanh_vectors(void** state)
{
    (void)state;
    for (size_t i = 0; i < MV_N_EXP; i++) {
        const nte_real_t y = nte_exp(mv_exp_in[i]);
        if (!same_bits(y, mv_exp_out[i])) {
            fail_msg("exp(%.9g) = %.17g, reference %.17g", (double)mv_exp_in[i], (double)y,
                     (double)mv_exp_out[i]);
        }
    }
    for (size_t i = 0; i < MV_N_TANH; i++) {
        const nte_real_t y = nte_tanh(mv_tanh_in[i]);
        if (!same_bits(y, mv_tanh_out[i])) {
            fail_msg("tanh(%.9g) = %.17g, reference %.17g", (double)mv_tanh_in[i], (double)y,
                     (double)mv_tanh_out[i]);
        }
    }
}

static void test_model_vectors(void** state)
{
    (void)state;
    for (size_t i = 0; i < MV_N_POINTS; i++) {
        nte_real_t row[MV_N_VALUES + 8];
        memset(row, 0, sizeof row);
        const size_t n = model_row(&mv_points[i], row);
        assert_int_equal(n, MV_N_VALUES);
        for (size_t k = 0; k < n; k++) {
            if (!same_bits(row[k], mv_values[i][k])) {
                fail_msg("point %zu value %zu: C %.17g, reference %.17g", i, k, (double)row[k],
                         (double)mv_values[i][k]);
            }
        }
    }
}

/* ---- Jacobians against central finite differences (double build is the sharp check) ---- */

typedef struct fd_case_t {
    double l;
    double z;
    double v;
} fd_case_t;

static nte_real_t output_at(const double* u, const double l, const double z, const double v)
{
    nte_theta_t th;
    nte_depth_terms_t d;
    nte_output_terms_t o;
    make_theta(&th, u);
    nte_model_depth_terms(&d, &th, (nte_real_t)l);
    nte_model_output(&o, &th, &d, (nte_real_t)z,
                     nte_model_smooth_sign((nte_real_t)v, (nte_real_t)MV_EPS));
    return o.h;
}

static nte_real_t rate_at(const double* u, const double l, const double z)
{
    nte_theta_t th;
    nte_depth_terms_t d;
    make_theta(&th, u);
    nte_model_depth_terms(&d, &th, (nte_real_t)l);
    return nte_model_rate(&th, &d, (nte_real_t)z);
}

static nte_real_t rk3_at(const double* u, const double z)
{
    nte_theta_t th;
    nte_rk3_result_t res;
    make_theta(&th, u);
    nte_model_rk3(&res, &th, (nte_real_t)z, (nte_real_t)10.0, (nte_real_t)10.5, (nte_real_t)0.05, 4,
                  NULL, 0, NULL);
    return res.z;
}

static void check_close(const char* what, const int j, const double analytic, const double fd,
                        const double scale)
{
#if NTE_DOUBLE
    const double tol = 1e-6;
#else
    const double tol = 2e-2;
#endif
    const double err = fabs(analytic - fd);
    if (err > (tol * (fabs(fd) + scale))) {
        fail_msg("%s d/du[%d]: analytic %.9g, finite difference %.9g", what, j, analytic, fd);
    }
}

static void test_jacobians_finite_differences(void** state)
{
    (void)state;
    static const uint8_t all[NP] = {0, 1, 2, 3, 4, 5, 6};
    static const fd_case_t cases[] = {{5.0, 0.3, 10.0}, {20.0, 1.2, -0.4}, {50.0, 2.5, 3.0}};
    static const double u0[NP] = {0.1, -0.2, 0.3, 0.05, -0.1, 0.2, 0.1};
#if NTE_DOUBLE
    const double hstep = 1e-6;
#else
    const double hstep = 2e-2;
#endif
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        const fd_case_t* k = &cases[c];
        nte_theta_t th;
        nte_depth_terms_t d;
        nte_output_terms_t o;
        make_theta(&th, u0);
        nte_model_depth_terms(&d, &th, (nte_real_t)k->l);
        const nte_real_t s = nte_model_smooth_sign((nte_real_t)k->v, (nte_real_t)MV_EPS);
        nte_model_output(&o, &th, &d, (nte_real_t)k->z, s);
        const double hscale = fabs((double)o.h) + 1e-3;
        /* dh/dz and d rate/dz */
        const double fd_hz = ((double)output_at(u0, k->l, k->z + hstep, k->v) -
                              (double)output_at(u0, k->l, k->z - hstep, k->v)) /
                             (2.0 * hstep);
        check_close("h (z)", -1, (double)nte_model_output_dz(&th, &d, &o), fd_hz, hscale);
        const double fd_rz = ((double)rate_at(u0, k->l, k->z + hstep) -
                              (double)rate_at(u0, k->l, k->z - hstep)) /
                             (2.0 * hstep);
        check_close("rate (z)", -1, (double)nte_model_rate_dz(&d), fd_rz, 1e-3);
        for (uint8_t j = 0; j < NP; j++) {
            double up[NP];
            double um[NP];
            memcpy(up, u0, sizeof up);
            memcpy(um, u0, sizeof um);
            up[j] += hstep;
            um[j] -= hstep;
            const double fd_h = ((double)output_at(up, k->l, k->z, k->v) -
                                 (double)output_at(um, k->l, k->z, k->v)) /
                                (2.0 * hstep);
            check_close("h", j, (double)nte_model_output_du(&th, &d, (nte_real_t)k->z, &o, j), fd_h,
                        hscale);
            bool present = false;
            const nte_real_t r = nte_model_rate_du(&th, &d, (nte_real_t)k->z, j, &present);
            const double fd_r =
                ((double)rate_at(up, k->l, k->z) - (double)rate_at(um, k->l, k->z)) / (2.0 * hstep);
            check_close("rate", j, present ? (double)r : 0.0, fd_r,
                        fabs((double)nte_model_rate(&th, &d, (nte_real_t)k->z)) + 1e-3);
        }
    }
    /* the RK3 sensitivities are the derivative of the discrete map */
    const double z0 = 0.8;
    nte_theta_t th;
    nte_rk3_result_t res;
    make_theta(&th, u0);
    nte_model_rk3(&res, &th, (nte_real_t)z0, (nte_real_t)10.0, (nte_real_t)10.5, (nte_real_t)0.05,
                  4, all, NP, NULL);
    const double fd_z = ((double)rk3_at(u0, z0 + hstep) - (double)rk3_at(u0, z0 - hstep)) /
                        (2.0 * hstep);
    check_close("rk3 (z0)", -1, (double)res.dz_dz0, fd_z, 1.0);
    for (int j = 0; j < NP; j++) {
        double up[NP];
        double um[NP];
        memcpy(up, u0, sizeof up);
        memcpy(um, u0, sizeof um);
        up[j] += hstep;
        um[j] -= hstep;
        const double fd = ((double)rk3_at(up, z0) - (double)rk3_at(um, z0)) / (2.0 * hstep);
        check_close("rk3", j, (double)res.dz_du[j], fd, 1e-2);
    }
}

/* nte_real_from_i64 = the cast, bit for bit: around every power of two from 2^24 to 2^62
 * (where ties first occur), the ties themselves, both signs and the int64 extremes. */
static void test_real_from_i64_is_the_cast(void** state)
{
    (void)state;
    size_t checked = 0U;
    for (int p = 20; p < 63; p++) {
        const int64_t base = (int64_t)1 << p;
        const int64_t unit = (p > 24) ? ((int64_t)1 << (p - 24)) : 1; /* the float's step */
        for (int64_t k = -3; k <= 3; k++) {
            for (int64_t d = -2; d <= 2; d++) {
                /* values near base, near base + k units, and exact half-units (ties) */
                const int64_t x = base + (k * unit) + ((d * unit) / 2) + ((d == 2) ? 1 : 0);
                const int64_t xs[2] = {x, -x};
                for (size_t j = 0U; j < 2U; j++) {
                    const nte_real_t a = nte_real_from_i64(xs[j]);
                    const nte_real_t b = (nte_real_t)xs[j];
                    assert_memory_equal(&a, &b, sizeof a);
                    checked++;
                }
            }
        }
    }
    const int64_t ends[4] = {INT64_MAX, INT64_MIN, (int64_t)INT32_MAX + 1, (int64_t)INT32_MIN - 1};
    for (size_t j = 0U; j < 4U; j++) {
        const nte_real_t a = nte_real_from_i64(ends[j]);
        const nte_real_t b = (nte_real_t)ends[j];
        assert_memory_equal(&a, &b, sizeof a);
    }
    assert_true(checked > 2000U);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_exp_tanh_vectors),
        cmocka_unit_test(test_real_from_i64_is_the_cast),
        cmocka_unit_test(test_model_vectors),
        cmocka_unit_test(test_jacobians_finite_differences),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
