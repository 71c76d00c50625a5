"""Blind-test generator for the discrepancy workflow (tests only; the workflow never imports it).

Simulates measured-looking insertions from the base force model plus hidden effects, written here
independently of reference_py/effects.py and deliberately not in the library's functional forms
where the physics allows another (two-exponential relaxation of the force held at the stop, tanh
pre-sliding, power-law layer ramp with a finite drop, tissue motion as a sinusoidal displacement).
Magnitudes are drawn from the ranges of model-notes §8.  Recordings are messy: the stage meets the
tissue 2-10 mm after zero, samples arrive at 76-100 Hz with occasional gaps, the force carries a
tare offset, and the velocity column is present in only half of the trials.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from reference_py.discrepancy.fastsim import state_trajectory
from reference_py.discrepancy.io import Trial
from reference_py.params import PRESETS, ParamSet

EFFECTS = ("dwell_relaxation", "reversal_presliding", "velocity_friction", "direction_asymmetry",
           "layer_puncture", "sensor_drift", "tissue_motion")


@dataclass
class Case:
    trials: list[Trial]
    effects: tuple[str, ...]
    truth: list[np.ndarray]        # noise-free force with the hidden effects (N, incl. tare)
    support: list[np.ndarray]      # samples where a hidden effect changes the force (> 0.5 mN)
    info: dict = field(default_factory=dict)


def _lspb(t: np.ndarray, dist: float, speed: float, acc: float) -> tuple[np.ndarray, np.ndarray]:
    v = min(speed, math.sqrt(dist * acc))
    tb = v / acc
    dur = dist / v + tb
    tc = np.clip(t, 0.0, dur)
    pos = np.where(tc < tb, 0.5 * acc * tc ** 2,
                   np.where(tc <= dur - tb, 0.5 * acc * tb ** 2 + v * (tc - tb),
                            dist - 0.5 * acc * (dur - tc) ** 2))
    vel = np.where((t <= 0) | (t >= dur), 0.0,
                   np.where(tc < tb, acc * tc, np.where(tc <= dur - tb, v, acc * (dur - tc))))
    return pos, vel


def _times(rng: np.random.Generator, total: float) -> np.ndarray:
    out, t = [0.0], 0.0
    while t < total:
        t += rng.uniform(1 / 100, 1 / 76)
        if rng.random() < 0.005:
            t += rng.uniform(0.05, 0.3)
        out.append(t)
    return np.asarray(out)


def _trajectory(rng: np.random.Generator, surface: float, depth: float, speed: float,
                dwell: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    acc = rng.uniform(50.0, 100.0)
    dist = surface + depth
    move = dist / min(speed, math.sqrt(dist * acc)) + min(speed, math.sqrt(dist * acc)) / acc
    rest0, rest1 = rng.uniform(0.5, 1.5), rng.uniform(1.0, 3.0)
    t = _times(rng, rest0 + 2 * move + dwell + rest1)
    p1, v1 = _lspb(t - rest0, dist, speed, acc)
    p2, v2 = _lspb(t - rest0 - move - dwell, dist, speed, acc)
    x = p1 - p2
    v = v1 - v2
    return t, x, v


def _params(rng: np.random.Generator) -> ParamSet:
    base = PRESETS[rng.choice(["paper-10mms", "paper-6mms"])].params
    k = lambda: float(np.exp(rng.uniform(-0.3, 0.3)))  # noqa: E731
    f1 = -base.f2 + (base.f1 + base.f2) * k()
    return ParamSet(base.sigma0 * k(), base.sigma1 * k(), base.sigma2 * k(), f1, base.f2,
                    base.alpha, base.beta * k())


def _force(pp: ParamSet, t: np.ndarray, l: np.ndarray, v: np.ndarray,
           s_scale: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(elastic, friction magnitude, sign) of the base model along (t, l, v)."""
    l = np.maximum(l, 0.0)
    z = state_trajectory(t, l, pp.f1 / pp.sigma0, pp.f2 / pp.sigma0, pp.alpha, pp.beta)
    e = np.exp(-pp.alpha * l)
    b = pp.sigma0 / (pp.f1 + pp.f2 * e)
    elastic = pp.sigma0 * z * l
    fric = l * (pp.sigma1 * e * (pp.beta - b * z) + pp.sigma2)
    return elastic, fric, np.sign(v) * (l > 0)


