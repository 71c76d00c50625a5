/*
 * The export's fit.  Twin: reference_py/tools/export_refine.py (the derivation and the rules
 * are written there; every loop here runs in the same order).
 */
#include "export_refine.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define P_MAX NTE_EXPORT_ROW_MAX

/* export_refine.readable: the row kept where a reader accepts it (n_sets layer sets at its
 * end, each with its own f1) */
static void readable(double* row, size_t row_len, size_t n_sets)
{
    const size_t end = row_len - (NTE_LAYER_SET_VALUES * n_sets); /* the strengths end here */
    double total = 0.0;
    for (size_t j = 0U; j < row_len; j++) {
        if ((j >= 7U) && (j < end)) {
            row[j] = fmin(row[j], NTE_REFINE_STRENGTH_MAX);
            total = total + row[j];
        } else {
            row[j] = fmax(fmin(row[j], NTE_REFINE_PARAM_MAX), -NTE_REFINE_PARAM_MAX);
        }
    }
    if (total > NTE_REFINE_STRENGTH_MAX) {
        const double scale = NTE_REFINE_STRENGTH_MAX / total;
        for (size_t j = 7U; j < end; j++) {
            row[j] = row[j] * scale;
        }
    }
    const size_t f2 = (size_t)nte_param_f2;
    for (size_t k = 0U; k <= n_sets; k++) {
        const size_t f1 = (k == 0U) ? (size_t)nte_param_f1
                                    : (end + ((k - 1U) * NTE_LAYER_SET_VALUES) + nte_layer_f1);
        if ((row[f2] < 0.0) && !((row[f1] + row[f2]) > 0.0)) {
            row[f1] = -row[f2] * NTE_REFINE_G0_MARGIN;
        }
    }
}

static bool same_row(const double* a, const double* b, size_t n)
{
    for (size_t j = 0U; j < n; j++) {
        /* Python's == on floats: NaN equals nothing, -0.0 equals 0.0 */
        if (isnan(a[j]) || isnan(b[j]) || (a[j] < b[j]) || (a[j] > b[j])) {
            return false;
        }
    }
    return true;
}

/* Lower L with L L' = M, row by row; false when M is not positive definite. */
static bool cholesky(const double M[P_MAX][P_MAX], size_t n, double L[P_MAX][P_MAX])
{
    for (size_t i = 0U; i < n; i++) {
        for (size_t j = 0U; j < P_MAX; j++) {
            L[i][j] = 0.0;
        }
    }
    for (size_t i = 0U; i < n; i++) {
        for (size_t j = 0U; j <= i; j++) {
            double s = M[i][j];
            for (size_t k = 0U; k < j; k++) {
                s = s - (L[i][k] * L[j][k]);
            }
            if (i == j) {
                if (!(s > 0.0)) {
                    return false;
                }
                L[i][i] = sqrt(s);
            } else {
                L[i][j] = s / L[j][j];
            }
        }
    }
    return true;
}

/* x with L L' x = b: forward, then backward substitution. */
static void cholesky_solve(const double L[P_MAX][P_MAX], size_t n, const double* b, double* x)
{
    double y[P_MAX];
    for (size_t i = 0U; i < n; i++) {
        double s = b[i];
        for (size_t k = 0U; k < i; k++) {
            s = s - (L[i][k] * y[k]);
        }
        y[i] = s / L[i][i];
    }
    for (size_t ii = n; ii > 0U; ii--) {
        const size_t i = ii - 1U;
        double s = y[i];
        for (size_t k = i + 1U; k < n; k++) {
            s = s - (L[k][i] * x[k]);
        }
        x[i] = s / L[i][i];
    }
}

/* The rows of one point's Jacobian (export_refine._perturbed): each fitted entry moved by
 * its relative step, forward, or backward where forward would leave what a reader accepts;
 * neither: the row itself (the column stays 0). */
static void perturbed(const double* row, size_t row_len, size_t n_sets, size_t j, double* moved,
                      double* step)
{
    const double hs[2] = {NTE_REFINE_H, -NTE_REFINE_H};
    *step = NTE_REFINE_H;
    (void)memcpy(moved, row, row_len * sizeof row[0]);
    for (size_t t = 0U; t < 2U; t++) {
        double cand[NTE_EXPORT_ROW_MAX];
        double kept[NTE_EXPORT_ROW_MAX];
        (void)memcpy(cand, row, row_len * sizeof row[0]);
        cand[j] = row[j] * (1.0 + hs[t]);
        (void)memcpy(kept, cand, row_len * sizeof row[0]);
        readable(kept, row_len, n_sets);
        if (same_row(kept, cand, row_len)) {
            *step = hs[t];
            (void)memcpy(moved, cand, row_len * sizeof row[0]);
            return;
        }
    }
}

