/*
 * The robust estimator (reference_py/robust.py RobustEstimator): the bank (nte_bank.h) plus a
 * batch refinement once per insertion.  Internal header; nte.c dispatches to it.
 */
#ifndef NTE_ROBUST_H
#define NTE_ROBUST_H

#include "nte_real.h"

#if NTE_ROBUST_BUFFER_LEN > 0

/** Row stride of the matrices ldlt_solve takes. */
typedef nte_real_t nte_robust_mat_t[NTE_MODEL_PARAM_COUNT][NTE_MODEL_PARAM_COUNT];

/**
 * robust.py ldlt_solve: M x = b for symmetric positive definite M (n <= NTE_MODEL_PARAM_COUNT)
 * by M = L D L^T, reading M's lower triangle only.  Returns false when a pivot was not
 * positive (a non-positive pivot is replaced by 1 to carry on, as the reference does); x is
 * then all zeros.  M is read only (not const: C99 array qualifiers).
 */
bool nte_robust_ldlt_solve(size_t n, nte_robust_mat_t M, const nte_real_t* b, nte_real_t* x);

/** The robust state right after nte_init / nte_reset (the bank must be started first). */
void nte_robust_start(nte_t* self);

/** RobustEstimator.step after the bank's step of the same sample: the buffer, the trigger and
 *  a slice of the refinement.  `valid`: the bank accepted the sample.  Returns the status
 *  bits to add (NTE_STATUS_REFINING, NTE_STATUS_REFINED, NTE_STATUS_CONVERGED). */
uint32_t nte_robust_step(nte_t* self, const nte_sample_t* sample, bool valid);

#endif

#endif /* NTE_ROBUST_H */
