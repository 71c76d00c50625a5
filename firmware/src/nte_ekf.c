/*
 * EKF kernels: reference_py/ekf.py in C, same operation order (PX4-ECL style: symmetric
 * covariance on one triangle, sequential scalar update, no matrix inverse).
 */
#include "nte_ekf.h"

/* The bank's filters have n = 2, 3 or 4 states: the Joseph update, their costliest kernel,
 * and the covariance prediction are inlined once for each n (NTE_SPECIALISE, NTE_UNROLL in
 * nte_real.h), so their loops and those of the sums below run written out.  The prediction's
 * copies take 288 B of the board's flash, which it has since the images are linked with -flto
 * (README, the cycle model).  The covariance check keeps one body: straight-line code. */

/* The Joseph update's sums of n products, accumulated left to right as ekf._dot does (with n
 * a constant where they are inlined, written out) */

/* sum_m a[m] b[m] */
static inline nte_real_t dot_rows(const size_t n, const nte_real_t* a, const nte_real_t* b)
{
    nte_real_t acc = a[0] * b[0];
    NTE_UNROLL
    for (size_t m = 1U; m < n; m++) {
        acc = acc + (a[m] * b[m]);
    }
    return acc;
}

/* sum_m a[m] M[m][j]: a row times column j */
static inline nte_real_t dot_column(const size_t n, const nte_real_t* a, nte_mat3_t M,
                                    const size_t j)
{
    nte_real_t acc = a[0] * M[0][j];
    NTE_UNROLL
    for (size_t m = 1U; m < n; m++) {
        acc = acc + (a[m] * M[m][j]);
    }
    return acc;
}

/* F = [[f], [0, I]]: (F P)[0][j] = sum_k f[k] P[k][j], the other rows P's own, so
 * out[0][0] = sum_k (F P)[0][k] f[k] + q[0], out[0][b] = (F P)[0][b] and out[a][b] = P[a][b]
 * (+ q[a] on the diagonal) for a, b >= 1; the dense product's other terms are products by 0
 * (derivation: ekf.predict_covariance) */
NTE_SPECIALISE void predict(const size_t n, nte_mat3_t P, const nte_real_t* f, const nte_real_t* q,
                            nte_mat3_t out)
{
    nte_real_t fp[NTE_EKF_N_MAX];
    NTE_UNROLL
    for (size_t j = 0U; j < n; j++) {
        fp[j] = dot_column(n, f, P, j);
    }
    out[0][0] = dot_rows(n, fp, f) + q[0];
    NTE_UNROLL
    for (size_t b = 1U; b < n; b++) {
        out[0][b] = fp[b];
        out[b][0] = fp[b];
    }
    NTE_UNROLL
    for (size_t a = 1U; a < n; a++) {
        out[a][a] = P[a][a] + q[a];
        NTE_UNROLL
        for (size_t b = a + 1U; b < n; b++) {
            out[a][b] = P[a][b];
            out[b][a] = P[a][b];
        }
    }
}

void nte_ekf_predict(const size_t n, nte_mat3_t P, const nte_real_t* f, const nte_real_t* q,
                     nte_mat3_t out)
{
    switch (n) {
    case 2U: predict(2U, P, f, q, out); break;
    case 3U: predict(3U, P, f, q, out); break;
    case 4U: predict(4U, P, f, q, out); break;
    default: break; /* not a filter of the bank: nothing written */
    }
}

