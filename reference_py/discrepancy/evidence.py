"""Local evidence: each effect judged where it lives, against a local baseline.

A poor base fit elsewhere (a multi-layer insertion fitted with one hump, say) inflates the global
residual and, with it, the price any information criterion puts on an extra parameter.  The
signatures below are measured on the force itself, in the window where the effect acts, so a plain
local signature stays visible however large the misfit elsewhere:

- ``ruptures``: force drops larger than ``max(RUPTURE_MIN_FRAC * peak, RUPTURE_NOISE * noise)``
  within ``RUPTURE_WINDOW_S`` (at that rate across a gap in the record), or within
  ``RUPTURE_TEAR_MM`` of travel after a climb of as much over as much travel, during the first
  insertion at speed, up to the point where the stage starts to slow into its stop (measured
  insertions: > 0.15 N within 0.1 s, 0-5 per insertion).  Their depths switch the multi-layer
  base model.
- ``dwell``: per dwell, the force (air drift removed) fitted by a constant, a line, one and two
  exponentials (time constants on a log grid in [0.05, 30] s).  Reported: relative decay, time
  constants, amplitude / noise and the chi-square gain of the exponential over the line.
- ``reversal``: travel from the reversal to the zero crossing of the smoothed force, and the
  chi-square gain of ``a + b d + c exp(-d/delta)`` over ``a + b d`` on the first 6 mm of travel.
- ``drift``: the force level in the air after exit against the level before contact (the tare is
  the latter), and its slope, in noise units.
- ``speeds``: distinct insertion speeds (velocity dependence needs two).
- ``period``: the strongest 0.1-0.6 Hz line of a residual and its share of the residual power.
"""
from __future__ import annotations

import numpy as np

from ..fmath import Array
from .prep import PHASES, Prepared, smooth

#: a rupture is a drop of at least this fraction of the insertion peak ...
RUPTURE_MIN_FRAC = 0.06
#: ... and at least this many noise standard deviations (of one sample: the largest of ~10
#: differences of 3-sample means over thousands of samples reaches ~4 sigma on noise alone) ...
RUPTURE_NOISE = 8.0
#: ... within this time (s), ...
RUPTURE_WINDOW_S = 0.1
#: ... or within this travel (mm) at the trial's cruise speed, if the force climbed by at least
#: RUPTURE_CLIMB thresholds over the same travel before it: a tear that runs on while the needle
#: advances takes longer on a slow stage (measured: 0.8 N over 0.5 s at 1 mm/s, of which a 0.1 s
#: window sees 0.33 N), and a membrane tents before it tears.  Without the climb, a window in
#: travel takes a tissue whose force rolls over and slowly declines for a tear.
RUPTURE_TEAR_MM = 0.6
RUPTURE_CLIMB = 0.5
#: ... while the stage moves at least this fraction of its median insertion speed ...
RUPTURE_CRUISE = 0.7
#: ... and has not yet begun to slow into its stop: the last sample at this fraction of the
#: median speed ends the insertion's cruise (a friction that follows the speed falls with it as
#: the stage slows: no rupture; a tear just before the stop, still at speed, is one)
RUPTURE_STEADY = 0.97
#: the force is averaged over this time (at least 3 samples) before drops are looked for, so a
#: fast logger's noise does not pass for a drop
RUPTURE_SMOOTH_S = 0.03
#: a drop is over when the force has risen this fraction of the threshold above its lowest point
#: or has set no new low for a window (the next layer loading, or the noise)
RUPTURE_END_RISE = 0.5
#: five or more drops evenly spaced in time (interval spread below this fraction of the mean
#: interval) are periodic: a motion or stick-slip line, not layers (random layer depths spread
#: more: 0.25 seen on a 4-layer trial) ...
RUPTURE_PERIODIC_CV = 0.1
#: ... and four drops only below this one: three intervals of random layer depths come out even
#: by chance (measured-like 4-layer trials: 0.075, 0.091, 0.098 in 3 of 29, every layer then
#: lost), a sawtooth's stay even (stick-slip with four drops: 0.043; with more, up to 0.088)
RUPTURE_PERIODIC_CV_FOUR = 0.05
#: a tear whose largest one-sample fall carries this fraction of its drop is placed between
#: those two samples (see _tear_depth)
RUPTURE_SHARP = 0.5
#: ruptures closer than this (mm) are one event
RUPTURE_MERGE_MM = 0.5
#: time-constant grid of the local dwell fits (s): the documented bounds of relaxation
TAU_GRID = np.geomspace(0.05, 30.0, 40)
#: presliding-length grid of the local reversal fit (mm)
DELTA_GRID = np.geomspace(0.05, 5.0, 30)
#: travel after a reversal in the local reversal window (mm)
REVERSAL_WINDOW_MM = 6.0


