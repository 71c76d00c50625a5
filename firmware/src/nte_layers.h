/*
 * Model III's layer index: a rupture detector on the bank's innovations (reference_py/layers.py
 * RuptureDetector).  See THE LAYER INDEX in nte.h.  Internal header; nte.c calls it after the
 * bank's step of every accepted sample when cfg.model == 3 and cfg.layers.
 */
#ifndef NTE_LAYERS_H
#define NTE_LAYERS_H

#include "nte_real.h"

/** RuptureDetector.reset: layer 0, CUSUM 0, no rupture yet.  Cost: O(1). */
void nte_layers_start(nte_t* self);

/**
 * RuptureDetector.step for one accepted sample: `run` false at the first sample after init;
 * depth below the surface (mm, what the bank was fed), velocity (mm/s) and the bank's output
 * of this sample (filter 1's innovation), in units of the noise the contact front end learned
 * (sqrt(r_n2) with it off).  Sets out->layer and, at a rupture, NTE_STATUS_RUPTURE in
 * out->status.  Cost: 1 sqrt, 1 division, 3 flops.
 */
void nte_layers_step(nte_t* self, bool run, nte_real_t depth_mm, nte_real_t velocity_mm_s,
                     nte_output_t* out);

#endif /* NTE_LAYERS_H */