NTE_SPECIALISE nte_ekf_update_t joseph(const size_t n, nte_real_t* x, nte_mat3_t P,
                                       nte_mat3_t P_out, const nte_real_t* h,
                                       const nte_real_t innovation, const nte_real_t r,
                                       const nte_real_t gate2, const bool open_gate,
                                       const bool apply, const nte_real_t step, const bool hold)
{
    nte_ekf_update_t res;
    nte_real_t pht[NTE_EKF_N_MAX] = {NTE_C(0.0)};
    nte_real_t k[NTE_EKF_N_MAX] = {NTE_C(0.0)};
    nte_mat3_t a;
    nte_mat3_t ap;
    NTE_UNROLL
    for (size_t i = 0U; i < n; i++) {
        nte_real_t acc = P[i][0] * h[0];
        NTE_UNROLL
        for (size_t m = 1U; m < n; m++) {
            acc = acc + (P[i][m] * h[m]);
        }
        pht[i] = acc;
    }
    nte_real_t s = h[0] * pht[0];
    NTE_UNROLL
    for (size_t m = 1U; m < n; m++) {
        s = s + (h[m] * pht[m]);
    }
    s = s + r;
    NTE_UNROLL
    for (size_t i = 0U; i < n; i++) {
        /* hold: the parameters' gain rows are 0 (the Joseph form below is right for any gain) */
        k[i] = (hold && (i > 0U)) ? NTE_C(0.0) : (pht[i] / s);
    }
    res.s = s;
    const nte_real_t y2 = innovation * innovation;
    res.nis = y2 / s;
    /* the gate decides on y^2 <= gate^2 S, without the division (ekf.joseph_update): what a
     * fixed-point port can compare (the NIS spans 1e-10..1e4); S <= 0 or NaN as y^2 / S did */
    const bool inside = (s > NTE_C(0.0)) ? (y2 <= (gate2 * s))
                                         : ((s < NTE_C(0.0)) && (y2 >= NTE_C(0.0)));
    res.accepted = inside || open_gate;
    if (!(apply && res.accepted)) {
        return res;
    }
    NTE_UNROLL
    for (size_t i = 0U; i < n; i++) {
        NTE_UNROLL
        for (size_t j = 0U; j < n; j++) {
            a[i][j] = ((i == j) ? NTE_C(1.0) : NTE_C(0.0)) - (k[i] * h[j]);
        }
    }
    NTE_UNROLL
    for (size_t i = 0U; i < n; i++) {
        NTE_UNROLL
        for (size_t j = 0U; j < n; j++) {
            ap[i][j] = dot_column(n, a[i], P, j);
        }
    }
    NTE_UNROLL
    for (size_t i = 0U; i < n; i++) {
        NTE_UNROLL
        for (size_t j = i; j < n; j++) {
            const nte_real_t v = dot_rows(n, ap[i], a[j]) + ((k[i] * r) * k[j]);
            P_out[i][j] = v;
            P_out[j][i] = v;
        }
    }
    /* the step bound (ekf.bound_step): the largest change of x[1..n), from 0, strict; over it
     * the whole update, z's change included, is shortened */
    nte_real_t xn[NTE_EKF_N_MAX];
    nte_real_t big = NTE_C(0.0);
    NTE_UNROLL
    for (size_t i = 0U; i < n; i++) {
        xn[i] = x[i] + (k[i] * innovation);
        const nte_real_t d = nte_abs(xn[i] - x[i]);
        big = ((i > 0U) && (d > big)) ? d : big;
    }
    const bool over = (step > NTE_C(0.0)) && (big > step);
    const nte_real_t scale = over ? (step / big) : NTE_C(1.0);
    NTE_UNROLL
    for (size_t i = 0U; i < n; i++) {
        x[i] = over ? (x[i] + ((xn[i] - x[i]) * scale)) : xn[i];
    }
    return res;
}

NTE_OUT_OF_LINE nte_ekf_update_t nte_ekf_joseph_update(const size_t n, nte_real_t* x, nte_mat3_t P,
                                                       nte_mat3_t P_out, const nte_real_t* h,
                                                       const nte_real_t innovation,
                                                       const nte_real_t r, const nte_real_t gate2,
                                                       const bool open_gate, const bool apply,
                                                       const nte_real_t step, const bool hold)
{
    switch (n) {
    case 2U: return joseph(2U, x, P, P_out, h, innovation, r, gate2, open_gate, apply, step, hold);
    case 3U: return joseph(3U, x, P, P_out, h, innovation, r, gate2, open_gate, apply, step, hold);
    case 4U: return joseph(4U, x, P, P_out, h, innovation, r, gate2, open_gate, apply, step, hold);
    default: break;
    }
    /* not a filter of the bank: nothing updated, and the NaN variance says so */
    const nte_ekf_update_t none = {(nte_real_t)NAN, (nte_real_t)NAN, false};
    return none;
}

