"""The replay a reader of an exported configuration gets: the model alone, from depth alone.

``--export-config`` judges parameter sets by what ``--config FILE --predict-only`` would do with
them on the record they came from: the run's configuration turned into a reader's (the set as
the nominal values, predict-only, the surface the front end ended with), the record's depth and
velocity stepped through the bank with the force ignored, the prediction compared with the
measured force less the tare.  export_select.py replays the run's snapshots this way to choose
a start, export_refine.py replays perturbed sets to fit.

Several sets replay at once: the bank is batched over them (one pass over the record), and a
batched row computes exactly what a run of that set alone computes.  The C twin is
firmware/host/export_replay.c (one set per pass through nte_step; C ≡ reference at 0 ULP).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..bank import FilterBank
from ..config import EstimatorConfig
from ..fmath import Real, real_for
from ..params import LAYER_SET_NAMES
from .csvio import Trial, time_us


@dataclass(frozen=True)
class Replay:
    residuals: np.ndarray   # (sets, counted samples): prediction - (force - tare), N, float64
    peak_n: float           # max |force - tare| over the counted samples, N


#: with layer sets every row is replayed with their starts moved by each of these, mm, and the
#: residuals follow one another (the fit then weighs the three alike).  Why: a trial of the
#: same condition tears a little deeper or shallower than the one identified, and sets fitted
#: at one depth alone switched their force there -- 1 mm early or late on the next trial made
#: the prediction worse than without sets in 34 of 38 cases (phantom skin-on-muscle and
#: artery-filled seeds 201-205, measured-like seeds 22-30; ±2 mm: 33 of 38); fitted over the
#: three, 5 of 38 (±1 mm) and 11 of 38 (±2 mm), the median better than without at every shift.
LAYER_SHIFTS_MM = (-1.0, 0.0, 1.0)


def reader_config(cfg: EstimatorConfig, surface_mm: float) -> EstimatorConfig:
    """The configuration a reader of the exported file runs: predict-only and, with the front
    end on, the known surface."""
    out = replace(cfg, predict_only=True)
    if cfg.contact.enabled:
        out = replace(out, contact=replace(cfg.contact, surface_mm=surface_mm))
    return out


def replay(cfg: EstimatorConfig, precision: str, trial: Trial, rows: list[list[float]],
           surface_mm: float, tare_n: float) -> Replay:
    """Replay every row (the seven force-model values, then the relaxation strengths in use,
    as a reader builds its nominal values, then the LAYER_SET_NAMES values of each of
    cfg.layer_sets) from depth alone.  Samples whose force is not finite are not counted (as
    the reader's comparison skips them).  With layer sets each row is replayed once per
    LAYER_SHIFTS_MM and its residuals are the replays' one after the other."""
    R = real_for(precision)
    n = len(LAYER_SET_NAMES)
    tail = n * len(cfg.layer_sets)
    base = [list(r[:len(r) - tail]) for r in rows]
    sets = [[list(r[len(r) - tail + k * n:len(r) - tail + (k + 1) * n])
             for k in range(len(cfg.layer_sets))] for r in rows]
    reader = reader_config(cfg, surface_mm)
    if not cfg.layer_sets:
        return _replay_batch(R, reader, trial, base, sets, None, tare_n)
    # every row once per shift, in one batch: the starts moved in the working precision, as
    # the C twin adds them
    S, K = len(LAYER_SHIFTS_MM), len(rows)
    starts = [[float(R.c(ls.start_mm) + R.c(shift)) for ls in cfg.layer_sets]
              for shift in LAYER_SHIFTS_MM for _ in range(K)]
    rep = _replay_batch(R, reader, trial, base * S, sets * S, starts, tare_n)
    res = rep.residuals.reshape(S, K, -1).transpose(1, 0, 2).reshape(K, -1)
    return Replay(res, rep.peak_n)


def _replay_batch(R: Real, cfg: EstimatorConfig, trial: Trial, base: list[list[float]],
                  sets: list[list[list[float]]], starts: list[list[float]] | None,
                  tare_n: float) -> Replay:
    bank = FilterBank(R, cfg, base, sets, starts)
    K = len(base)
    t_us = time_us(trial.t_s)
    depth, vel = R.arr(trial.depth_mm), R.arr(trial.velocity_mm_s)
    zero_force = R.arr(np.zeros(K))
    counted = [k for k in range(len(trial.t_s)) if math.isfinite(float(trial.force_n[k]))]
    res = np.zeros((K, len(counted)))
    peak = 0.0
    col = 0
    for k in range(len(trial.t_s)):
        o = bank.step(np.full(K, t_us[k]), np.full(K, depth[k], dtype=R.dtype),
                      np.full(K, vel[k], dtype=R.dtype), zero_force)
        f = float(trial.force_n[k])
        if not math.isfinite(f):
            continue
        target = f - tare_n
        peak = max(peak, abs(target))
        res[:, col] = o.force_hat.astype(np.float64) - target
        col += 1
    return Replay(res, peak)


def sum_in_order(x: np.ndarray) -> float:
    """x[0] + x[1] + ... added left to right in double, as the C twin's loop adds (numpy's
    accumulate is sequential; its sum is pairwise and would differ in the last bits)."""
    return float(np.add.accumulate(x)[-1]) if len(x) else 0.0


__all__ = ["Replay", "reader_config", "replay", "sum_in_order"]
