"""Model III's layer index: a rupture detector on the bank's innovations (issue "Model III on
the board", part 3).  C twin: firmware/src/nte_layers.c (tear_prior and LayerSets, at the end:
firmware/src/nte_bank.c).

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

Inside the hold-off, a drop past the alarm in a single sample (-nu - DRIFT_SIGMA >
THRESHOLD_SIGMA) is a drop, not a new layer: mostly a tear's second and third samples (the
force falls over 2-3 samples at 100 Hz), or a second tear of the same membrane.  The bank
treats it as a tear (below) and the index stays.  Before, the bank adapted through it: on
model3_batch_figures.py --set select the phantom insertion's innovation fell 3.92 -> 3.68 with
it (read unchanged on --set held, 3.91 -> 3.81; the measured-like records, whose tears are
one sample, alike; the forms alike or better but the tear over 1 mm's reversal peak, 5.1 ->
5.8).

The constants were chosen on phantom skin-on-muscle seeds 101-103 (2 of 2 ruptures at the right
depth, no false alarm, for drift 1 and thresholds 20-40) and checked on records drawn otherwise:
`lab` tissues (seeds 201-210, 0-3 ruptures each) and the five presets (seeds 111-112):
tests/python/test_layers.py measures the index (its figures in the README).

The bank runs the detector (RuptureDetector.watch) on filter 1's prior innovation of every
accepted sample, before any filter's update, and treats the sample of a rupture or a drop as a
tear (tear_prior): every filter's covariance restarts at P0 — the torn layer's estimates are the
next layer's start — and that sample updates z alone; then the model's force is scaled down to the
force measured after the drop (tear_rescale).  --export-config writes a layer set (MODEL.md
§3b part 3, LayerSets) at each tear the detector found in a record's first insertion, for
predict-only mode.

This module is Model III's layers as the bank sees them: the index (RuptureDetector), what a
tear does to a filter (tear_prior) and the sets the model switches to below each start
(LayerSets).  The last two are the bank's code in C (nte_bank.c tear_prior, enter_layer_sets):
here they sit with the index so that bank.py keeps to the filters.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from .ekf import Matrix
from .fmath import Array, Real
from .model import ScaledParams, Theta
from .params import IDX, LAYER_SET_NAMES

#: layers counted, index 0..LAYER_MAX - 1 (the C build's NTE_LAYER_MAX; static memory)
LAYER_MAX = 4
#: the CUSUM's reference value, noise standard deviations per sample
DRIFT_SIGMA = 1.0
#: its alarm level, noise standard deviations
THRESHOLD_SIGMA = 20.0
#: no rupture within this depth below the surface or the previous rupture, mm
HOLDOFF_MM = 1.5
#: the smallest share of the prior force a tear's rescale keeps (tear_rescale)
TEAR_RATIO_MIN = 0.05
#: the bank's status bits for the detector's findings (bank.py's STATUS_*; nte.h's NTE_STATUS_*)
STATUS_RUPTURE = 1 << 12   # a layer's rupture was found at this sample: the index advanced
STATUS_DROP = 1 << 16      # a drop past the alarm in one sample inside the hold-off: a tear
#                            of the same layer (the bank treats it as a tear, the index stays)
STATUS_TEAR = STATUS_RUPTURE | STATUS_DROP   # the samples the bank treated as a tear


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
             sigma: Array) -> tuple[Array, Array, Array]:
        """One sample: ``valid`` accepted, ``run`` accepted and not the first; depth below the
        surface (mm, what the bank was fed), velocity (mm/s), filter 1's innovation (N) and the
        noise's standard deviation (N).  Returns the layer index, where a rupture was found
        and where a drop inside the hold-off was."""
        R = self.R
        zero = R.c(0.0)
        inside = depth > zero
        moving_in = run & inside & (velocity > self.v_still)
        beyond = (depth - self.last_mm) > self.holdoff
        may = moving_in & beyond
        nu = innovation / sigma
        g = (self.g - nu) - self.drift
        # inside the hold-off, a drop past the alarm in one sample is a tear of the same layer
        drop = moving_in & ~beyond & (((zero - nu) - self.drift) > self.threshold)
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
        return self.layer, rupture & valid, drop & valid

    def watch(self, first: Array, run: Array, depth: Array, velocity: Array, innovation: Array,
              in_range: Array, sigma: Array, predict_only: bool) -> Array:
        """The bank's call, once per sample on filter 1's prior innovation, before any filter's
        update (so that the sample of a rupture or of a drop is updated as a tear:
        tear_prior); returns per run STATUS_RUPTURE, STATUS_DROP or 0 (uint32).  C twin:
        nte_layers_watch and its call in nte_bank.c.

        Only running samples whose prior is in range feed the CUSUM (a diverged prior's
        innovation may not be finite), and none in predict-only mode (no force is read)."""
        zero = self.R.c(0.0)
        watched = run & ~np.bool_(predict_only) & in_range
        nu = np.where(watched, innovation, zero)
        _, rupture, drop = self.step(run | first, run, depth, velocity, nu, sigma)
        return (np.where(rupture, np.uint32(STATUS_RUPTURE), np.uint32(0))
                | np.where(drop, np.uint32(STATUS_DROP), np.uint32(0)))


def tear_prior(R: Real, P: Matrix, hrow: list[Array], tear: Array, P0: Matrix
               ) -> tuple[Matrix, list[Array]]:
    """A filter's prior at a tear, where ``tear``: the needle meets new tissue, so the
    covariance restarts at P0 (the estimates carry over as the new layer's start, with a
    start's uncertainty), and the tear's own sample updates z alone (its row on the parameters
    0; the bank opens the gate).  C twin: nte_bank.c tear_prior.

    Why: the drop (50-500 noise sd in one sample) is no evidence about the torn layer's
    parameters, yet a converged filter whose gate had just reopened took it at full gain
    and drove a relaxation strength or sigma0 to its clip, after which the one-step
    prediction stayed 1-3 N off for the rest of the insertion (measured-like seed 19:
    insertion innovation 59x the noise, 4x with this).  Tried and dropped on the same
    development seeds: z alone with the parameters' covariance kept (a catastrophic
    seed, 38 -> 151x), the whole covariance restarted with a full update (median 11x
    against 10x), the reopened gate's step bounded to the gate's size (worse
    everywhere).  Tried later and dropped: z's variance restarted at 1e-3 instead of p0_z,
    so that z takes the whole drop in the tear's sample (held-out measured-like records:
    insertion 7.7 -> 7.0, and 4.2 -> 2.5 without the tears' own samples, but the
    retraction's 90th percentile 4.9 -> 8.0, and 6.4 -> 27 at 200 Hz: z left far from its
    steady state pays at the reversal)."""
    zero = R.c(0.0)
    n = len(hrow)
    P = [[np.where(tear, P0[a][b], P[a][b]) for b in range(n)] for a in range(n)]
    hrow = [hrow[0]] + [np.where(tear, zero, hrow[a]) for a in range(1, n)]
    return P, hrow


def tear_rescale(R: Real, tear: Array, y: Array, innovation: Array, z_prior: Array,
                 z_post: Array, scaled: ScaledParams, mrel: list[Array], th: Theta
                 ) -> tuple[Array, list[Array], Theta]:
    """After a tear's sample: the model's force scaled down to the force measured after the
    drop, where ``tear``, by r = y / h (h = y - innovation: filter 1's prior force), at least
    TEAR_RATIO_MIN and only for a drop (h > 0, r < 1; the bank skips it while the parameters
    are held, FilterBank.set_frozen).  Scales the nominal beta and sigma2 in ``scaled`` in
    place; returns z = r z_prior (the posterior ``z_post`` elsewhere), the relaxation memories
    and theta with its beta and sigma2 times r (the next refresh of the two, nominal exp(u),
    agrees with them to rounding).  C twin: nte_bank.c tear_rescale.

    Why this is exact.  z, beta and sigma2 scaled by r scale the whole model:
        dz/dt = l (beta - sigma0 z / g)  ->  r dz/dt     (z stays r times the old trajectory)
        f = sigma0 z l + s l (sigma1 e (beta - sigma0 z / g) + sigma2)  ->  r f
    and the memories, which follow the elastic force, with it; sigma0, sigma1, f1 and z's time
    scale are untouched.  So the tear's sample ends on the measured force without moving any
    parameter along the gain.

    Why.  Tenting a membrane, the filters explain the rising force by the friction's scale
    (sigma1 10x its value, beta): where z's leverage on the force is small, the tear's z-only
    update (tear_prior) cannot take the drop, and the parameters, bounded to u_step_max per
    update, took 25-35 samples at -100 to -400 noise sd to come down (measured-like seed 124:
    5.2 N tented, 0.76 N after).  Chosen on model3_batch_figures.py --set select (ratio floor
    0.01-0.1 alike, 0.2 worse), read on --set held and --set forms (README "A tear rescales
    the model to the force after the drop")."""
    one = R.c(1.0)
    h = y - innovation
    r = y / h
    ok = tear & (h > R.c(0.0)) & (r < one)
    floor = R.c(TEAR_RATIO_MIN)
    r = np.where(r > floor, r, floor)
    fresh = {}
    for nm in ("beta", "sigma2"):
        j = IDX[nm]
        scaled.nominal[j] = np.where(ok, scaled.nominal[j] * r, scaled.nominal[j])
        fresh[nm] = np.where(ok, getattr(th, nm) * r, getattr(th, nm))
    return (np.where(ok, z_prior * r, z_post), [np.where(ok, m * r, m) for m in mrel],
            replace(th, **fresh))


class LayerSets:
    """Model III's layer sets for a batch (nte.h THE LAYER SETS, MODEL.md §3b part 3): per set
    its start depth below the surface and, per LAYER_SET_NAMES entry, the value of every run,
    in the working precision; and the set each run's model runs with (0: the nominal).

    C twin: nte_bank.c enter_layer_sets.  The C library keeps the sets in its configuration
    and the set in use in nte_t, so its code lives in the bank's file; here the bank owns one
    LayerSets (FilterBank.layer_sets) and calls enter() at the start of every sample."""

    def __init__(self, R: Real, batch: int, sets: Sequence[Any],
                 layer_values: list[list[list[float]]] | None,
                 layer_starts: list[list[float]] | None,
                 nominal0: tuple[list[Array], Array], kappa: Any) -> None:
        """``sets``: the configuration's (config.LayerSet: start_mm, values; config.py imports
        this module, so the type is not named here).  ``layer_values``: per run, the values of
        each set (LAYER_SET_NAMES order); ``layer_starts``: per run, their starts (mm); default:
        the configuration's own for every run (the export's replays shift them per run).
        ``nominal0``: the bank's configured scaled nominal values and f1 excess, which return
        out of the tissue; ``kappa``: its f1 kappa."""
        self.R, self.batch = R, batch
        if layer_values is None:
            layer_values = [[list(ls.values) for ls in sets] for _ in range(batch)]
        if layer_starts is None:
            layer_starts = [[ls.start_mm for ls in sets] for _ in range(batch)]
        for given in (layer_values, layer_starts):
            if len(given) != batch or any(len(v) != len(sets) for v in given):
                raise ValueError("layer_values, layer_starts: one entry per configured layer "
                                 "set for every run")
        self.starts = [R.arr([run[k] for run in layer_starts]) for k in range(len(sets))]
        self.values = [[R.arr([run[k][j] for run in layer_values])
                        for j in range(len(LAYER_SET_NAMES))] for k in range(len(sets))]
        nominal, self.ex0 = nominal0
        self.nominal0 = [nominal[IDX[nm]] for nm in LAYER_SET_NAMES]
        f2 = nominal[IDX["f2"]]
        f1 = LAYER_SET_NAMES.index("f1")
        # the part of each set's f1 the filters scale, as FilterBank.restart_from computes it
        self.ex = [v[f1] - kappa * (-f2) for v in self.values]
        if any(np.any(~(ex > R.c(0.0))) for ex in self.ex):
            raise ValueError("layer_sets: every f1 must exceed -f2 (g(0) = f1 + f2 must be "
                             "positive)")
        self.reset()

    def reset(self) -> None:
        """Every run back on the nominal values (the bank's reset restores those)."""
        self.layer = np.zeros(self.batch, dtype=np.uint32)

    def enter(self, predict_only: bool, fed: Array, l: Array, surface: Array,
              scaled: ScaledParams, u: list[Array], th: Theta) -> Theta:
        """One sample's switch, before the filters run, where ``fed`` (the bank's samples that
        run or start it), at the depth l below the surface (mm, >= 0): in predict-only mode the
        deepest set whose start the tip has reached since it entered the tissue replaces the
        nominal values of LAYER_SET_NAMES in ``scaled`` and their ``u`` restart at 0 (so the
        model runs with the set's values); out of the tissue, in any mode, the configured
        nominal values return.  Writes scaled and u in place; returns the refreshed theta.

        Why only predict-only mode: the filters identify one set as the needle goes; the sets
        are what an export found, for running the model alone on a later insertion."""
        R = self.R
        reached = np.zeros(self.batch, dtype=np.uint32)
        for start in self.starts:
            reached = reached + (l >= start).astype(np.uint32)
        deeper = np.where(reached > self.layer, reached, self.layer)
        target = self.layer
        if predict_only:
            target = deeper
        target = np.where(surface, np.uint32(0), target).astype(np.uint32)
        change = fed & (target != self.layer)
        if not np.any(change):
            return th
        for j, nm in enumerate(LAYER_SET_NAMES):
            value = self.nominal0[j]
            for k, vals in enumerate(self.values):
                value = np.where(target == k + 1, vals[j], value)
            scaled.nominal[IDX[nm]] = np.where(change, value, scaled.nominal[IDX[nm]])
            u[IDX[nm]] = np.where(change, R.c(0.0), u[IDX[nm]])
        ex = self.ex0
        for k, ex_k in enumerate(self.ex):
            ex = np.where(target == k + 1, ex_k, ex)
        scaled.ex_nominal = np.where(change, ex, scaled.ex_nominal)
        fresh = scaled.refresh(th, u, LAYER_SET_NAMES)
        self.layer = np.where(change, target, self.layer).astype(np.uint32)
        return Theta(*(np.where(change, getattr(fresh, f), getattr(th, f))
                       for f in Theta.__dataclass_fields__))


__all__ = ["LAYER_MAX", "DRIFT_SIGMA", "THRESHOLD_SIGMA", "HOLDOFF_MM", "TEAR_RATIO_MIN",
           "STATUS_RUPTURE", "STATUS_DROP", "STATUS_TEAR",
           "RuptureDetector", "tear_prior", "tear_rescale", "LayerSets"]
