/*
 * nte_preset_config.h -- a preset's (or a configuration file's) seven force-model values as an
 * estimator configuration's nominal values: the one rule the host programs (nte-run) and the
 * ports (nte-node) share.  Compiled into each program with its own nte_real_t (the presets are
 * double; the library float or double).  Host programs and ports only, never the library.
 */
#ifndef NTE_PRESET_CONFIG_H
#define NTE_PRESET_CONFIG_H

#include "nte.h"

/** The seven values (sigma0, sigma1, sigma2, f1, f2, alpha, beta) as cfg's nominal (starting)
 *  values, each rounded once to nte_real_t, and the identified part of f1 computed in double
 *  as the reference does (f1 - kappa (-f2), kappa = 1 when f2 < 0; params.py f1_excess), then
 *  rounded.  Returns -1 (cfg's f1_excess untouched) when that part is not positive
 *  (g(0) = f1 + f2 must be). */
int nte_preset_nominal(nte_config_t* cfg, const double values[7]);

#endif /* NTE_PRESET_CONFIG_H */