def ruptures(p: Prepared) -> list[dict[str, float]]:
    """Sudden force drops during the first insertion: tissue depth (mm), time (s), drop (N)."""
    l = p.stage_mm - p.surface_mm
    s = np.sign(p.v_mm_s) * (np.abs(p.v_mm_s) > 0.02)
    back = np.nonzero((s < 0) & (l > 0))[0]
    end = int(back[0]) if len(back) else len(l)
    ins = np.nonzero((l[:end] > 0) & (s[:end] > 0))[0]       # advancing (a dwell is no rupture)
    if len(ins) < 8:
        return []
    v_cruise = float(np.median(p.v_mm_s[ins]))
    cruise = p.v_mm_s[ins] >= RUPTURE_CRUISE * v_cruise
    cruise[int(np.nonzero(p.v_mm_s[ins] >= RUPTURE_STEADY * v_cruise)[0][-1]) + 1:] = False
    window = RUPTURE_WINDOW_S
    tear = max(window, RUPTURE_TEAR_MM / max(v_cruise, 1e-6))
    t = p.t_s[ins]
    dt = float(np.median(np.diff(t)))
    # averaged within each unbroken run of samples: across a gap in the record (or a pause of
    # the stage) the average would mix forces of another moment and make a drop of its own
    width = max(3, int(round(RUPTURE_SMOOTH_S / max(dt, 1e-9))))
    breaks = np.flatnonzero((np.diff(ins) != 1) | (np.diff(t) > 3.0 * dt)) + 1
    f = np.concatenate([smooth(p.force_n[run], width) for run in np.split(ins, breaks)])
    peak = float(np.max(f))
    thr = max(RUPTURE_MIN_FRAC * abs(peak), RUPTURE_NOISE * p.noise_n)
    out: list[dict[str, float]] = []
    j0 = j1 = 0
    k = 0
    n = len(f)
    since = 0                                 # a top is never looked for inside the last drop

    def top_and_drop(first: int, span: float) -> tuple[int, bool]:
        """The highest force from `first` (at least two samples back over gaps, never inside
        the last drop) to k, and whether the force fell from it by the threshold at its rate
        over `span` (across a gap in the record longer than the span, a slow decline hidden in
        the gap is no rupture)."""
        lo = max(min(first, k - 2), since)
        top = lo + int(np.argmax(f[lo:k + 1]))
        return top, bool(f[top] - f[k] > thr * max(1.0, (t[k] - t[top]) / span))

    while k < n:
        while t[j0] < t[k] - window - 1e-9:
            j0 += 1
        while t[j1] < t[k] - tear - 1e-9:
            j1 += 1
        jm, found = top_and_drop(j0, window)
        span = window
        if not found and tear > window:
            # a tear that ran on: the drop over the travel window, after a climb as long
            jt, fell = top_and_drop(j1, tear)
            climb_from = max(int(np.searchsorted(t, t[jt] - tear)), since)
            if fell and f[jt] - float(np.min(f[climb_from:jt + 1])) >= RUPTURE_CLIMB * thr:
                found, jm, span = True, jt, tear
        if found and cruise[k] and cruise[jm]:
            # the event: follow the fall, through the noise, to its lowest point
            low = kk = k
            while kk + 1 < n and t[kk + 1] - t[low] <= span and \
                    f[kk + 1] <= f[low] + RUPTURE_END_RISE * thr:
                kk += 1
                if f[kk] < f[low]:
                    low = kk
            drop = float(f[jm] - f[low])
            depth = _tear_depth(p.force_n[ins], l[ins], ins, jm, low, width, drop,
                                float(l[ins[jm]]))
            since = low
            if f[low] <= 0.0:
                # a tissue that tore still holds the tip (cutting, friction): a fall to or below
                # zero is the needle pulled back by a moving tissue, not a rupture
                k = low + 1
                continue
            if out and depth - out[-1]["depth_mm"] < RUPTURE_MERGE_MM:
                out[-1]["drop_n"] = max(out[-1]["drop_n"], float(out[-1]["peak_n"] - f[low]))
            else:
                out.append({"depth_mm": depth, "t_s": float(t[jm]), "drop_n": drop,
                            "peak_n": float(f[jm])})
            k = low + 1
            continue
        k += 1
    if len(out) >= 4:
        gaps = np.diff([r["t_s"] for r in out])
        even = RUPTURE_PERIODIC_CV if len(out) >= 5 else RUPTURE_PERIODIC_CV_FOUR
        if float(np.std(gaps)) < even * float(np.mean(gaps)):
            return []        # evenly spaced drops: an oscillation (motion, stick-slip), not layers
    return out


