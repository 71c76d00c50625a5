/*
 * Model III's layer index: a rupture detector on the bank's innovations (reference_py/layers.py
 * RuptureDetector).  See THE LAYER INDEX in nte.h.  Internal header; the bank (nte_bank.c)
 * calls it after filter 1's measurement of every running sample (the first after init
 * updates nothing) when cfg.model == 3 and cfg.layers.
 */
#ifndef NTE_LAYERS_H
#define NTE_LAYERS_H

#include "nte_real.h"

/** RuptureDetector.reset: layer 0, CUSUM 0, no rupture yet.  Cost: O(1). */
void nte_layers_start(nte_t* self);

/**
 * RuptureDetector.step for one accepted sample, before any filter's update (the bank calls
 * it, nte_bank.c, on running samples: the reference's `run` is true); depth below the
 * surface (mm, what the bank was fed, clamped at 0), velocity (mm/s) and filter 1's prior
 * innovation of this sample (N; 0 where it is not watched), in units of the noise the
 * contact front end learned (sqrt(r_n2) with it off).  Advances self->layers.layer at a rupture.
 * Returns NTE_STATUS_RUPTURE at a rupture, NTE_STATUS_DROP at a one-sample drop inside the
 * hold-off (a tear of the same layer), else 0: the bank treats either as a tear.
 * Cost: 1 sqrt, 1 division, 3 flops.
 */
uint32_t nte_layers_watch(nte_t* self, nte_real_t depth_mm, nte_real_t velocity_mm_s,
                          nte_real_t innovation_n);

#endif /* NTE_LAYERS_H */