/* What one point's part of a pass gives: SSE, A = J'J and b = J'r. */
typedef struct normal_t {
    double sse;
    double A[P_MAX][P_MAX];
    double b[P_MAX];
} normal_t;

/* Replay a point and its Jacobian rows; sums in sample order (export_refine._normal_equations).
 * res holds (1 + P) * n doubles, n = tr->n times the replays per row (export_replay.h); *m:
 * the counted samples. */
static int point_pass(const nte_config_t* run_cfg, const nte_trial_t* tr, const double* row,
                      size_t row_len, const size_t* idx, size_t P, double surface_mm, double tare_n,
                      nte_t* scratch, double* res, normal_t* ne, size_t* m)
{
    const size_t n = tr->n * ((run_cfg->layer_sets > 0U) ? NTE_EXPORT_LAYER_SHIFTS : 1U);
    double steps[P_MAX];
    nte_export_replay_t rep;
    if (nte_export_replay(run_cfg, tr, row, row_len, surface_mm, tare_n, scratch, res, &rep) != 0) {
        return -1;
    }
    *m = rep.counted;
    for (size_t j = 0U; j < P; j++) {
        double moved[NTE_EXPORT_ROW_MAX];
        perturbed(row, row_len, run_cfg->layer_sets, idx[j], moved, &steps[j]);
        if (nte_export_replay(run_cfg, tr, moved, row_len, surface_mm, tare_n, scratch,
                              res + ((j + 1U) * n), &rep) != 0) {
            return -1;
        }
    }
    /* the Jacobian's columns overwrite the moved replays: J_j = (r_j - r_0) / step_j */
    for (size_t j = 0U; j < P; j++) {
        double* col = res + ((j + 1U) * n);
        for (size_t k = 0U; k < *m; k++) {
            col[k] = (col[k] - res[k]) / steps[j];
        }
    }
    double s = 0.0;
    for (size_t k = 0U; k < *m; k++) {
        s = s + (res[k] * res[k]);
    }
    ne->sse = s;
    for (size_t i = 0U; i < P; i++) {
        const double* ji = res + ((i + 1U) * n);
        for (size_t j = 0U; j <= i; j++) {
            const double* jj = res + ((j + 1U) * n);
            double a = 0.0;
            for (size_t k = 0U; k < *m; k++) {
                a = a + (ji[k] * jj[k]);
            }
            ne->A[i][j] = a;
            ne->A[j][i] = a;
        }
        double bi = 0.0;
        for (size_t k = 0U; k < *m; k++) {
            bi = bi + (ji[k] * res[k]);
        }
        ne->b[i] = bi;
    }
    return 0;
}

/* export_refine._step: the values after the step solving (A + lam diag(A)) d = -b; the row
 * itself when the system cannot be solved. */
static void damped_step(const double* row, size_t row_len, size_t n_sets, const size_t* idx,
                        size_t P, const normal_t* ne, double lam, double* moved)
{
    double M[P_MAX][P_MAX];
    double L[P_MAX][P_MAX];
    double nb[P_MAX];
    double d[P_MAX];
    (void)memcpy(moved, row, row_len * sizeof row[0]);
    for (size_t i = 0U; i < P_MAX; i++) {
        nb[i] = (i < P) ? -ne->b[i] : 0.0;
        d[i] = 0.0;
    }
    for (size_t i = 0U; i < P; i++) {
        for (size_t j = 0U; j < P; j++) {
            M[i][j] = ne->A[i][j];
        }
        M[i][i] = ne->A[i][i] + (lam * ((ne->A[i][i] > 0.0) ? ne->A[i][i] : 1.0));
    }
    if (!cholesky((const double(*)[P_MAX])M, P, L)) {
        return;
    }
    cholesky_solve((const double(*)[P_MAX])L, P, nb, d);
    for (size_t i = 0U; i < P; i++) {
        if (!isfinite(d[i])) {
            return;
        }
    }
    for (size_t k = 0U; k < P; k++) {
        const double dk = fmin(fmax(d[k], NTE_REFINE_STEP_MIN), NTE_REFINE_STEP_MAX);
        moved[idx[k]] = row[idx[k]] * ((2.0 + dk) / (2.0 - dk));
    }
    readable(moved, row_len, n_sets);
}