def make_case(effects: tuple[str, ...], seed: int) -> Case:
    """One case: 1-3 trials of one tissue at different speeds, with ``effects`` hidden."""
    rng = np.random.default_rng(seed)
    pp = _params(rng)
    n_tr = int(rng.integers(2, 4)) if "velocity_friction" in effects else int(rng.integers(1, 4))
    while True:
        speeds = rng.uniform(1.0, 10.0, n_tr)
        if n_tr == 1 or (min(np.diff(np.sort(speeds))) > 1.0 and max(speeds) > 2 * min(speeds)):
            break
    noise = rng.uniform(0.002, 0.010)
    info: dict = {"params": pp, "noise_n": noise, "speeds": speeds.tolist()}
    # effect parameters shared by the trials of one case (same needle, tissue and sensor)
    relax_drop5 = rng.uniform(0.30, 0.52)
    if rng.random() < 0.5:
        taus, weights = (rng.uniform(1.0, 1.8),), (1.0,)
    else:
        w = rng.uniform(0.3, 0.7)
        taus, weights = (rng.uniform(0.2, 0.4), rng.uniform(2.0, 5.0)), (w, 1.0 - w)
    presl = rng.uniform(0.6, 2.0)
    bvisc = rng.uniform(1.0e-4, 3.0e-4)
    ratio = rng.uniform(1.25, 1.6) if rng.random() < 0.5 else rng.uniform(0.6, 0.8)
    layer_frac, layer_drop, layer_w = rng.uniform(0.3, 0.7), float(np.exp(rng.uniform(
        np.log(0.05), np.log(0.66)))), rng.uniform(1.5, 4.0)
    drift0 = rng.choice([-1, 1]) * rng.uniform(0.002, 0.008)
    drift1 = rng.choice([-1, 1]) * rng.uniform(0.0003, 0.0015)
    mot_a, mot_f = rng.uniform(0.5, 2.0), rng.uniform(0.2, 0.33)
    min_depth = 20.0
    depths = rng.uniform(min_depth, 80.0, n_tr)
    layer_depth = layer_frac * min(depths)
    info.update(relax=(relax_drop5, taus, weights), presliding_mm=presl, b_visc=bvisc,
                ratio=ratio, layer=(layer_depth, layer_drop, layer_w), drift=(drift0, drift1),
                motion=(mot_a, mot_f))
    trials, truth, support = [], [], []
    for i in range(n_tr):
        surface = rng.uniform(2.0, 10.0)
        t, x, v = _trajectory(rng, surface, depths[i], speeds[i], rng.uniform(1.0, 6.0))
        l, vv = x - surface, v.copy()
        if "tissue_motion" in effects:
            ph = rng.uniform(0, 2 * np.pi)
            w = 2 * np.pi * mot_f
            l = l - mot_a * np.sin(w * t + ph)
            vv = vv - mot_a * w * np.cos(w * t + ph)
        el0, fr0, s0 = _force(pp, t, x - surface, v)
        clean0 = el0 + s0 * fr0
        el, fr, s = _force(pp, t, l, vv)
        li = np.maximum(l, 0.0)
        f = el + s * fr
        if "reversal_presliding" in effects:
            dirs = np.where(s != 0, s, 0.0)
            idx = np.where(dirs != 0, np.arange(len(s)), 0)
            np.maximum.accumulate(idx, out=idx)
            last = dirs[idx]
            start = np.where(np.concatenate([[True], last[1:] != last[:-1]]),
                             np.arange(len(s)), 0)
            np.maximum.accumulate(start, out=start)
            cum = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(li)))])
            d = cum - cum[start]
            f = el + s * np.tanh(d / presl) * fr
        if "direction_asymmetry" in effects:
            f = np.where(s < 0, el + s * ratio * fr, f)
        if "velocity_friction" in effects:
            f = f + bvisc * vv * li
        if "dwell_relaxation" in effects:
            rest = (np.abs(v) == 0) & (li > 0)
            if rest.any():
                i0 = int(np.argmax(rest))
                i1 = i0 + int(np.argmin(rest[i0:])) if not rest[i0:].all() else len(rest)
                tau_t = t[i0:i1] - t[i0]
                shape = sum(wk / (1 - np.exp(-5.0 / tk)) * (1 - np.exp(-tau_t / tk))
                            for wk, tk in zip(weights, taus))
                # model-notes §8.1: the *measured* force at the stop decays by relax_drop5 in 5 s.
                # The tissue holds the stress it carried when the needle stopped (the base model
                # drops its friction term the instant s = 0), then relaxes: the force stays
                # continuous at the stop and loses relax_drop5 of it within 5 s.
                f_stop = f[i0 - 1] if i0 > 0 else f[i0]
                f[i0:i1] = f_stop * (1.0 - relax_drop5 * shape)
        if "layer_puncture" in effects:
            first = (np.maximum.accumulate(li) <= layer_depth + 0.2) & (v > 0) & (li > 0)
            up = np.clip((li - (layer_depth - layer_w)) / layer_w, 0.0, 1.0) ** 1.5
            down = np.clip((layer_depth + 0.2 - li) / 0.2, 0.0, 1.0)
            f = f + np.where(first, layer_drop * np.where(li <= layer_depth, up, down), 0.0)
        if "sensor_drift" in effects:
            f = f + drift0 + drift1 * t
        tare = rng.uniform(-0.05, 0.05)
        f_clean = f + tare
        meas = f_clean + rng.normal(0.0, noise, len(t))
        vel = v if rng.random() < 0.5 else None
        trials.append(Trial(f"trial{i}", t, x, meas, vel))
        truth.append(f_clean)
        support.append(np.abs(f - clean0) > 5e-4)
    return Case(trials, tuple(effects), truth, support, info)


