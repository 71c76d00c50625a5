"""Model III's layer index: a rupture detector on the bank's innovations (issue "Model III on
the board", part 3).  C twin: firmware/src/nte_layers.c.

Why.  A needle crosses layers: each membrane is tented until it tears, and the force drops by
0.5-3 N within a few samples (MODEL.md §9: 1-5 ruptures per insertion in measured records).
The model's force cannot drop like that, so a rupture shows as a run of large negative
innovations — the force suddenly below the one-step prediction.  A one-sided CUSUM of the
innovation in units of the sensor noise finds it:

    nu = innovation / sigma      (filter 1's; sigma: the contact front end's noise learned in
                                  the air, or sqrt(r_n2) with the front end off)
    g  <- max(0, g - nu - DRIFT_SIGMA)                            (only while it may rupture)
    g  >  THRESHOLD_SIGMA  ->  a rupture: layer + 1 (at most LAYER_MAX - 1), g <- 0

The noise, not the filter's own sqrt(S): S grows with the covariance after every large
innovation, so a tear soon after another (or after a stretch the model lagged) looked small
in NIS units — on the held-out records below the NIS form found 27 of 31 with 3 false alarms.

It may rupture only while the needle moves in (v > v_still_mm_s) at least HOLDOFF_MM below the
surface and below the previous rupture: the contact onset and the bank's re-adaptation after a
drop also make negative innovations, and no membrane tears within 1.5 mm of the last one in the
measured records (layers 2-7 mm).  Out of the tissue (depth <= 0) the index returns to 0: the
next insertion starts in the first layer.  A drop of 20 noise standard deviations in one sample
fires at once; a slower one (a tear over 0.5 s at 1 mm/s) accumulates.

The constants were chosen on phantom skin-on-muscle seeds 101-103 (2 of 2 ruptures at the right
depth, no false alarm, for drift 1 and thresholds 20-40) and checked on records drawn otherwise:
`lab` tissues (seeds 201-210, 0-3 ruptures each) and the five presets (seeds 111-112):
tests/python/test_layers.py measures the index (its figures in the README).

The bank (bank._watch_layers) runs the detector on filter 1's prior innovation of every
accepted sample, before any filter's update, and treats the sample of a rupture as a tear
(bank._tear_prior): every filter's covariance restarts at P0 — the torn layer's estimates are
the next layer's start — and that sample updates z alone.  --export-config writes a layer set
(MODEL.md §3b part 3, bank._enter_layer_sets) at each tear the detector found in a record's
first insertion, for predict-only mode.
"""
from __future__ import annotations

import numpy as np

from .fmath import Array, Real

#: layers counted, index 0..LAYER_MAX - 1 (the C build's NTE_LAYER_MAX; static memory)
LAYER_MAX = 4
#: the CUSUM's reference value, noise standard deviations per sample
DRIFT_SIGMA = 1.0
#: its alarm level, noise standard deviations
THRESHOLD_SIGMA = 20.0
#: no rupture within this depth below the surface or the previous rupture, mm
HOLDOFF_MM = 1.5


class RuptureDetector:
    """The layer index of every run of a batch (LayerState in C)."""

    def __init__(self, R: Real, batch: int, v_still_mm_s: float) -> None:
        self.R = R
        self.v_still = R.c(v_still_mm_s)
        self.drift = R.c(DRIFT_SIGMA)
        self.threshold = R.c(THRESHOLD_SIGMA)
        self.holdoff = R.c(HOLDOFF_MM)
        self.batch = batch
        self.reset()

    def reset(self) -> None:
        R, B = self.R, self.batch
        self.g = R.full(B, 0.0)            # the CUSUM, noise standard deviations
        self.last_mm = R.full(B, 0.0)      # depth of the previous rupture (0: the surface)
        self.layer = np.zeros(B, dtype=np.uint32)

    def step(self, valid: Array, run: Array, depth: Array, velocity: Array, innovation: Array,
             sigma: Array) -> tuple[Array, Array]:
        """One sample: ``valid`` accepted, ``run`` accepted and not the first; depth below the
        surface (mm, what the bank was fed), velocity (mm/s), filter 1's innovation (N) and the
        noise's standard deviation (N).  Returns the layer index and where a rupture was
        found."""
        R = self.R
        zero = R.c(0.0)
        inside = depth > zero
        may = run & inside & (velocity > self.v_still) & ((depth - self.last_mm) > self.holdoff)
        nu = innovation / sigma
        g = (self.g - nu) - self.drift
        g = np.where(may & (g > zero), g, zero)
        rupture = may & (g > self.threshold)
        top = np.uint32(LAYER_MAX - 1)
        layer = np.where(rupture, np.minimum(self.layer + np.uint32(1), top), self.layer)
        last = np.where(rupture, depth, self.last_mm)
        g = np.where(rupture, zero, g)
        # out of the tissue: the next insertion starts in the first layer
        layer = np.where(inside, layer, np.uint32(0))
        last = np.where(inside, last, zero)
        self.g = np.where(valid, g, self.g)
        self.last_mm = np.where(valid, last, self.last_mm)
        self.layer = np.where(valid, layer, self.layer).astype(np.uint32)
        return self.layer, rupture & valid


__all__ = ["LAYER_MAX", "DRIFT_SIGMA", "THRESHOLD_SIGMA", "HOLDOFF_MM", "RuptureDetector"]
