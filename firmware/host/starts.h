/*
 * Reproducible starting values (reference_py/starts.py): SplitMix64 draws and libm log/exp in
 * double.  Host only.
 */
#ifndef NTE_STARTS_H
#define NTE_STARTS_H

#include "nte.h"

#include <stdint.h>

/** One SplitMix64 step: advances *state, returns the output. */
uint64_t nte_splitmix64(uint64_t* state);

/** Seven start values (sigma0, sigma1, sigma2, f1, f2, alpha, beta) from the given ones.
 *  Returns -1 if seed != 0 and factor is not finite and >= 1. */
int nte_start_values(const double values[7], uint64_t seed, double factor, int model,
                     double out[7]);

#endif /* NTE_STARTS_H */