def _tear_depth(force: Array, depth: Array, idx: Array, top: int, low: int, width: int,
                drop: float, at_top: float) -> float:
    """Where a tear happened, for the model that drops at once when the tip reaches it: the
    averaged force peaks a sample before the last intact sample (the average over `width`
    samples already holds part of the drop), and a model that drops there misses the whole
    drop on two samples (measured-like 361: 5 N, 530 noise sd each, the insertion residual 58x
    the noise).  So when one step of the raw force, from `width` samples before the top to
    `width` after the lowest point, carries at least RUPTURE_SHARP of the drop, the tear lies
    between its two samples (their mid-depth); a slower release keeps the top's depth."""
    a, b = max(top - width, 0), min(low + width, len(force) - 1)
    if b <= a:
        return at_top
    falls = np.where(np.diff(idx[a:b + 1]) == 1, force[a:b] - force[a + 1:b + 1], -np.inf)
    i = a + int(np.argmax(falls))
    if not falls[i - a] >= RUPTURE_SHARP * drop:
        return at_top
    return float(0.5 * (depth[i] + depth[i + 1]))


def air_drift(p: Prepared) -> dict[str, float]:
    """Level of the force in the air after exit relative to before contact (N, N/s, noise units)."""
    pre = p.phase == PHASES.index("out_of_tissue")
    post = p.phase == PHASES.index("after_exit")
    if pre.sum() < 5 or post.sum() < 5:
        return {"available": 0.0, "level_n": 0.0, "slope_n_per_s": 0.0, "z": 0.0}
    a, b = float(np.median(p.force_n[pre])), float(np.median(p.force_n[post]))
    dt = float(np.median(p.t_s[post]) - np.median(p.t_s[pre]))
    se = p.noise_n * np.sqrt(np.pi / 2) * np.sqrt(1.0 / pre.sum() + 1.0 / post.sum())
    return {"available": 1.0, "level_n": b - a, "slope_n_per_s": (b - a) / max(dt, 1e-6),
            "z": abs(b - a) / se}


def _lin_sse(cols: Array, y: Array) -> tuple[float, Array]:
    c, *_ = np.linalg.lstsq(cols, y, rcond=None)
    r = y - cols @ c
    return float(r @ r), c


