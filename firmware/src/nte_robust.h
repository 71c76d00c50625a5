/*
 * The robust estimator (reference_py/robust.py) and the two bank entry points it needs
 * (reference_py/bank.py FilterBank.restart_from, the identified parameter list).  Internal
 * header.
 */
#ifndef NTE_ROBUST_H
#define NTE_ROBUST_H

#include "nte_real.h"

/** The identified parameters of the instance's model in reference MODEL_PARAMS order;
 *  returns their count (Model I: 6, Model II: 5). */
size_t nte_bank_identified(const nte_t* self, const uint8_t** ids);

/** FilterBank.restart_from for one run: re-centre the scaled parameters on theta (seven
 *  physical values): nominal = theta, ex_nominal = f1 - kappa (-f2) in nte_real_t, u = 0,
 *  every filter's P = P0 with var(u) = p0_u, gated runs cleared; z and the time line carry
 *  on.  Cost: 7 exp. */
void nte_bank_restart_from(nte_t* self, const nte_real_t theta[NTE_PARAM_COUNT],
                           nte_real_t p0_u);

#if NTE_ROBUST_BUFFER_LEN > 0

/** Row stride of the matrices ldlt_solve takes. */
typedef nte_real_t nte_robust_mat_t[NTE_IDENTIFIED_MAX][NTE_IDENTIFIED_MAX];

/**
 * robust.py ldlt_solve: M x = b for symmetric positive definite M (n <= NTE_IDENTIFIED_MAX)
 * by M = L D L^T, reading M's lower triangle only.  Returns false when a pivot was not
 * positive (a non-positive pivot is replaced by 1 to carry on, as the reference does); x is
 * then all zeros.  M is read only (not const: C99 array qualifiers).
 */
bool nte_robust_ldlt_solve(size_t n, nte_robust_mat_t M, const nte_real_t* b, nte_real_t* x);

/** The robust state right after nte_init / nte_reset (the bank must be started first). */
void nte_robust_start(nte_t* self);

/** RobustEstimator.step after the bank's step of the same sample: the buffer, the trigger and
 *  the refinement.  `valid`: the bank accepted the sample.  Returns the status bits to add
 *  (NTE_STATUS_REFINED, NTE_STATUS_CONVERGED). */
uint32_t nte_robust_step(nte_t* self, const nte_sample_t* sample, bool valid);

#endif

#endif /* NTE_ROBUST_H */