bool nte_ekf_positive_definite(const size_t n, nte_mat3_t P)
{
    /* every entry finite: x * 0 is 0 for a finite x and NaN for an infinite or NaN one, and a
     * NaN stays NaN through a sum, so the sum of the products is 0 or NaN and one check at the
     * end replaces a compare and branch per entry.  P is symmetric by construction (the
     * prediction and the Joseph update write both triangles from one value, the guard's reset
     * is diagonal): the upper triangle holds every value. */
    const nte_real_t o = NTE_C(0.0);
    nte_real_t zero = P[0][0] * o;
    bool ok = P[0][0] > NTE_C(0.0);
    if (n >= 2U) {
        zero = (zero + (P[0][1] * o)) + (P[1][1] * o);
        const nte_real_t d2 = (P[0][0] * P[1][1]) - (P[0][1] * P[1][0]);
        ok = ok && (d2 > NTE_C(0.0));
    }
    if (n >= 3U) {
        zero = ((zero + (P[0][2] * o)) + (P[1][2] * o)) + (P[2][2] * o);
        const nte_real_t c0 = (P[1][1] * P[2][2]) - (P[1][2] * P[2][1]);
        const nte_real_t c1 = (P[1][0] * P[2][2]) - (P[1][2] * P[2][0]);
        const nte_real_t c2 = (P[1][0] * P[2][1]) - (P[1][1] * P[2][0]);
        const nte_real_t d3 = ((P[0][0] * c0) - (P[0][1] * c1)) + (P[0][2] * c2);
        ok = ok && (d3 > NTE_C(0.0));
    }
#if NTE_EKF_N_MAX >= 4
    if (n >= 4U) {
        zero = (((zero + (P[0][3] * o)) + (P[1][3] * o)) + (P[2][3] * o)) + (P[3][3] * o);
        /* Laplace expansion along rows 0, 1: their 2x2 minors s_ij times the complementary
         * minors c_kl of rows 2, 3 (ekf.py positive_definite, same order) */
        const nte_real_t s01 = (P[0][0] * P[1][1]) - (P[0][1] * P[1][0]);
        const nte_real_t s02 = (P[0][0] * P[1][2]) - (P[0][2] * P[1][0]);
        const nte_real_t s03 = (P[0][0] * P[1][3]) - (P[0][3] * P[1][0]);
        const nte_real_t s12 = (P[0][1] * P[1][2]) - (P[0][2] * P[1][1]);
        const nte_real_t s13 = (P[0][1] * P[1][3]) - (P[0][3] * P[1][1]);
        const nte_real_t s23 = (P[0][2] * P[1][3]) - (P[0][3] * P[1][2]);
        const nte_real_t c01 = (P[2][0] * P[3][1]) - (P[2][1] * P[3][0]);
        const nte_real_t c02 = (P[2][0] * P[3][2]) - (P[2][2] * P[3][0]);
        const nte_real_t c03 = (P[2][0] * P[3][3]) - (P[2][3] * P[3][0]);
        const nte_real_t c12 = (P[2][1] * P[3][2]) - (P[2][2] * P[3][1]);
        const nte_real_t c13 = (P[2][1] * P[3][3]) - (P[2][3] * P[3][1]);
        const nte_real_t c23 = (P[2][2] * P[3][3]) - (P[2][3] * P[3][2]);
        const nte_real_t d4 =
            ((((((s01 * c23) - (s02 * c13)) + (s03 * c12)) + (s12 * c03)) - (s13 * c02)) +
             (s23 * c01));
        ok = ok && (d4 > NTE_C(0.0));
    }
#endif
    return ok && nte_isfinite(zero);
}
