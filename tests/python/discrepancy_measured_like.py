"""Measured-like insertions for the discrepancy tests, built from the statistics of 331 public
trials (reference_py/MODEL.md §9), not from the library's effect forms.

Tissue: 1-4 layers, each a membrane that tents (force growing as a power of the travel since the
previous rupture, exponent 1.3-2.5) up to its rupture force, then drops; after a rupture the tip
cuts (constant force while advancing) and the shaft carries a friction density per band.  The
friction's direction follows a Dahl state over travelled distance (pre-sliding: the sign needs
millimetres to turn over).  The whole tissue force passes through a generalised Maxwell element
(two branches, ~0.3 s and 2-5 s) on the stress the tissue holds on the needle (cutting and
friction): relaxation is a property of the tissue, present while moving and visible in the dwell;
a membrane's tenting stress is released at its rupture.  The stage meets the tissue 4-16 mm
after it starts; 25 mm stroke at 1-3 mm/s (LSPB), 5.26 s dwell, retraction; 76-100 Hz with
gaps; noise 8-50 mN; tare offset.  ``trial``: another insertion of the same condition (the
same tissue, speed and rate; where the stage starts, the clock, each tear, the tare and the
noise drawn anew), for predicting one trial from another's identification.
Out-of-vocabulary option: stick-slip (a sawtooth on the force while moving).  Options for the
rupture detector: a tear that releases over a travel (``release_mm``) instead of at once, and
the deepest rupture this far before the stop (``stop_rupture_mm``), and smaller
membranes (``rupture_scale`` on their rupture forces).  Option for the dwell evidence: the stage
backs off ``unload_mm`` as the dwell starts, so the relaxing force recovers (rises) after it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from reference_py.discrepancy.io import Trial


@dataclass
class MeasuredCase:
    trials: list[Trial]
    truth: list[np.ndarray]         # noise-free force (N, tare included, recorded sign)
    noise_n: float
    layers: list[int]               # ruptures per trial
    relaxation: bool


def _lspb(t: np.ndarray, t0: float, dist: float, speed: float, acc: float
          ) -> tuple[np.ndarray, np.ndarray]:
    v = min(speed, math.sqrt(abs(dist) * acc))
    tb = v / acc
    dur = abs(dist) / v + tb
    tc = np.clip(t - t0, 0.0, dur)
    pos = np.where(tc < tb, 0.5 * acc * tc ** 2,
                   np.where(tc <= dur - tb, 0.5 * acc * tb ** 2 + v * (tc - tb),
                            abs(dist) - 0.5 * acc * (dur - tc) ** 2))
    vel = np.where((t - t0 <= 0) | (t - t0 >= dur), 0.0,
                   np.where(tc < tb, acc * tc, np.where(tc <= dur - tb, v, acc * (dur - tc))))
    sg = 1.0 if dist >= 0 else -1.0
    return sg * pos, sg * vel, t0 + dur  # type: ignore[return-value]


def make_trial(seed: int, n_layers: int | None = None, relaxation: bool = True,
               presliding: bool = True, noise: float | None = None, speed: float | None = None,
               stick_slip: bool = False, rate_hz: float | None = None,
               release_mm: float = 0.0, stop_rupture_mm: float | None = None,
               rupture_scale: float = 1.0, unload_mm: float = 0.0, trial: int | None = None
               ) -> tuple[Trial, np.ndarray, float, int]:
    """The record of ``seed`` (its Trial, noise-free force with the tare, noise sd in N and
    number of ruptures).  ``trial``: another trial of the same condition — the tissue, speed,
    rate and noise level of ``seed``, but what differs between two insertions of one phantom
    drawn from (seed, trial): where the stage starts (the surface +-1.5 mm), the sample clock,
    each tear's depth (+-0.3 mm sd) and force (x0.85-1.15), the tare and the noise itself.
    None: the record exactly as it always was."""
    rng, other, rate, speed, condition_surface, surface = _stage(seed, trial, rate_hz, speed)
    stroke = 25.0
    dwell = 5.26
    acc = rng.uniform(20.0, 60.0)
    t_pre = rng.uniform(0.5, 1.5)
    total = t_pre + 2 * (stroke / speed + 1.0) + dwell + 2.0
    tt = _clock(rng, rate, total)
    depth_max = stroke - condition_surface  # the condition's: its layers are drawn on it
    if other is not None:
        t_pre = other.uniform(0.5, 1.5)
        tt = _clock(other, rate, t_pre + 2 * (stroke / speed + 1.0) + dwell + 2.0)
    x1, v1, t_end1 = _lspb(tt, t_pre, stroke, speed, acc)
    x2, v2, _ = _lspb(tt, t_end1 + dwell, -stroke, speed, acc)
    x, v = x1 + x2, v1 + v2
    if unload_mm > 0:   # the stage backs off a little as the dwell starts: a sudden unloading
        x3, v3, _ = _lspb(tt, t_end1, -unload_mm, speed, acc)
        x, v = x + x3, v + v3
    l = np.maximum(x - surface, 0.0)
    nl = int(rng.choice([1, 1, 2, 2, 2, 3, 3, 3, 4])) if n_layers is None else n_layers
    # rupture depths spread over the inserted depth, at least 1.5 mm apart
    while True:
        rd = np.sort(rng.uniform(1.5, max(depth_max - 2.0, 2.0), nl))
        if nl == 0 or (np.all(np.diff(rd) > 1.5) and rd[0] > 1.5):
            break
    if stop_rupture_mm is not None and nl:  # after the draw: the seed's other draws stay
        rd[-1] = depth_max - stop_rupture_mm
    peak_force = rng.uniform(2.3, 6.2)
    rupt_f = np.sort(rng.uniform(0.5, 1.0, nl))[::-1] * peak_force if nl else np.array([])
    rupt_f = rupt_f * rupture_scale
    if other is not None and nl:
        # the same membranes, torn a little deeper or shallower, a little harder or softer
        rd = np.sort(np.clip(rd + other.normal(0.0, 0.3, nl), 1.0,
                             max(stroke - surface - 0.5, 1.0)))
        rupt_f = rupt_f * other.uniform(0.85, 1.15, nl)
    gam = rng.uniform(1.3, 2.5, nl)
    cut = rng.uniform(0.15, 0.4) * peak_force
    mu = rng.uniform(0.07, 0.15, nl + 1)        # N/mm per band (band 0 before the first rupture)
    delta = rng.uniform(1.5, 4.0)               # Dahl length (mm): zero crossing ~ 1-3.5 mm
    g_fast, g_slow = rng.uniform(0.3, 0.4), rng.uniform(0.35, 0.5)
    tau_f, tau_s = rng.uniform(0.2, 0.45), rng.uniform(2.0, 5.0)
    edges = np.concatenate([[0.0], rd, [np.inf]])
    f_inst = np.zeros(len(tt))                  # held stress: cutting + friction (relaxes)
    f_mem = np.zeros(len(tt))                   # membrane tenting (released at rupture)
    w = 0.0                                     # Dahl direction state
    deepest = 0.0
    for k in range(len(tt)):
        if k:
            dx = l[k] - l[k - 1]
            if presliding:
                sg = np.sign(dx)
                w = w + (sg - w) * (1.0 - math.exp(-abs(dx) / delta)) if dx != 0 else w
            else:
                w = float(np.sign(v[k])) if v[k] != 0 else w
        deepest = max(deepest, l[k])
        if l[k] <= 0:
            w = 0.0
            continue
        f = 0.0
        # membrane loading of the layer not yet pierced
        j = int(np.searchsorted(rd, deepest, side="right"))
        if j < nl and v[k] >= 0:
            u = (l[k] - edges[j]) / (rd[j] - edges[j])
            if u > 0:
                f_mem[k] = rupt_f[j] * min(u, 1.0) ** gam[j]
        # a tear that runs on while the needle advances: the last pierced membrane lets go
        # over release_mm of travel instead of at once
        if release_mm > 0 and j > 0 and v[k] >= 0 and deepest - rd[j - 1] < release_mm:
            f_mem[k] += rupt_f[j - 1] * (1.0 - (deepest - rd[j - 1]) / release_mm)
        # cutting once through the first layer, while the tip sits at the deepest point reached
        # (advancing or resting: the tissue keeps holding the cut)
        if nl and deepest > rd[0]:
            grip = min((deepest - rd[0]) / release_mm, 1.0) if release_mm > 0 else 1.0
            f += cut * grip * max(w, 0.0)
        # shaft friction per band
        band = np.clip(l[k] - edges[:-1], 0.0, np.diff(edges))
        f += float(mu @ band) * w
        f_inst[k] = f
    if relaxation:
        q1 = q2 = 0.0
        out = np.zeros_like(f_inst)
        for k in range(len(tt)):
            if k:
                dt = tt[k] - tt[k - 1]
                df = f_inst[k] - f_inst[k - 1]
                q1 = q1 * math.exp(-dt / tau_f) + g_fast * df
                q2 = q2 * math.exp(-dt / tau_s) + g_slow * df
            else:
                q1, q2 = g_fast * f_inst[0], g_slow * f_inst[0]
            out[k] = (1.0 - g_fast - g_slow) * f_inst[k] + q1 + q2
        # the elastic part relaxes; scale so the insertion peak stays in the measured range
        f_tis = out + f_mem
    else:
        f_tis = f_inst + f_mem
    f_tis = np.where(l > 0, f_tis, 0.0)        # out of the tissue nothing is held
    if stick_slip:
        phase = (tt * 1.5) % 1.0
        f_tis = f_tis + np.where((np.abs(v) > 0) & (l > 0), 0.25 * peak_force * 0.2 *
                                 (phase - 0.5), 0.0)
    sigma = noise if noise is not None else float(rng.choice([rng.uniform(0.008, 0.013),
                                                              rng.uniform(0.013, 0.05)]))
    tare = rng.uniform(-0.3, 0.3)
    if other is not None:
        tare = other.uniform(-0.3, 0.3)
    truth = f_tis + tare
    meas = truth + (rng if other is None else other).normal(0.0, sigma, len(tt))
    return Trial(f"m{seed}", tt, x, meas), truth, sigma, nl


def _stage(seed: int, trial: int | None, rate_hz: float | None, speed: float | None
           ) -> tuple[np.random.Generator, np.random.Generator | None, float, float, float,
                      float]:
    """make_trial's first draws: the condition's stream and the trial's (None for the record
    itself; the per-trial draws come from their own stream, so the condition's stay in order),
    the rate (Hz), the speed (mm/s), the condition's surface and this trial's (stage mm)."""
    rng = np.random.default_rng(seed)
    other = None if trial is None else np.random.default_rng([seed, trial])
    rate = rate_hz or rng.uniform(76.0, 100.0)
    speed = speed or rng.uniform(1.0, 3.0)
    surface = rng.uniform(4.4, 15.7)
    moved = surface if other is None else float(np.clip(surface + other.uniform(-1.5, 1.5),
                                                        2.0, 18.0))
    return rng, other, rate, speed, surface, moved


def surface_of(seed: int, trial: int | None = None, rate_hz: float | None = None,
               speed: float | None = None) -> float:
    """Where make_trial's stage meets the tissue (stage mm) for the same arguments: what a
    robot registered to the tissue would know (nte-ref estimate --surface)."""
    return _stage(seed, trial, rate_hz, speed)[5]


def _clock(rng: np.random.Generator, rate: float, total: float) -> np.ndarray:
    """Sample times from 0 to past ``total`` s at ``rate`` Hz, each period jittered by +-10 %
    and one in 250 followed by a gap of 0.05-0.3 s."""
    ts, t = [0.0], 0.0
    while t < total:
        t += (1.0 / rate) * rng.uniform(0.9, 1.1)
        if rng.random() < 0.004:
            t += rng.uniform(0.05, 0.3)
        ts.append(t)
    return np.asarray(ts)


def make_case(seed: int, trials: int = 3, **kw: object) -> MeasuredCase:
    out, truths, layers = [], [], []
    sig = 0.0
    for k in range(trials):
        tr, tru, sig, nl = make_trial(seed * 100 + k, **kw)  # type: ignore[arg-type]
        out.append(tr)
        truths.append(tru)
        layers.append(nl)
    return MeasuredCase(out, truths, sig, layers, bool(kw.get("relaxation", True)))


def grade(seed: int, trials: int = 1, **kw: object) -> dict:
    """Run the workflow on one measured-like condition and grade it against the hidden truth."""
    import time

    from reference_py.discrepancy.report import bound_violations
    from reference_py.discrepancy.workflow import run
    case = make_case(seed, trials=trials, **kw)
    t0 = time.perf_counter()
    res = run(case.trials)
    dt = time.perf_counter() - t0

    def rmse(k: int) -> float:
        d = np.concatenate([p - t for p, t in zip(res.predictions[k], case.truth)])
        return float(np.sqrt(np.mean(d ** 2)))
    return {"seed": seed, "named": res.named, "layers": res.layers, "true_layers": case.layers,
            "relaxation": case.relaxation, "truth_before": rmse(0), "truth_after": rmse(-1),
            "noise": case.noise_n, "unexplained": bool(res.unexplained),
            "violations": bound_violations(res), "runtime_per_trial_s": dt / trials,
            "validation_shrink": res.validation.get("shrink")}


def phantom_trial(name: str, seed: int, **kw: object) -> tuple[Trial, np.ndarray, float, int]:
    """One record of the realistic phantom (reference_py/sim/phantom.py, a preset or "lab"):
    the trial as recorded, the noise-free force with the sensor's offset and drift (what the
    workflow's prediction, tare included, should follow), the noise and the ruptures of the first
    insertion."""
    from reference_py.sim.phantom import simulate_phantom
    ph = simulate_phantom(name, seed=seed, **kw)  # type: ignore[arg-type]
    fs = float(ph.spec.sensor.force_sign)
    truth = ph.force_true_n + fs * (ph.spec.sensor.offset_n + ph.truth["samples"]["drift_n"])
    return (Trial(f"{name}-{seed}", ph.t_s, ph.depth_mm, ph.force_n, ph.velocity_mm_s), truth,
            float(ph.spec.sensor.noise_n), int(ph.truth["ruptures_per_cycle"][0]))


def grade_phantom(name: str, seed: int, **kw: object) -> dict:
    """Run the workflow on one phantom record and grade it against the phantom's truth."""
    import time

    from reference_py.discrepancy.report import bound_violations
    from reference_py.discrepancy.workflow import run
    tr, truth, sig, nl = phantom_trial(name, seed, **kw)
    t0 = time.perf_counter()
    res = run([tr])
    dt = time.perf_counter() - t0

    def rmse(k: int) -> float:
        return float(np.sqrt(np.mean((res.predictions[k][0] - truth) ** 2)))
    return {"seed": seed, "phantom": name, "named": res.named, "layers": res.layers,
            "true_layers": [nl], "relaxation": True, "truth_before": rmse(0),
            "truth_after": rmse(-1), "noise": sig, "unexplained": bool(res.unexplained),
            "violations": bound_violations(res), "runtime_per_trial_s": dt,
            "validation_shrink": None}