def dwell_decay(p: Prepared, drift_n_per_s: float = 0.0) -> list[dict[str, float]]:
    """Local fits of each dwell's force: constant, line, one and two exponentials."""
    out = []
    for i0, i1 in p.dwells:
        t = p.t_s[i0:i1] - p.t_s[i0]
        if len(t) < 12:
            continue
        y = p.force_n[i0:i1] - drift_n_per_s * t
        one = np.ones_like(t)
        sse_c = float(np.sum((y - y.mean()) ** 2))
        sse_l, _ = _lin_sse(np.column_stack([one, t]), y)
        best1 = (np.inf, 0.0, 0.0)
        for tau in TAU_GRID:
            e = np.exp(-t / tau)
            sse, c = _lin_sse(np.column_stack([one, e]), y)
            if sse < best1[0]:
                best1 = (sse, float(tau), float(c[1]))
        best2 = (np.inf, 0.0, 0.0)
        for a, tf in enumerate(TAU_GRID[:-1]):
            if tf > 1.5:
                break
            for ts in TAU_GRID[a + 4::2]:
                sse, _ = _lin_sse(np.column_stack([one, np.exp(-t / tf), np.exp(-t / ts)]), y)
                if sse < best2[0]:
                    best2 = (sse, float(tf), float(ts))
        n_head = max(3, len(y) // 20)
        f0 = float(np.mean(p.force_n[i0:i0 + n_head]))
        f1 = float(np.mean(y[-n_head:]))
        rel = (f0 - f1) / abs(f0) if abs(f0) > 1e-12 else 0.0
        s2 = p.noise_n ** 2
        out.append({
            "t0_s": float(p.t_s[i0]), "duration_s": float(t[-1]),
            "depth_mm": float(p.stage_mm[i0] - p.surface_mm), "force_start_n": f0,
            "relative_decay": rel, "amplitude_n": best1[2], "amplitude_over_noise":
                abs(best1[2]) / p.noise_n, "tau_one_s": best1[1], "tau_fast_s": best2[1],
            "tau_slow_s": best2[2],
            "chi2_exp_vs_const": (sse_c - best1[0]) / s2,
            "chi2_exp_vs_line": (sse_l - min(best1[0], best2[0])) / s2,
            "resid_rms_over_noise": float(np.sqrt(min(best1[0], best2[0]) / len(y)) / p.noise_n),
        })
    return out


def transient(t: Array, y: Array, sigma: float) -> dict[str, float]:
    """An exponential transient in time on top of a line, ``a + b t + c e^{-t/tau}`` (tau on
    TAU_GRID up to the span of t), against the line alone: chi-square gain (noise units), the
    signed amplitude c (> 0: falling) over the noise, tau and the RMS left over the noise."""
    one = np.ones_like(t)
    line = np.column_stack([one, t])
    sse_l, _ = _lin_sse(line, y)
    best = (sse_l, 0.0, float("nan"))
    for tau in TAU_GRID[TAU_GRID <= max(float(t[-1] - t[0]), TAU_GRID[0])]:
        sse, c = _lin_sse(np.column_stack([line, np.exp(-(t - t[0]) / tau)]), y)
        if sse < best[0]:
            best = (sse, float(c[2]), float(tau))
    return {"chi2": (sse_l - best[0]) / sigma ** 2, "amp_over_noise": best[1] / sigma,
            "tau_s": best[2], "rms_over_noise": float(np.sqrt(best[0] / len(t))) / sigma}


def reversal_transition(p: Prepared) -> dict[str, float] | None:
    """Travel to the zero crossing after the first reversal, and the curvature of the turn-over."""
    l = p.stage_mm - p.surface_mm
    s = np.sign(p.v_mm_s) * (np.abs(p.v_mm_s) > 0.02)
    back = np.nonzero((s < 0) & (l > 0))[0]
    if len(back) < 10:
        return None
    k0 = int(back[0])
    idx = np.arange(k0, len(l))
    idx = idx[(s[idx] < 0) & (l[idx] > 0)]
    d = l[k0] - l[idx]
    keep = d <= REVERSAL_WINDOW_MM
    idx, d = idx[keep], d[keep]
    if len(idx) < 10:
        return None
    y = p.force_n[idx]
    ys = smooth(y, 5)
    neg = np.nonzero(ys < 0)[0]
    cross = float(d[neg[0]]) if len(neg) else float("nan")
    one = np.ones_like(d)
    sse_l, _ = _lin_sse(np.column_stack([one, d]), y)
    best = (np.inf, 0.0)
    for dl in DELTA_GRID:
        sse, c = _lin_sse(np.column_stack([one, d, np.exp(-d / dl)]), y)
        if sse < best[0]:
            best = (sse, float(dl))
    return {"zero_crossing_mm": cross, "delta_mm": best[1],
            "chi2_curve_vs_line": (sse_l - best[0]) / p.noise_n ** 2,
            "force_at_reversal_n": float(ys[0])}


def distinct_speeds(preps: list[Prepared], rel_tol: float = 0.15) -> int:
    """Number of insertion speeds differing by more than ``rel_tol`` relative."""
    sp = sorted(p.speed_mm_s for p in preps if p.speed_mm_s > 0)
    n, last = 0, -np.inf
    for v in sp:
        if v > last * (1.0 + rel_tol):
            n += 1
            last = v
    return n


def period(t: Array, r: Array, lo: float = 0.1, hi: float = 0.6) -> tuple[float, float]:
    """Strongest frequency in [lo, hi] Hz of ``r`` and the share of its variance it carries."""
    from scipy.signal import lombscargle
    if len(t) < 20 or t[-1] - t[0] < 2.0 / hi:
        return float("nan"), 0.0
    freqs = np.linspace(lo, hi, 101)
    rc = r - r.mean()
    pw = lombscargle(t, rc, 2 * np.pi * freqs)
    k = int(np.argmax(pw))
    return float(freqs[k]), float(min(2.0 * pw[k] / (len(t) * np.var(rc) + 1e-30), 1.0))


def collect(preps: list[Prepared]) -> dict[str, object]:
    """All local evidence of a condition (JSON-ready)."""
    per_trial = []
    for p in preps:
        dr = air_drift(p)
        per_trial.append({"trial": p.name, "ruptures": ruptures(p), "air_drift": dr,
                          "dwells": dwell_decay(p, dr["slope_n_per_s"] if dr["z"] > 4 else 0.0),
                          "reversal": reversal_transition(p), "noise_n": p.noise_n})
    return {"per_trial": per_trial, "distinct_speeds": distinct_speeds(preps)}


#: a dwell shows relaxation when the force falls by at least this fraction ...
DWELL_MIN_DECAY = 0.03
#: ... by at least this many noise standard deviations (exponential amplitude) ...
DWELL_MIN_AMP = 4.0
#: ... and an exponential beats a straight line by this chi-square (curvature: not a drift)
DWELL_MIN_CHI2 = 25.0


#: ... and the exponentials leave the dwell at most max(DWELL_MAX_RMS noise, DWELL_MAX_SHARE of
#: the transient): a transient, not a motion line or a stick-slip the exponential only bends
#: through (blind tissue-motion cases: 17-90 noise left of a 38-400 noise "decay", stick-slip
#: 5 of 11; relaxation: at most 1 noise)
DWELL_MAX_RMS = 3.0
DWELL_MAX_SHARE = 0.1


def _transient_explains(d: dict[str, float]) -> bool:
    """One dwell (dwell_decay) holds an exponential transient, either way, that explains it."""
    return d["amplitude_over_noise"] >= DWELL_MIN_AMP and \
        d["chi2_exp_vs_line"] >= DWELL_MIN_CHI2 and \
        d["resid_rms_over_noise"] <= max(DWELL_MAX_RMS, DWELL_MAX_SHARE * d["amplitude_over_noise"])


def dwell_verdict(ev: dict[str, object]) -> tuple[bool, float]:
    """Relaxation seen locally (majority of dwells: the force falls by DWELL_MIN_DECAY in an
    exponential transient that explains the dwell) and the median relative decay."""
    dw = [d for t in ev["per_trial"] for d in t["dwells"]]  # type: ignore[index,union-attr]
    if not dw:
        return False, 0.0
    ok = [d["relative_decay"] >= DWELL_MIN_DECAY and _transient_explains(d) for d in dw]
    return (sum(ok) * 2 > len(ok)), float(np.median([d["relative_decay"] for d in dw]))


def memory_verdict(ev: dict[str, object]) -> tuple[bool, float]:
    """A transient in time in most dwells, as dwell_verdict asks but whichever way the force
    moves, and the median signed amplitude in noise units (> 0: falling).  A relaxing tissue
    recovers (rises) after a sudden unloading (issue 22 item 6), but the base model's own state
    also creeps back in a dwell: alone this is no evidence of relaxation (residual_memory)."""
    dw = [d for t in ev["per_trial"] for d in t["dwells"]]  # type: ignore[index,union-attr]
    if not dw:
        return False, 0.0
    ok = [_transient_explains(d) for d in dw]
    amp = [float(np.sign(d["amplitude_n"])) * d["amplitude_over_noise"] for d in dw]
    return (sum(ok) * 2 > len(ok)), float(np.median(amp))


#: a dwell of the current model's residual shows a memory when a + b t + c e^{-t/tau} beats the
#: line a + b t by this chi-square with |c| at least DWELL_MIN_AMP noise standard deviations,
#: leaving as little as _transient_explains asks ...
RESIDUAL_MEMORY_CHI2 = 25.0
#: ... and settles within the dwell: tau at most this fraction of it.  A tau as long as the dwell
#: is a bend a line and an exponential fit to any slow curvature (measured-like recovery seeds
#: 70-73 and the blind pair#3: tau 0.2-1.1 s; the blind pre-sliding, velocity and drift cases
#: whose residual bends by >= 4 noise: 4.2-5.8 s over their 5.26 s dwells)
RESIDUAL_MEMORY_MAX_TAU = 1.0 / 3.0


def residual_memory(dwells: list[tuple[Array, Array, float]]) -> tuple[int, int, float]:
    """How many dwells (times, current model's residual, noise) hold in their residual a
    transient in time (see transient) that the model leaves, how many were judged, and the
    median signed amplitude of those (noise units, > 0: falling).  The base model's own creep in
    a dwell is in the model, so what is left is a memory the model does not have: at zero
    velocity a direction state (pre-sliding) does not move, a Maxwell memory does."""
    hits, amps = 0, []
    for t, r, sigma in dwells:
        d = transient(t, r, sigma)
        amp = abs(d["amp_over_noise"])
        if d["chi2"] >= RESIDUAL_MEMORY_CHI2 and amp >= DWELL_MIN_AMP and \
                d["tau_s"] <= RESIDUAL_MEMORY_MAX_TAU * float(t[-1] - t[0]) and \
                d["rms_over_noise"] <= max(DWELL_MAX_RMS, DWELL_MAX_SHARE * amp):
            hits += 1
            amps.append(d["amp_over_noise"])
    return hits, len(dwells), float(np.median(amps)) if amps else 0.0


#: the force in the air after the exit shows a drift when its level departs from the tare before
#: contact by at least this many standard errors ...
AIR_DRIFT_MIN_Z = 5.0
#: ... and by at least this many noise standard deviations (a level the fit can see)
AIR_DRIFT_MIN_NOISE = 1.0
#: ... and shows none when every trial's level is within this many standard errors of its tare
AIR_DRIFT_NONE_Z = 3.0


def drift_verdict(ev: dict[str, object]) -> tuple[bool | None, str]:
    """A sensor drift seen in the air (True: the level after the exit departs from the tare in at
    least half of the trials that have both), absent (False: every such trial's level is its
    tare's within AIR_DRIFT_NONE_Z standard errors) or not told (None: no trial has air on both
    sides, or the trials disagree).  In the air the needle feels no tissue, so a level that moved
    is the sensor's whatever form its drift takes in time (a warm-up, a random walk), and a
    record that returns to its tare shows none (model notes section 9)."""
    trials = [t for t in ev["per_trial"]  # type: ignore[union-attr]
              if t["air_drift"]["available"] > 0]  # type: ignore[index]
    if not trials:
        return None, "no trial has air before the contact and after the exit"
    air = [t["air_drift"] for t in trials]
    moved = sum(a["z"] >= AIR_DRIFT_MIN_Z and abs(a["level_n"]) >= AIR_DRIFT_MIN_NOISE *
                float(t["noise_n"]) for a, t in zip(air, trials))
    zs = ", ".join(f"{a['z']:.0f}" for a in air)
    if all(a["z"] < AIR_DRIFT_NONE_Z for a in air):
        return False, (f"the level in the air after the exit is the tare's in every trial "
                       f"({zs} standard errors)")
    return (True if 2 * moved >= len(air) else None), (
        f"the level in the air after the exit departs from the tare in {moved}/{len(air)} "
        f"trials ({zs} standard errors)")


def rupture_count(ev: dict[str, object]) -> list[int]:
    return [len(t["ruptures"]) for t in ev["per_trial"]]  # type: ignore[index,union-attr]
