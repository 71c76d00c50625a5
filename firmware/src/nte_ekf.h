/*
 * Small dense EKF kernels (state dimension n <= NTE_STATE_MAX, 4): reference_py/ekf.py in C.  Every product is
 * a sum in index order, accumulated left to right; covariances are computed on the upper
 * triangle and mirrored.  Internal header.
 */
#ifndef NTE_EKF_H
#define NTE_EKF_H

#include "nte_real.h"

#define NTE_EKF_N_MAX NTE_STATE_MAX

typedef nte_real_t nte_mat3_t[NTE_EKF_N_MAX][NTE_EKF_N_MAX];

/** out = F P F^T + diag(q) for the bank's transition F = [[f], [0, I]]: z's row f (dz/dz0,
 *  dz/du) and the parameters a random walk (ekf.predict_covariance), for the bank's filters,
 *  2 <= n <= NTE_EKF_N_MAX (any other n: out not written).  P is read only (not const: C99
 *  array qualifiers); out must not alias P. */
void nte_ekf_predict(size_t n, nte_mat3_t P, const nte_real_t* f, const nte_real_t* q,
                     nte_mat3_t out);

/** Result of one scalar update. */
typedef struct nte_ekf_update_t {
    nte_real_t s;   /**< innovation variance h P h^T + r */
    nte_real_t nis; /**< innovation^2 / s */
    bool accepted;  /**< the gate let the update through (or open_gate forced it) */
} nte_ekf_update_t;

/** Scalar measurement update in Joseph form behind an innovation gate (ekf.joseph_update), for
 *  the bank's filters, 2 <= n <= NTE_EKF_N_MAX (any other n: nothing updated, s and nis NaN,
 *  not accepted).
 *  Only when `apply` and accepted: x is updated in place and P_out gets the posterior
 *  covariance of the prior P (P is read only; P_out may be P).  Otherwise P_out is not
 *  written: the caller copies the prior then, which spares a copy on the usual path.  s, nis
 *  and accepted are always computed (the reference evaluates them for idle filters too).
 *  step > 0 bounds the update (ekf.bound_step): where the largest |change| of x[1..n)
 *  exceeds it, the whole update, x[0] included, is scaled by step / largest; step <= 0: no
 *  bound.
 *  hold: the gain's rows 1..n) are 0, so x[1..n) stays bit for bit and P follows that gain
 *  (the parameters held, nte.h HELD PARAMETERS). */
nte_ekf_update_t nte_ekf_joseph_update(size_t n, nte_real_t* x, nte_mat3_t P, nte_mat3_t P_out,
                                       const nte_real_t* h, nte_real_t innovation, nte_real_t r,
                                       nte_real_t gate2, bool open_gate, bool apply,
                                       nte_real_t step, bool hold);

/** Sylvester's criterion on the leading minors, and every entry finite (P read only; P must be
 *  symmetric, as every covariance of the bank is: only its upper triangle is checked for
 *  finite values). */
bool nte_ekf_positive_definite(size_t n, nte_mat3_t P);

#endif /* NTE_EKF_H */