def _job(a: tuple) -> dict:
    seed, trials, kw = a
    if "phantom" in kw:
        kw = dict(kw)
        return grade_phantom(str(kw.pop("phantom")), seed, **kw)
    return grade(seed, trials, **kw)


def campaign(n: int = 40, trials: int = 1, workers: int = 2, **kw: object) -> list[dict]:
    import multiprocessing as mp
    import os
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    with mp.get_context("spawn").Pool(workers) as pool:
        return list(pool.imap_unordered(_job, [(20000 + s, trials, kw) for s in range(n)]))


def summary(rows: list[dict]) -> str:
    relax = [r for r in rows if r["relaxation"]]
    lines = [
        f"conditions {len(rows)}",
        f"relaxation named: {sum('dwell_relaxation' in r['named'] for r in relax)}/{len(relax)}",
        f"layer count right: {sum(r['layers'] == r['true_layers'] for r in rows)}/{len(rows)}",
        "RMSE to truth shrink: median {:.2f}".format(
            np.median([1 - r['truth_after'] / r['truth_before'] for r in rows])),
        "final RMSE to truth / noise: median {:.2f}".format(
            np.median([r['truth_after'] / r['noise'] for r in rows])),
        f"unexplained fired: {sum(r['unexplained'] for r in rows)}/{len(rows)}",
        f"bound violations: {sum(bool(r['violations']) for r in rows)}",
        "run time per trial: median {:.2f} s, max {:.2f} s".format(
            np.median([r['runtime_per_trial_s'] for r in rows]),
            max(r['runtime_per_trial_s'] for r in rows)),
    ]
    return "\n".join(lines)


