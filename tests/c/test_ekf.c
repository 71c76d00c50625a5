/*
 * The EKF kernels' contracts that the bank's replay files cannot show (white-box: uses the
 * library's internal header): the covariance check refuses a matrix with a non-finite entry
 * wherever it sits and accepts huge finite ones; the Joseph update writes its posterior to
 * P_out only when it applies, leaves the prior alone, gives the same bits whether P_out is P
 * or another matrix, and refuses a state count outside the bank's 2..4.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "nte_ekf.h"

/* a symmetric positive definite n x n matrix: diagonal 2 + i, off-diagonal 0.25 */
static void spd(const size_t n, nte_mat3_t P)
{
    memset(P, 0, sizeof(nte_mat3_t));
    for (size_t i = 0U; i < n; i++) {
        for (size_t j = 0U; j < n; j++) {
            P[i][j] = (i == j) ? (nte_real_t)(2.0 + (double)i) : (nte_real_t)0.25;
        }
    }
}

static void test_covariance_check_refuses_every_non_finite_entry(void** state)
{
    (void)state;
    const nte_real_t bad[3] = {(nte_real_t)NAN, (nte_real_t)INFINITY, (nte_real_t)-INFINITY};
    for (size_t n = 2U; n <= NTE_EKF_N_MAX; n++) {
        nte_mat3_t P;
        spd(n, P);
        assert_true(nte_ekf_positive_definite(n, P));
        for (size_t i = 0U; i < n; i++) {
            for (size_t j = i; j < n; j++) {
                for (size_t b = 0U; b < 3U; b++) {
                    spd(n, P);
                    P[i][j] = bad[b];
                    P[j][i] = bad[b];
                    if (nte_ekf_positive_definite(n, P)) {
                        fail_msg("n %zu: entry (%zu, %zu) = %g accepted", n, i, j, (double)bad[b]);
                    }
                }
            }
        }
        /* entries beyond n are not the matrix's */
        spd(n, P);
        if (n < NTE_EKF_N_MAX) {
            P[n][n] = (nte_real_t)NAN;
        }
        assert_true(nte_ekf_positive_definite(n, P));
        /* huge but finite: entry times 0 is still 0 */
        spd(n, P);
        P[n - 1U][n - 1U] = (nte_real_t)1e30;
        assert_true(nte_ekf_positive_definite(n, P));
    }
}

static nte_ekf_update_t update(const size_t n, nte_real_t* x, nte_mat3_t P, nte_mat3_t P_out,
                               const nte_real_t innovation, const bool apply)
{
    const nte_real_t h[NTE_EKF_N_MAX] = {(nte_real_t)0.5, (nte_real_t)-0.25, (nte_real_t)0.125,
                                         (nte_real_t)0.75};
    return nte_ekf_joseph_update(n, x, P, P_out, h, innovation, (nte_real_t)0.01, (nte_real_t)144.0,
                                 false, apply, (nte_real_t)0.0, false);
}

static void test_joseph_writes_the_posterior_only_when_it_applies(void** state)
{
    (void)state;
    for (size_t n = 2U; n <= NTE_EKF_N_MAX; n++) {
        nte_mat3_t prior;
        nte_mat3_t P;
        nte_mat3_t out;
        nte_mat3_t in_place;
        nte_real_t x[NTE_EKF_N_MAX] = {0};
        nte_real_t x2[NTE_EKF_N_MAX] = {0};
        spd(n, prior);
        spd(n, P);
        memset(out, 0x5a, sizeof out);
        const nte_ekf_update_t u = update(n, x, P, out, (nte_real_t)0.3, true);
        assert_true(u.accepted);
        assert_memory_equal(P, prior, sizeof P); /* the prior is read only */
        /* the posterior: symmetric, smaller variances, the same bits as in place */
        spd(n, in_place);
        (void)update(n, x2, in_place, in_place, (nte_real_t)0.3, true);
        for (size_t i = 0U; i < n; i++) {
            assert_true(out[i][i] < prior[i][i]);
            assert_memory_equal(&x[i], &x2[i], sizeof x[i]);
            for (size_t j = 0U; j < n; j++) {
                assert_memory_equal(&out[i][j], &out[j][i], sizeof out[i][j]);
                assert_memory_equal(&out[i][j], &in_place[i][j], sizeof out[i][j]);
            }
        }
        /* not applied (an idle filter) or refused by the gate: P_out untouched, x too */
        nte_mat3_t untouched;
        memset(untouched, 0x5a, sizeof untouched);
        memset(out, 0x5a, sizeof out);
        nte_real_t x0[NTE_EKF_N_MAX] = {0};
        (void)update(n, x0, P, out, (nte_real_t)0.3, false);
        assert_memory_equal(out, untouched, sizeof out);
        const nte_ekf_update_t gated = update(n, x0, P, out, (nte_real_t)1e3, true);
        assert_false(gated.accepted);
        assert_memory_equal(out, untouched, sizeof out);
        const nte_real_t zeros[NTE_EKF_N_MAX] = {0};
        assert_memory_equal(x0, zeros, sizeof x0);
    }
}

static void test_joseph_refuses_a_state_count_outside_the_bank(void** state)
{
    (void)state;
    const size_t counts[3] = {0U, 1U, NTE_EKF_N_MAX + 1U};
    for (size_t c = 0U; c < 3U; c++) {
        nte_mat3_t P;
        nte_mat3_t out;
        spd(NTE_EKF_N_MAX, P);
        memcpy(out, P, sizeof out);
        nte_real_t x[NTE_EKF_N_MAX + 1U] = {0};
        const nte_ekf_update_t u = update(counts[c], x, P, out, (nte_real_t)0.3, true);
        assert_false(u.accepted);
        assert_true(isnan(u.s) && isnan(u.nis));
        assert_memory_equal(out, P, sizeof out);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_covariance_check_refuses_every_non_finite_entry),
        cmocka_unit_test(test_joseph_writes_the_posterior_only_when_it_applies),
        cmocka_unit_test(test_joseph_refuses_a_state_count_outside_the_bank),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