int nte_export_refine(const nte_config_t* run_cfg, const nte_trial_t* tr, const double* start,
                      size_t row_len, const bool fitted[NTE_EXPORT_ROW_MAX], double surface_mm,
                      double tare_n, nte_t* scratch, nte_export_fit_t* out)
{
    size_t idx[P_MAX];
    size_t P = 0U;
    for (size_t j = 0U; j < row_len; j++) {
        if (fitted[j]) {
            idx[P++] = j;
        }
    }
    /* every replay: NTE_EXPORT_LAYER_SHIFTS of them with layer sets (export_replay.h) */
    const size_t n_res = (tr->n > 0U ? tr->n : 1U) *
                         ((run_cfg->layer_sets > 0U) ? NTE_EXPORT_LAYER_SHIFTS : 1U);
    double* res = malloc((P + 1U) * n_res * sizeof(double));
    if (res == NULL) {
        return -1;
    }
    double row[NTE_EXPORT_ROW_MAX];
    (void)memcpy(row, start, row_len * sizeof row[0]);
    normal_t cur;      /* the current values' SSE, A and b */
    normal_t light_ne; /* the two candidate steps' */
    normal_t heavy_ne;
    size_t m = 0U;
    size_t m2 = 0U;
    int rc = point_pass(run_cfg, tr, row, row_len, idx, P, surface_mm, tare_n, scratch, res, &cur,
                        &m);
    unsigned passes = 1U;
    double lam = NTE_REFINE_LAMBDA_START;
    while ((rc == 0) && (passes < NTE_REFINE_PASSES) && (P > 0U) && isfinite(cur.sse) &&
           (lam <= NTE_REFINE_LAMBDA_MAX)) {
        /* two damped steps replayed together: lam and NTE_REFINE_LAMBDA_WIDE * lam */
        double light[NTE_EXPORT_ROW_MAX];
        double heavy[NTE_EXPORT_ROW_MAX];
        damped_step(row, row_len, run_cfg->layer_sets, idx, P, &cur, lam, light);
        damped_step(row, row_len, run_cfg->layer_sets, idx, P, &cur, lam * NTE_REFINE_LAMBDA_WIDE,
                    heavy);
        if (same_row(light, row, row_len) && same_row(heavy, row, row_len)) {
            break;
        }
        rc = point_pass(run_cfg, tr, light, row_len, idx, P, surface_mm, tare_n, scratch, res,
                        &light_ne, &m2);
        if (rc == 0) {
            rc = point_pass(run_cfg, tr, heavy, row_len, idx, P, surface_mm, tare_n, scratch, res,
                            &heavy_ne, &m2);
        }
        passes++;
        if (rc != 0) {
            break;
        }
        const double before = cur.sse;
        if ((light_ne.sse < cur.sse) && (light_ne.sse <= heavy_ne.sse)) {
            (void)memcpy(row, light, row_len * sizeof row[0]);
            cur = light_ne;
            lam = lam * NTE_REFINE_LAMBDA_DOWN;
        } else if (heavy_ne.sse < cur.sse) {
            (void)memcpy(row, heavy, row_len * sizeof row[0]);
            cur = heavy_ne;
            lam = lam * NTE_REFINE_LAMBDA_WIDE;
        } else {
            lam = lam * NTE_REFINE_LAMBDA_WIDE * NTE_REFINE_LAMBDA_WIDE;
            continue;
        }
        if (((before - cur.sse) / before) < NTE_REFINE_TOL) {
            break;
        }
    }
    free(res);
    if (rc != 0) {
        return -1;
    }
    (void)memcpy(out->row, row, row_len * sizeof row[0]);
    for (size_t j = 0U; j < NTE_EXPORT_ROW_MAX; j++) {
        out->has_sd[j] = false;
        out->sd[j] = 0.0;
    }
    double L[P_MAX][P_MAX];
    if ((P > 0U) && (m > P) && cholesky((const double(*)[P_MAX])cur.A, P, L)) {
        const double s2 = cur.sse / (double)(m - P);
        for (size_t k = 0U; k < P; k++) {
            double e[P_MAX];
            double x[P_MAX];
            for (size_t i = 0U; i < P; i++) {
                e[i] = (i == k) ? 1.0 : 0.0;
            }
            cholesky_solve((const double(*)[P_MAX])L, P, e, x);
            if (x[k] > 0.0) {
                out->sd[idx[k]] = fabs(row[idx[k]]) * sqrt(s2 * x[k]);
                out->has_sd[idx[k]] = true;
            }
        }
    }
    out->rmse_n = (m > 0U) ? sqrt(cur.sse / (double)m) : (double)NAN;
    out->passes = passes;
    return 0;
}