# ------------------------------------------------------------------------------------------
# Running blind cases (shared by the tests and reference_py/discrepancy/confusion.py)
# ------------------------------------------------------------------------------------------
CASES_PER_KIND = 20
PAIR = ("dwell_relaxation", "reversal_presliding")


def kinds() -> list[tuple[str, ...]]:
    """Every hidden-effect configuration the issue asks about: each effect, none, the pair."""
    return [(e,) for e in EFFECTS] + [(), PAIR]


def case_seed(kind: tuple[str, ...], k: int) -> int:
    return 7919 * (kinds().index(kind) + 1) + k


def run_case(job: tuple[tuple[str, ...], int]) -> dict:
    """Generate one case, run the workflow blind, and grade it against the hidden truth.

    The gap is measured against the noise-free truth (the measured RMSE has a floor at the noise
    level, 2-10 mN, comparable to a few-mN drift): RMSE of (model - truth) where the hidden effect
    changes the force (its phases), and overall.
    """
    import time as _time

    from reference_py.discrepancy.workflow import run

    kind, k = job
    case = make_case(kind, case_seed(kind, k))
    t0 = _time.perf_counter()
    res = run(case.trials)
    dt = _time.perf_counter() - t0

    def rmse(preds: list[np.ndarray], on_support: bool) -> float:
        d = np.concatenate([(p - tr)[s] if on_support else (p - tr)
                            for p, tr, s in zip(preds, case.truth, case.support)])
        return float(np.sqrt(np.mean(d ** 2))) if len(d) else float("nan")

    return {"kind": kind, "k": k, "named": res.named, "n_trials": len(case.trials),
            "support_before": rmse(res.predictions[0], True),
            "support_after": rmse(res.predictions[-1], True),
            "overall_before": rmse(res.predictions[0], False),
            "overall_after": rmse(res.predictions[-1], False),
            "runtime_s": dt, "runtime_per_trial_s": dt / len(case.trials)}


def run_all(workers: int = 2, per_kind: int = CASES_PER_KIND) -> list[dict]:
    """All blind cases, in ``workers`` processes (single-threaded BLAS in each)."""
    import multiprocessing as mp
    import os

    jobs = [(kind, k) for kind in kinds() for k in range(per_kind)]
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    ctx = mp.get_context("spawn")
    with ctx.Pool(workers) as pool:
        return list(pool.imap_unordered(run_case, jobs, chunksize=2))