#: phantom presets of the campaign (every preset, one seed each) and lab seeds
PHANTOM_PRESETS = ("skin", "skin-on-muscle", "artery-filled", "muscle", "skin-incision")


def phantom_campaign(lab_seeds: int = 10, workers: int = 2) -> list[dict]:
    """Every phantom preset (seed 2) and ``lab_seeds`` lab records (seeds 100, 101, ...)."""
    import multiprocessing as mp
    import os
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    jobs = [(2, 1, {"phantom": name}) for name in PHANTOM_PRESETS] + \
        [(100 + s, 1, {"phantom": "lab"}) for s in range(lab_seeds)]
    with mp.get_context("spawn").Pool(workers) as pool:
        return list(pool.imap(_job, jobs))


if __name__ == "__main__":
    import sys
    if sys.argv[1:2] == ["phantom"]:
        rows = phantom_campaign(int(sys.argv[2]) if len(sys.argv) > 2 else 10)
        for r in rows:
            print(f"{r['phantom']:>15} seed {r['seed']:>3}: {','.join(r['named'])}; layers "
                  f"{r['layers']} (true {r['true_layers']}); RMSE to truth "
                  f"{r['truth_before']:.3f} -> {r['truth_after']:.3f} N (noise {r['noise']:.3f})")
        print(summary(rows))
        sys.exit(0)
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 40
    tr = int(sys.argv[2]) if len(sys.argv) > 2 else 1
    print(summary(campaign(n, tr)))
