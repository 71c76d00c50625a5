"""The realistic phantom calibrated on measurements: the measured statistics, the presets and
the random ``lab`` tissue.

The statistics of 331 public robotic insertions (p10 / median / p90, rupture counts as a
distribution; PHANTOM.md) are the targets: ``lab_spec(seed)`` draws a tissue, motion and sensor
from them and scales the drawn tissue so that its noise-free record meets three drawn figures
(insertion peak, dwell decay, retraction minimum).  The presets are fixed physical tissues.
How close the lab records come is measured by :mod:`reference_py.sim.phantom_stats`.
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, Sequence

import numpy as np

from ..fmath import Array
from .motion import Motion, record_duration, stage_motion
from .spec import Layer, PhantomSpec, Sensor, Tissue
from .tissue import tissue_force

# ---------------------------------------------------------------------------------------------
# The measured statistics (p10 / median / p90 of 331 public trials; ruptures as a distribution).
# The inverse CDFs below pass through those three quantiles; the end points (p = 0, 1) are ours.
MEASURED: dict[str, Any] = {
    "rate_hz": (76.0, 100.0, 100.0),
    "noise_mn": (7.6, 12.8, 51.0),
    "surface_mm": (4.4, 6.1, 15.7),
    "peak_n": (2.3, 4.7, 6.2),
    "dwell_decay_pct": (28.0, 38.0, 49.0),
    "retraction_min_n": (-2.4, -1.6, -0.9),
    "turnover_mm": (1.0, 2.6, 3.5),
    "dwell_tau_fast_s": (0.3,),          # two-exponential fits of the dwell: fast ~0.3 s,
    "dwell_tau_slow_s": (2.0, 5.0),      # slow 2-5 s (a range, not quantiles)
    "ruptures": {0: 0.03, 1: 0.27, 2: 0.32, 3: 0.28, 4: 0.07, 5: 0.03},
    "drop_n": (0.5, 3.0),
}
_QUANTILES: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {
    "rate_hz": ((0.0, 0.1, 0.4, 1.0), (75.0, 76.0, 100.0, 100.0)),
    "noise_n": ((0.0, 0.1, 0.5, 0.8, 0.9, 1.0), (0.007, 0.0076, 0.0128, 0.020, 0.050, 0.055)),
    "surface_mm": ((0.0, 0.1, 0.5, 0.75, 0.9, 1.0), (4.0, 4.4, 6.1, 9.0, 15.7, 16.0)),
    "peak_n": ((0.0, 0.1, 0.5, 0.9, 1.0), (2.0, 2.3, 4.7, 6.2, 6.6)),
    "dwell_decay": ((0.0, 0.1, 0.5, 0.9, 1.0), (0.25, 0.28, 0.38, 0.49, 0.52)),
    "retraction_min_n": ((0.0, 0.1, 0.5, 0.9, 1.0), (-2.7, -2.4, -1.6, -0.9, -0.8)),
    "turnover_mm": ((0.0, 0.1, 0.5, 0.9, 1.0), (0.8, 1.0, 2.6, 3.5, 3.8)),
}
# an exponential Dahl state turned from +1 crosses 0 after delta_p ln 2 of travel; the force of a
# lab record (relaxed grip, Maxwell and cutting terms) crosses after 0.71 / 0.74 / 0.86 delta_p
# (p10 / median / p90 of lab seeds 1-60, noise-free), so the drawn turn-over is divided by 0.74
_TURN_TO_DAHL = 1.0 / 0.74


def draw_measured(name: str, rng: np.random.Generator, u: float | None = None) -> float:
    """One draw from the piecewise-linear inverse CDF through the measured quantiles (at the
    probability u if given)."""
    p, v = _QUANTILES[name]
    return float(np.interp(rng.uniform() if u is None else u, p, v))


# a stiffer tissue pushes harder in and pulls harder out: the peak and the depth of the
# retraction minimum are drawn with this rank correlation (Gaussian copula)
_PEAK_RETRACTION_CORR = 0.7


def _correlated_uniforms(rng: np.random.Generator, corr: float) -> tuple[float, float]:
    z1, z2 = rng.normal(size=2)
    z2 = corr * z1 + math.sqrt(1.0 - corr * corr) * z2
    return tuple(0.5 * (1.0 + math.erf(z / math.sqrt(2.0))) for z in (z1, z2))  # type: ignore


# ---------------------------------------------------------------------------------------------
# Presets: fixed physical tissues (the speed, rate and noise can be overridden).
def _skin(thick: float, R: float, tent: float) -> Layer:
    return Layer("skin", thick, R, tent, 0.45, 0.07)


PRESETS: dict[str, PhantomSpec] = {
    "skin": PhantomSpec("skin", Tissue((
        _skin(3.0, 3.2, 6.0),
        Layer("subcutis", 40.0, 0.0, 1.0, 0.35, 0.15),))),
    "skin-on-muscle": PhantomSpec("skin-on-muscle", Tissue((
        _skin(2.5, 2.8, 5.0),
        Layer("muscle", 40.0, 1.8, 2.5, 0.4, 0.16),))),
    "artery-filled": PhantomSpec("artery-filled", Tissue((
        _skin(2.5, 2.5, 5.0),
        Layer("artery wall (near)", 2.0, 1.6, 2.0, 0.35, 0.14),
        Layer("lumen (filled)", 2.5, 0.0, 1.0, 0.07, 0.03, 0.3),
        Layer("artery wall (far)", 1.5, 1.6, 1.5, 0.35, 0.14),
        Layer("muscle", 40.0, 1.5, 1.5, 0.4, 0.15),)), surface_mm=5.0),
    "muscle": PhantomSpec("muscle", Tissue((
        Layer("muscle", 40.0, 2.2, 4.0, 0.5, 0.2),))),
    "skin-incision": PhantomSpec("skin-incision", Tissue((
        Layer("skin (incised)", 2.5, 0.0, 1.0, 0.4, 0.11),
        Layer("muscle", 40.0, 0.0, 1.0, 0.45, 0.18),))),
}
LAB = "lab"


# ---------------------------------------------------------------------------------------------
# The lab generator: a random stack drawn so that its records follow the measured statistics.
_RUPTURE_P = np.array([MEASURED["ruptures"][k] for k in range(6)])


def lab_spec(seed: int) -> PhantomSpec:
    """A random tissue, motion and sensor drawn from the measured distributions (seeded).

    The layer stack, speed, surface, rate and noise are drawn directly.  Three targets drawn from
    the measured distributions (insertion peak, dwell decay, retraction minimum) then fix three
    physical scales of the drawn tissue: a common factor on every elastic force (membranes,
    cutting, friction), the strength of the Maxwell element and the retraction friction ratio.
    All three enter the tissue force linearly, so they are solved from one noise-free run.
    """
    rng = np.random.default_rng([seed, 0x1AB])
    u_peak, u_ret = _correlated_uniforms(rng, _PEAK_RETRACTION_CORR)
    targets = {"peak_n": draw_measured("peak_n", rng, u_peak),
               "dwell_decay": draw_measured("dwell_decay", rng),
               "retraction_min_n": draw_measured("retraction_min_n", rng, 1.0 - u_ret)}
    speed = float(rng.choice([1.0, 2.0, 3.0]))
    surface = draw_measured("surface_mm", rng)
    nr = int(rng.choice(6, p=_RUPTURE_P))
    room = 25.0 - surface - 0.8                    # tip travel available for the stack
    tents = [float(rng.uniform(3.0, 6.0))] + [float(rng.uniform(1.0, 3.0)) for _ in range(nr - 1)]
    cuts = [float(rng.uniform(0.8, 3.5)) for _ in range(nr)]
    need = sum(tents) + sum(cuts) - cuts[-1] + 0.5 if nr else 0.0
    shrink = min(1.0, room / need) if nr else 1.0
    tents = [u * shrink for u in tents]
    cuts = [c * shrink for c in cuts]
    layers = []
    names = ["skin"] + ["wall" if rng.uniform() < 0.5 else "fascia" for _ in range(nr - 1)]
    drops: list[float] = []
    for i in range(nr):
        c = float(rng.uniform(0.2, 0.8))
        mu = float(rng.uniform(0.08, 0.18))
        drops.append(float(rng.uniform(0.6, min(2.5, 0.4 * targets["peak_n"]))))
        thick = tents[i] + cuts[i]
        layers.append(Layer(names[i], thick, 1.0, tents[i], c, mu, float(rng.uniform(0.6, 1.4))))
    if nr == 0:   # an incision or a membrane-free stack: cutting and friction only
        layers.append(Layer("incised skin", float(rng.uniform(1.5, 3.0)), 0.0, 1.0,
                            float(rng.uniform(0.2, 0.8)), float(rng.uniform(0.08, 0.18))))
    # what lies beyond: a thick layer (its membrane, if any, is not reached within the stroke)
    c_last = layers[-1].cutting_n
    layers.append(Layer("deep", 60.0, 0.0, 1.0, c_last * float(rng.uniform(0.8, 1.3)),
                        float(rng.uniform(0.08, 0.18)), float(rng.uniform(0.6, 1.4))))
    tau1 = float(np.exp(rng.uniform(np.log(0.2), np.log(0.45))))
    tau2 = float(np.exp(rng.uniform(np.log(2.0), np.log(5.0))))
    share = float(rng.uniform(0.35, 0.6))               # fast branch's share of the strength
    tissue = Tissue(tuple(layers), maxwell_n_mm=(0.05 * share, 0.05 * (1.0 - share)),
                    maxwell_tau_s=(tau1, tau2),
                    relax_g=(float(rng.uniform(0.05, 0.15)), float(rng.uniform(0.1, 0.2))),
                    rate_exponent=float(rng.uniform(0.4, 0.7)),
                    tip_mm=float(rng.uniform(2.0, 4.0)),
                    presliding_mm=_TURN_TO_DAHL * draw_measured("turnover_mm", rng),
                    retraction_ratio=float(rng.uniform(0.6, 1.3)),
                    unload_mm=float(rng.uniform(0.3, 0.8)))
    sensor = Sensor(rate_hz=draw_measured("rate_hz", rng), noise_n=draw_measured("noise_n", rng),
                    offset_n=float(rng.normal(0.0, 0.005)),
                    drift_n_s=float(rng.normal(0.0, 3e-4)),
                    walk_n_sqrt_s=float(rng.uniform(0.0, 1e-3)))
    spec = PhantomSpec(f"lab-{seed}", tissue, surface, Motion(speeds_mm_s=(speed,)), sensor)
    for _ in range(2):     # rupture forces from the drops, then the scales; twice (they interact)
        spec = _calibrate(_set_ruptures(spec, drops), targets)
    return spec


def _set_ruptures(spec: PhantomSpec, drops: Sequence[float]) -> PhantomSpec:
    """Rupture forces that give the drawn drops: the membrane's release less what the tip gains
    at once in the new layer (more cutting force, friction and shear on the recoiled length)."""
    ti = spec.tissue
    v = max(spec.motion.speeds_mm_s[0], 1e-9)
    shear = sum(ti.maxwell_n_mm) * v ** ti.rate_exponent        # steady Maxwell stress, N/mm
    layers = list(ti.layers)
    prev_c = 0.0
    for i, drop in enumerate(drops):
        ly = layers[i]
        R = drop + max(ly.cutting_n - prev_c, 0.0) + (ly.friction_n_mm + shear * ly.viscous) * \
            ly.tent_mm
        layers[i] = replace(ly, rupture_n=R)
        prev_c = ly.cutting_n
    return replace(spec, tissue=replace(ti, layers=tuple(layers)))


def _calibrate(spec: PhantomSpec, targets: dict[str, float]) -> PhantomSpec:
    """Scale the cutting and friction forces (a), the Maxwell strength (b) and the retraction
    friction ratio (rho) so that the noise-free record has the target insertion peak, dwell decay
    and retraction minimum; the membranes keep their drawn rupture forces (so the drops keep
    their drawn sizes).  The tissue force is linear in a, b and a*rho, so one unit run gives the
    components; a and rho stay within _A and _RHO (a target beyond them is not reached)."""
    probe = replace(spec, sensor=replace(spec.sensor, rate_hz=100.0, jitter=0.0, gaps=0))
    t = np.arange(int(record_duration(probe.motion) * 100.0) + 1) / 100.0
    x, _, phase, cycle, marks = stage_motion(t, probe.motion)
    comp, _ = tissue_force(probe, t, x, cycle)
    rho0 = spec.tissue.retraction_ratio
    Mm = comp["membrane"]
    E_pos = comp["cutting"] + comp["friction_pos"]
    E_neg = comp["friction_neg"] / rho0                # at rho = 1
    V = comp["viscous"]
    m = marks[0]
    w0 = (t >= m["insertion_end_s"]) & (t <= m["insertion_end_s"] + 0.1)
    w1 = (t >= m["retraction_start_s"] - 0.1) & (t <= m["retraction_start_s"])
    def start_drop(x: Array) -> tuple[float, float]:
        return float(np.mean(x[w0])), float(np.mean(x[w0]) - np.mean(x[w1]))

    (M0, dM), (E0, dE), (V0, dV) = start_drop(Mm), start_drop(E_pos), start_drop(V)
    D, P, M = targets["dwell_decay"], targets["peak_n"], targets["retraction_min_n"]
    ins = (phase == 1) & (t <= m["insertion_end_s"] - 0.05)
    ret = phase == 3

    def visc(a: float) -> float:                       # b from the decay, given a
        return max(D * (M0 + a * E0) - dM - a * dE, 0.0) / max(dV - D * V0, 1e-9)

    def peak(a: float) -> float:
        return float(np.max(Mm[ins] + a * E_pos[ins] + visc(a) * V[ins]))

    a = _bisect(peak, P, *_A, increasing=True)
    b = visc(a)

    def rmin(rho: float) -> float:
        return float(np.min(Mm[ret] + a * (E_pos[ret] + rho * E_neg[ret]) + b * V[ret]))

    rho = _bisect(rmin, M, *_RHO, increasing=False)
    ti = spec.tissue
    layers = tuple(replace(ly, cutting_n=a * ly.cutting_n, friction_n_mm=a * ly.friction_n_mm)
                   for ly in ti.layers)
    tissue = replace(ti, layers=layers, maxwell_n_mm=tuple(b * x for x in ti.maxwell_n_mm),
                     retraction_ratio=rho)
    return replace(spec, tissue=tissue)


def _bisect(fun: Any, goal: float, lo: float, hi: float, increasing: bool) -> float:
    """x in [lo, hi] with fun(x) = goal for a monotone fun (the nearer bound if out of reach)."""
    sgn = 1.0 if increasing else -1.0
    if sgn * (fun(lo) - goal) >= 0.0:
        return lo
    if sgn * (fun(hi) - goal) <= 0.0:
        return hi
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if sgn * (fun(mid) - goal) < 0.0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


_A = (0.1, 5.0)     # bounds of the cutting and friction scale
_RHO = (0.3, 3.0)   # bounds of the retraction / insertion friction ratio
