/*
 * The bank of three joint state-parameter EKFs (reference_py/bank.py FilterBank) for one run.
 * It knows nothing of the robust estimator, which uses it through this header.  Internal
 * header; the public API (nte_init, nte_step, ...) is nte.c.
 */
#ifndef NTE_BANK_H
#define NTE_BANK_H

#include "nte_real.h"

/** FilterBank.reset: the configured nominal, u = 0, z = 0, the initial covariances, no
 *  history, the last output and the counters cleared.  Cost: 7 exp. */
void nte_bank_start(nte_t* self);

/** FilterBank._advance: one accepted sample (dt in s; `first`: the first accepted sample
 *  since the start, nothing to predict from).  Writes the sample's output to *out (status
 *  without NTE_STATUS_INIT / NTE_STATUS_REJECTED, which nte_step adds). */
void nte_bank_advance(nte_t* self, bool first, nte_real_t dt, nte_real_t l_in, nte_real_t v,
                      nte_real_t y, nte_output_t* out);

/** The identified parameters of the instance's model in reference MODEL_PARAMS order;
 *  returns their count (Model I: 6, Model II: 5). */
size_t nte_bank_identified(const nte_t* self, const uint8_t** ids);

/** FilterBank.restart_from for one run: re-centre the scaled parameters on theta (seven
 *  physical values): nominal = theta, ex_nominal = f1 - kappa (-f2) in nte_real_t, u = 0,
 *  every filter's P = P0 with var(u) = p0_u, gated runs cleared; z and the time line carry
 *  on.  Cost: 7 exp. */
void nte_bank_restart_from(nte_t* self, const nte_real_t theta[NTE_PARAM_COUNT], nte_real_t p0_u);

/** FilterBank._scale_to_sensor for one run: the bank's force unit becomes `unit` (units per
 *  N); z, the relaxation memories and the data's bound carry over (times the ratio), the
 *  nominal values are not converted.  Nothing happens when the unit is unchanged. */
void nte_bank_set_unit(nte_t* self, nte_real_t unit);

/** FilterBank._unscaled for one run: the output's force, z and innovation from the bank's
 *  unit back to N (divided by the unit). */
void nte_bank_unscale(const nte_t* self, nte_output_t* out);

/** FilterBank.parameter_estimates: up to `capacity` identified parameters with their
 *  standard deviations (delta method on u); returns the count (see nte_get_params). */
size_t nte_bank_params(const nte_t* self, nte_param_estimate_t* out, size_t capacity);

#endif /* NTE_BANK_H */
