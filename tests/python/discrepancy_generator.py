"""Blind-test generator for the discrepancy workflow (tests only; the workflow never imports it).

An independent examiner: the base force model is integrated here by its own scheme (an exact
exponential step of the linear state equation, not the library's RK3), and every hidden effect
comes in two or three physically different *forms*, drawn at random.  Each form is marked
``library=True`` when the workflow's effect library (reference_py/discrepancy/effects.py and its
multi-layer base) contains that exact functional form, and ``library=False`` ("held out") when it
does not; the blind confusion is reported per form and restricted to held-out forms.

Forms (magnitudes from reference_py/MODEL.md §8-§9):

dwell_relaxation (the measured force falls by 28-49 % over a 5 s dwell)
  prony_dwell    library: the force held at the stop relaxes during the dwell only, two
                 exponentials (tau 0.2-0.4 s and 2-5 s).
  maxwell_total  held out: quasi-linear viscoelasticity on the whole tissue force, all the time
                 (moving too): F = G * dF_e, G(t) = 1 - rho sum_k w_k (1 - e^{-t/tau_k}), two
                 branches (0.2-0.4 s, 2-5 s); the tissue keeps relaxing after the reversal.
  power_law      held out: the same hereditary integral with a fractional (power-law) kernel
                 G(t) = 1 - rho (1 - (1 + t/t0)^-a), a 0.4-0.8, t0 0.02-0.2 s (a 14-branch
                 Prony approximation, < 0.5 % of G); long memory, slower than any exponential.
  In every form the friction holds at rest (static friction) before relaxing; rho is solved
  so that the first trial's dwell loses the drawn fraction over min(dwell, 5 s).
reversal_presliding (the friction needs 1-3.5 mm of travel to cross zero after a reversal)
  dahl           held out: Dahl friction state over travelled distance, dm/dx = (1 - m sgn v)^i
                 / delta, exponent i 0.7-1.5, continuous from +1 to -1 (the library restarts
                 from 0); delta solved from the drawn zero-crossing distance.
  lugre          held out: LuGre bristle z (mm), dz/dt = v - |v| z / z_ss(v), z_ss with a
                 Stribeck rise at low speed (x1-1.5 below 0.2-1 mm/s), m = (z + tau_d dz/dt)/d_b.
  elastoplastic  held out: Dupont's elasto-plastic bristle: purely elastic (linear in travel)
                 until the break-away deflection (30-80 % of z_ss), a smooth transition, then
                 sliding; zero crossing at z_ss.
  At rest the friction term follows the base model's convention (zero); the state is kept.
velocity_friction (shaft friction density grows with speed; PVC 34/59/80 N/m at 1/3/9 mm/s)
  linear         library: density sigma2 + b |v| (b v l).
  power          held out: density sigma2 (|v| / v_ref)^n, n 0.3-0.6.
  stribeck       held out: density sigma2 (1 + (r_s - 1) e^{-(v/v_s)^2} + k |v|/v_ref) /
                 (value at v_ref): falls then rises with speed.
  Always 2-3 trials at speeds at least 2.5x apart; the density ratio between the extreme speeds
  is 1.3-2.4 (redrawn otherwise).
direction_asymmetry (retraction friction differs from insertion friction)
  constant       library: retraction friction x r, r 1.25-1.6 or 0.6-0.8.
  depth          held out: ratio grows with depth, r(l) = 1 + (r_d - 1) (l / l_max)^g,
                 r_d 1.4-2.0 or 0.4-0.7, g 0.7-1.5.
layer_puncture (1-3 extra membranes: tenting load up to the rupture force, then a drop)
  exponential    library: F e^{(l - d)/w_e}, w_e = span/k 0.25-2 mm (the library's layer effect).
  linear         library: F u over the tenting span, u = (l - d + w)/w (the multi-layer base's
                 polynomial loading contains it).
  cubic_membrane held out: F u^3 (point-loaded hyperelastic membrane, Foppl-Hencky).
  Drops 15-60 % of the base insertion peak and >= 10x the noise, 3-25 mm below the surface,
  >= 3 mm apart, spans 1.5-5 mm, released over 0.1 mm of travel.
sensor_drift (bias changing after tare; excursion 3-8x the noise, >= 6 mN)
  linear         library: c t.
  random_walk    held out: integrated white noise (10 Hz knots, interpolated), scaled.
  warmup         held out: D (1 - e^{-t/tau}), tau 3-20 s (sensor warming up).
tissue_motion (breathing, 0.2-0.33 Hz, 0.5-2.5 mm)
  sinusoid       library: a sin(2 pi f t + phi).
  respiratory    held out: Lujan's breathing waveform a (cos^{2n}(pi f t + phi) - mean), n 2-3:
                 asymmetric, with end-expiration pauses.
  irregular      held out: a sinusoid whose period and amplitude change cycle to cycle (+-15 %).

Kinds of cases: "EFFECT/FORM" for each form, "none" (base only), "pair" (dwell_relaxation +
reversal_presliding, forms drawn at random), and "stick_slip" (out of the vocabulary: a stick-slip
sawtooth on the force while inserting, 0.3-1.5 s period, 5-15 % of the peak and >= 10x the noise)
which must come out "unexplained".

Base and recordings: Model II from one of the project's five presets (each parameter perturbed by
x e^{+-0.3}), scaled to the paper's 0.15-0.4 N peak or the measured 2.3-6.2 N; surface 4-16 mm
after the stage start; 12-35 mm in the tissue at 1-10 mm/s (LSPB, 20-100 mm/s^2), a 4-6.5 s dwell,
retraction to 0; 76-1000 Hz with jitter and gaps (at most ~30 000 samples a trial); noise 2-10 mN
(paper scale) or 8-50 mN (measured scale); tare offset +-50 mN; velocity column in half the trials;
1-3 trials per case (2-3 at several speeds for velocity friction).
"""
from __future__ import annotations

import math
import re
import zlib
from dataclasses import dataclass, field

import numpy as np

from reference_py.discrepancy.io import Trial
from reference_py.params import PRESETS, ParamSet

EFFECTS = ("dwell_relaxation", "reversal_presliding", "velocity_friction", "direction_asymmetry",
           "layer_puncture", "sensor_drift", "tissue_motion")
PAIR = ("dwell_relaxation", "reversal_presliding")
OOV = "stick_slip"


@dataclass(frozen=True)
class Form:
    effect: str
    name: str
    library: bool       # True: the workflow's library has this exact functional form
    doc: str


FORMS: dict[str, tuple[Form, ...]] = {
    "dwell_relaxation": (
        Form("dwell_relaxation", "prony_dwell", True, "two exponentials on the held force, dwell"),
        Form("dwell_relaxation", "maxwell_total", False, "two-branch QLV on the total force"),
        Form("dwell_relaxation", "power_law", False, "fractional kernel QLV on the total force")),
    "reversal_presliding": (
        Form("reversal_presliding", "dahl", False, "Dahl state over distance, +1 -> -1"),
        Form("reversal_presliding", "lugre", False, "LuGre bristle with Stribeck and damping"),
        Form("reversal_presliding", "elastoplastic", False, "Dupont elasto-plastic bristle")),
    "velocity_friction": (
        Form("velocity_friction", "linear", True, "viscous density b|v|"),
        Form("velocity_friction", "power", False, "density ~ |v|^n"),
        Form("velocity_friction", "stribeck", False, "falls then rises with speed")),
    "direction_asymmetry": (
        Form("direction_asymmetry", "constant", True, "retraction friction x r"),
        Form("direction_asymmetry", "depth", False, "ratio grows with depth")),
    "layer_puncture": (
        Form("layer_puncture", "exponential", True, "F e^{(l-d)/w} then drop"),
        Form("layer_puncture", "linear", True, "linear tenting then drop"),
        Form("layer_puncture", "cubic_membrane", False, "cubic (membrane) tenting then drop")),
    "sensor_drift": (
        Form("sensor_drift", "linear", True, "c t"),
        Form("sensor_drift", "random_walk", False, "integrated white noise"),
        Form("sensor_drift", "warmup", False, "exponential warm-up")),
    "tissue_motion": (
        Form("tissue_motion", "sinusoid", True, "sinusoidal displacement"),
        Form("tissue_motion", "respiratory", False, "Lujan cos^2n breathing waveform"),
        Form("tissue_motion", "irregular", False, "cycle-to-cycle varying period/amplitude")),
}


def form_of(effect: str, name: str) -> Form:
    for f in FORMS[effect]:
        if f.name == name:
            return f
    raise KeyError(f"{effect}/{name}")


def kinds() -> list[str]:
    """Every kind of blind case: one per (effect, form), none, the pair, the out-of-vocabulary."""
    return [f"{e}/{f.name}" for e in EFFECTS for f in FORMS[e]] + ["none", "pair", OOV]


def kind_effects(kind: str) -> tuple[str, ...]:
    """The hidden vocabulary effects of a kind (empty for none and stick-slip)."""
    if kind == "pair":
        return PAIR
    if kind in ("none", OOV):
        return ()
    return (kind.split("/")[0],)


@dataclass
class Case:
    kind: str
    trials: list[Trial]
    effects: tuple[str, ...]       # hidden vocabulary effects
    forms: dict[str, str]          # effect -> form name
    held_out: dict[str, bool]      # effect -> True when its form is not in the library
    truth: list[np.ndarray]        # noise-free force with the hidden effects (N, incl. tare)
    base: list[np.ndarray]         # noise-free force of the base model alone (N, incl. tare)
    support: list[np.ndarray]      # samples where a hidden effect changes the force (> 0.5 mN)
    info: dict = field(default_factory=dict)


# ------------------------------------------------------------------------------------------
# Recordings: trajectories and sample times
# ------------------------------------------------------------------------------------------
def _lspb(t: np.ndarray, dist: float, speed: float, acc: float) -> tuple[np.ndarray, np.ndarray,
                                                                          float]:
    v = min(speed, math.sqrt(dist * acc))
    tb = v / acc
    dur = dist / v + tb
    tc = np.clip(t, 0.0, dur)
    pos = np.where(tc < tb, 0.5 * acc * tc ** 2,
                   np.where(tc <= dur - tb, 0.5 * acc * tb ** 2 + v * (tc - tb),
                            dist - 0.5 * acc * (dur - tc) ** 2))
    vel = np.where((t <= 0) | (t >= dur), 0.0,
                   np.where(tc < tb, acc * tc, np.where(tc <= dur - tb, v, acc * (dur - tc))))
    return pos, vel, dur


def _times(rng: np.random.Generator, total: float, rate: float) -> np.ndarray:
    """Sample times at ``rate`` Hz with +-10 % jitter and ~0.2 gaps per second of 0.05-0.3 s."""
    n = int(total * rate * 1.1) + 10
    dt = rng.uniform(0.9, 1.1, n) / rate
    gaps = rng.random(n) < 0.2 / rate
    dt = dt + np.where(gaps, rng.uniform(0.05, 0.3, n), 0.0)
    t = np.concatenate([[0.0], np.cumsum(dt)])
    return t[t <= total]


@dataclass
class _Motion:
    t: np.ndarray
    stage: np.ndarray        # stage position (mm)
    v: np.ndarray            # stage velocity (mm/s)
    surface: float           # stage position of the surface (mm)
    speed: float
    dwell: tuple[float, float]


def _trajectory(rng: np.random.Generator, surface: float, depth: float, speed: float,
                dwell: float, rate: float) -> _Motion:
    acc = rng.uniform(20.0, 100.0)
    dist = surface + depth
    rest0, rest1 = rng.uniform(0.5, 1.5), rng.uniform(1.0, 3.0)
    _, _, move = _lspb(np.zeros(1), dist, speed, acc)
    total = rest0 + 2 * move + dwell + rest1
    rate = min(rate, 30000.0 / total)
    t = _times(rng, total, rate)
    p1, v1, _ = _lspb(t - rest0, dist, speed, acc)
    p2, v2, _ = _lspb(t - rest0 - move - dwell, dist, speed, acc)
    return _Motion(t, p1 - p2, v1 - v2, surface, speed, (rest0 + move, rest0 + move + dwell))


# ------------------------------------------------------------------------------------------
# The base model, integrated independently of the library (exact exponential step)
# ------------------------------------------------------------------------------------------
def base_state(pp: ParamSet, t: np.ndarray, l: np.ndarray, substeps: int = 4) -> np.ndarray:
    """z along depth l (>= 0): dz/dt = l (beta - sigma0 z / g(l)) is linear in z; each sub-step
    (depth at its midpoint, linear within a sample) is solved exactly, z -> z* + (z - z*)e^{-lam h}
    with lam = l sigma0 / g, z* = beta g / sigma0.  z resets to 0 out of the tissue."""
    n = len(t)
    if n < 2:
        return np.zeros(n)
    dt = np.diff(t)
    la, dl = l[:-1], np.diff(l)
    a_tot, c_tot = np.ones(n - 1), np.zeros(n - 1)
    for j in range(substeps):
        lm = np.maximum(la + dl * ((j + 0.5) / substeps), 0.0)
        g = pp.f1 + pp.f2 * np.exp(-pp.alpha * lm)
        a = np.exp(-lm * pp.sigma0 / g * dt / substeps)
        c = pp.beta * g / pp.sigma0 * (1.0 - a)
        a_tot, c_tot = a * a_tot, a * c_tot + c
    inside = l[1:] > 0.0
    a_l = np.where(inside, a_tot, 0.0).tolist()
    c_l = np.where(inside, c_tot, 0.0).tolist()
    z = [0.0] * n
    zk = 0.0
    for k in range(n - 1):
        zk = a_l[k] * zk + c_l[k]
        z[k + 1] = zk
    return np.asarray(z)


def base_terms(pp: ParamSet, t: np.ndarray, l: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(elastic force, friction magnitude) of Model II along depth l: f = el + s fr."""
    l = np.maximum(l, 0.0)
    z = base_state(pp, t, l)
    e = np.exp(-pp.alpha * l)
    g = pp.f1 + pp.f2 * e
    return pp.sigma0 * z * l, l * (pp.sigma1 * e * (pp.beta - pp.sigma0 * z / g) + pp.sigma2)


def _params(rng: np.random.Generator) -> tuple[str, ParamSet]:
    name = str(rng.choice(sorted(PRESETS)))
    b = PRESETS[name].params
    k = lambda: float(np.exp(rng.uniform(-0.3, 0.3)))  # noqa: E731
    while True:
        pp = ParamSet(b.sigma0 * k(), b.sigma1 * k(), b.sigma2 * k(), b.f1 * k(), b.f2 * k(),
                      b.alpha * k(), b.beta * k())
        if pp.g_min() > 0.2 * abs(b.f1):
            return name, pp


def _scaled(pp: ParamSet, k: float) -> ParamSet:
    """Force scaled by k exactly: sigma0, sigma1, sigma2, f1, f2 all x k (b(l), z unchanged)."""
    return ParamSet(pp.sigma0 * k, pp.sigma1 * k, pp.sigma2 * k, pp.f1 * k, pp.f2 * k,
                    pp.alpha, pp.beta)


# ------------------------------------------------------------------------------------------
# Effect forms (each a pure function of its drawn parameters: the unit tests call them)
# ------------------------------------------------------------------------------------------
def direction(v: np.ndarray) -> np.ndarray:
    return np.sign(v)


def presliding_multiplier(form: str, par: dict, x: np.ndarray, v: np.ndarray,
                          t: np.ndarray) -> np.ndarray:
    """Friction direction multiplier m in [-1, 1] along tissue position x (mm), velocity v.

    The state starts saturated in the insertion direction (+1) and is advanced over the travel
    of each sample; m is 0 at rest (base-model convention; the state is kept)."""
    n = len(x)
    dx = np.concatenate([[0.0], np.diff(x)]).tolist()
    vv = v.tolist()
    out = [0.0] * n
    if form == "dahl":
        delta, ex = par["delta_mm"], par["exponent"]
        m = 1.0
        for k in range(n):
            d = dx[k]
            if d != 0.0:
                sg = 1.0 if d > 0 else -1.0
                w = max(1.0 - sg * m, 0.0)     # distance to the saturation in this direction
                if abs(ex - 1.0) < 1e-12:
                    w = w * math.exp(-abs(d) / delta)
                elif ex < 1.0:
                    w = max(w ** (1 - ex) - (1 - ex) * abs(d) / delta, 0.0) ** (1 / (1 - ex))
                elif w > 0.0:
                    w = (w ** (1 - ex) + (ex - 1) * abs(d) / delta) ** (1 / (1 - ex))
                m = sg * (1.0 - w)
            out[k] = m if vv[k] != 0.0 else 0.0
    elif form == "lugre":
        db, rs, vs, td = par["bristle_mm"], par["stribeck_ratio"], par["stribeck_v"], par["damp_s"]
        z, m = db, 1.0
        tt = t.tolist()
        for k in range(n):
            d = dx[k]
            if d != 0.0:
                sg = 1.0 if d > 0 else -1.0
                h = tt[k] - tt[k - 1] if k else 1.0
                speed = abs(d) / h
                zss = db * (1.0 + (rs - 1.0) * math.exp(-(speed / vs) ** 2))
                z_new = sg * zss + (z - sg * zss) * math.exp(-abs(d) / zss)
                zdot = (z_new - z) / h
                z = z_new
                m = min(max((z + td * zdot) / db, -1.6), 1.6)
            out[k] = m if vv[k] != 0.0 else 0.0
    elif form == "elastoplastic":
        zss, zba = par["zss_mm"], par["zba_mm"]
        z = zss
        for k in range(n):
            d = dx[k]
            if d != 0.0:
                # sub-steps of <= 0.01 mm: the transition function is not linear in z
                ns = max(1, int(abs(d) / 0.01) + 1)
                h = d / ns
                for _ in range(ns):
                    sg = 1.0 if h > 0 else -1.0
                    if z * sg <= 0.0 or abs(z) <= zba:
                        al = 0.0
                    elif abs(z) >= zss:
                        al = 1.0
                    else:
                        al = 0.5 * math.sin(math.pi * (abs(z) - 0.5 * (zss + zba)) /
                                            (zss - zba)) + 0.5
                    z = z + h * (1.0 - al * z * sg / zss)
            out[k] = z / zss if vv[k] != 0.0 else 0.0
    else:
        raise KeyError(form)
    return np.asarray(out)


def presliding_crossing_mm(form: str, par: dict) -> float:
    """Travel after a reversal at which the multiplier crosses zero (constant speed, analytic)."""
    if form == "dahl":
        ex = par["exponent"]
        f = math.log(2.0) if abs(ex - 1.0) < 1e-12 else (2 ** (1 - ex) - 1) / (1 - ex)
        return par["delta_mm"] * f
    if form == "lugre":
        return par["bristle_mm"] * math.log(2.0)
    if form == "elastoplastic":
        return par["zss_mm"]
    raise KeyError(form)


#: Prony approximation of the power-law kernel: time constants (s), log-spaced
_PL_TAUS = np.logspace(-3, 3.5, 14)


def relaxation_kernel(form: str, par: dict, t: np.ndarray) -> np.ndarray:
    """G(t) (G(0) = 1) of the QLV forms; for prony_dwell the normalised dwell shape 1 - D s(t)."""
    if form == "maxwell_total":
        w, taus, rho = par["weights"], par["taus"], par["rho"]
        return 1.0 - rho * sum(wk * (1.0 - np.exp(-t / tk)) for wk, tk in zip(w, taus))
    if form == "power_law":
        return 1.0 - par["rho"] * (1.0 - (1.0 + t / par["t0"]) ** (-par["a"]))
    if form == "prony_dwell":
        return 1.0 - par["drop"] * _prony_shape(par, t)
    raise KeyError(form)


def _prony_shape(par: dict, t: np.ndarray) -> np.ndarray:
    w, taus, span = par["weights"], par["taus"], par["span_s"]
    return sum(wk * (1 - np.exp(-t / tk)) for wk, tk in zip(w, taus)) / \
        sum(wk * (1 - np.exp(-span / tk)) for wk, tk in zip(w, taus))


def _powerlaw_prony(a: float, t0: float) -> tuple[np.ndarray, np.ndarray]:
    """Weights (sum 1) of exponentials on _PL_TAUS approximating (1 + t/t0)^-a, by NNLS."""
    from scipy.optimize import nnls
    tt = np.concatenate([[0.0], np.logspace(-3, 3, 400)])
    target = (1.0 + tt / t0) ** (-a)
    m = np.exp(-tt[:, None] / _PL_TAUS[None, :])
    w, _ = nnls(m, target)
    return _PL_TAUS, w


def _qlv_branches(f_e: np.ndarray, t: np.ndarray, taus: np.ndarray) -> list[np.ndarray]:
    """H_k(t) = int e^{-(t-s)/tau_k} dF_e(s), F_e linear within a sample (exact)."""
    out = []
    dt = np.diff(t)
    df = np.diff(f_e)
    for tau in taus:
        x = dt / tau
        a = np.exp(-x).tolist()
        phi = np.where(x > 1e-8, -np.expm1(-x) / np.maximum(x, 1e-300), 1.0)
        b = (df * phi).tolist()
        h = [0.0] * len(t)
        hk = float(f_e[0])
        h[0] = hk
        for k in range(len(t) - 1):
            hk = a[k] * hk + b[k]
            h[k + 1] = hk
        out.append(np.asarray(h))
    return out


def qlv(f_e: np.ndarray, t: np.ndarray, taus: np.ndarray, weights: np.ndarray
        ) -> np.ndarray:
    """Q = sum_k w_k (H_k - F_e): the relaxed force is F_e + rho Q (rho the relaxing fraction)."""
    hs = _qlv_branches(f_e, t, taus)
    return sum(w * (h - f_e) for w, h in zip(weights, hs))


def velocity_density_factor(form: str, par: dict, speed: np.ndarray) -> np.ndarray:
    """Friction density relative to the base sigma2 at |v| (1 at v_ref)."""
    s = np.abs(speed)
    vr = par["v_ref"]
    if form == "linear":
        return 1.0 + par["b_rel"] * (s - vr) / vr
    if form == "power":
        return np.maximum(s / vr, 1e-9) ** par["n"]
    if form == "stribeck":
        def raw(u: np.ndarray) -> np.ndarray:
            return 1.0 + (par["r_s"] - 1.0) * np.exp(-(u / par["v_s"]) ** 2) + par["k_v"] * u / vr
        return raw(s) / raw(np.asarray(vr))
    raise KeyError(form)


def asymmetry_ratio(form: str, par: dict, l: np.ndarray) -> np.ndarray:
    if form == "constant":
        return np.full_like(l, par["ratio"])
    if form == "depth":
        return 1.0 + (par["ratio_deep"] - 1.0) * np.clip(l / par["l_max"], 0, 1) ** par["gamma"]
    raise KeyError(form)


def layer_loading(form: str, u: np.ndarray, par: dict) -> np.ndarray:
    """Tenting load / rupture force as a function of u = (l - d + w)/w in [0, 1] (u = 1 at the
    rupture); the exponential form is e^{k (u - 1)} = e^{(l - d)/w_e} at every depth."""
    if form == "linear":
        return np.clip(u, 0, 1)
    if form == "cubic_membrane":
        return np.clip(u, 0, 1) ** 3
    if form == "exponential":
        return np.exp(-par["k"] * (1.0 - np.minimum(u, 1.0)))
    raise KeyError(form)


def drift_signal(form: str, par: dict, t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Sensor drift (N) from the start of the record, with the drawn excursion."""
    ex = par["excursion_n"]
    if form == "linear":
        d = t / t[-1]
    elif form == "warmup":
        d = -np.expm1(-t / par["tau_s"]) / -np.expm1(-t[-1] / par["tau_s"])
    elif form == "random_walk":
        knots = np.arange(0.0, t[-1] + 0.1, 0.1)
        walk = np.concatenate([[0.0], np.cumsum(rng.normal(0, 1, len(knots) - 1))])
        d = np.interp(t, knots, walk)
        d = d / max(np.max(np.abs(d)), 1e-12)
    else:
        raise KeyError(form)
    return par["sign"] * ex * d


def motion_signal(form: str, par: dict, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tissue displacement m(t) (mm) and its rate (mm/s)."""
    a, f, ph = par["amp_mm"], par["freq_hz"], par["phase"]
    if form == "sinusoid":
        w = 2 * np.pi * f
        return a * np.sin(w * t + ph), a * w * np.cos(w * t + ph)
    if form == "respiratory":
        n = par["n"]
        c = np.cos(np.pi * f * t + ph)
        mean = math.comb(2 * n, n) / 4 ** n
        return a * (c ** (2 * n) - mean), -a * 2 * n * c ** (2 * n - 1) * np.sin(
            np.pi * f * t + ph) * np.pi * f
    if form == "irregular":
        # phase advances with a cycle-to-cycle varying period; amplitude varies per cycle too
        cyc_f = par["cycle_f"]       # frequencies of successive cycles
        cyc_a = par["cycle_a"]
        dur = 1.0 / cyc_f
        edges = np.concatenate([[0.0], np.cumsum(dur)])
        k = np.clip(np.searchsorted(edges, t + par["t_shift"], side="right") - 1, 0,
                    len(cyc_f) - 1)
        tau = t + par["t_shift"] - edges[k]
        ph_t = 2 * np.pi * cyc_f[k] * tau
        amp = cyc_a[k]
        return amp * np.sin(ph_t), amp * 2 * np.pi * cyc_f[k] * np.cos(ph_t)
    raise KeyError(form)


# ------------------------------------------------------------------------------------------
# Drawing a case
# ------------------------------------------------------------------------------------------
def _draw_effect(rng: np.random.Generator, effect: str, form: str, info: dict) -> dict:
    """Parameters of one effect form shared by the trials of a case."""
    noise, peak = info["noise_n"], info["peak_n"]
    if effect == "dwell_relaxation":
        drop = rng.uniform(0.28, 0.49)
        w = rng.uniform(0.3, 0.7)
        taus = np.array([rng.uniform(0.2, 0.4), rng.uniform(2.0, 5.0)])
        if form == "power_law":
            a, t0 = rng.uniform(0.4, 0.8), rng.uniform(0.02, 0.2)
            ptaus, pw = _powerlaw_prony(a, t0)
            return {"drop": drop, "a": a, "t0": t0, "taus": ptaus, "weights": pw}
        return {"drop": drop, "taus": taus, "weights": np.array([w, 1 - w])}
    if effect == "reversal_presliding":
        cross = rng.uniform(1.0, 3.5)
        if form == "dahl":
            ex = rng.uniform(0.7, 1.5)
            f = math.log(2.0) if abs(ex - 1.0) < 1e-12 else (2 ** (1 - ex) - 1) / (1 - ex)
            return {"delta_mm": cross / f, "exponent": ex, "crossing_mm": cross}
        if form == "lugre":
            return {"bristle_mm": cross / math.log(2.0), "stribeck_ratio": rng.uniform(1.0, 1.5),
                    "stribeck_v": rng.uniform(0.2, 1.0), "damp_s": rng.uniform(0.005, 0.03),
                    "crossing_mm": cross}
        return {"zss_mm": cross, "zba_mm": cross * rng.uniform(0.3, 0.8), "crossing_mm": cross}
    if effect == "velocity_friction":
        sp = np.asarray(info["speeds"])
        vref = float(np.exp(np.mean(np.log(sp))))
        for _ in range(200):
            if form == "linear":
                par = {"b_rel": rng.uniform(0.2, 1.5), "v_ref": vref}
            elif form == "power":
                par = {"n": rng.uniform(0.3, 0.6), "v_ref": vref}
            else:
                par = {"r_s": rng.uniform(1.5, 2.5), "v_s": rng.uniform(0.7, 1.0) * sp.min(),
                       "k_v": rng.uniform(0.3, 1.0), "v_ref": vref}
            fac = velocity_density_factor(form, par, sp)
            ratio = float(fac[np.argmax(sp)] / fac[np.argmin(sp)])
            if 1.3 <= max(ratio, 1 / ratio) <= 2.4 and np.all(fac > 0.2):
                par["density_ratio"] = ratio
                return par
        raise RuntimeError("velocity friction: no admissible draw")
    if effect == "direction_asymmetry":
        hi = rng.random() < 0.5
        if form == "constant":
            return {"ratio": rng.uniform(1.25, 1.6) if hi else rng.uniform(0.6, 0.8)}
        return {"ratio_deep": rng.uniform(1.4, 2.0) if hi else rng.uniform(0.4, 0.7),
                "gamma": rng.uniform(0.7, 1.5), "l_max": info["min_depth_mm"]}
    if effect == "layer_puncture":
        n = int(rng.integers(1, 4))
        lo, hi = 3.0, min(25.0, info["min_depth_mm"] - 2.0)
        for _ in range(500):
            d = np.sort(rng.uniform(lo, hi, n))
            if n == 1 or np.min(np.diff(d)) >= 3.0:
                break
        else:
            n, d = 1, np.array([0.5 * (lo + hi)])
        spans = np.minimum(rng.uniform(1.5, 5.0, n), np.diff(np.concatenate([[0.5], d])) - 0.3)
        drops = np.maximum(rng.uniform(0.15, 0.6, n) * peak, 10 * noise)
        return {"depths_mm": d, "spans_mm": np.maximum(spans, 0.5), "drops_n": drops,
                "k": rng.uniform(2.5, 6.0)}
    if effect == "sensor_drift":
        par = {"excursion_n": max(rng.uniform(3.0, 8.0) * noise, 0.006),
               "sign": float(rng.choice([-1.0, 1.0]))}
        if form == "warmup":
            par["tau_s"] = rng.uniform(3.0, 20.0)
        return par
    if effect == "tissue_motion":
        par = {"amp_mm": rng.uniform(0.5, 2.5), "freq_hz": rng.uniform(0.2, 0.33)}
        if form == "respiratory":
            par["n"] = int(rng.integers(2, 4))
            par["amp_mm"] *= 2.0      # peak-to-peak of cos^2n is ~a; match the sinusoid's 2a
        return par
    raise KeyError(effect)


def _trial_effect(rng: np.random.Generator, effect: str, form: str, par: dict,
                  t_total: float) -> dict:
    """Per-trial draws (phase of motion, cycle lists)."""
    p = dict(par)
    if effect == "tissue_motion":
        p["phase"] = rng.uniform(0, 2 * np.pi)
        if form == "irregular":
            ncyc = int(t_total * par["freq_hz"] * 1.6) + 4
            p["cycle_f"] = par["freq_hz"] * rng.uniform(0.85, 1.15, ncyc)
            p["cycle_a"] = par["amp_mm"] * rng.uniform(0.85, 1.15, ncyc)
            p["t_shift"] = rng.uniform(0, 1 / par["freq_hz"])
    return p


def _held_direction(s: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """The last non-zero direction carried through rests (friction holds at rest)."""
    n = len(s)
    idx = np.where(s != 0, np.arange(n), 0)
    np.maximum.accumulate(idx, out=idx)
    held = s[idx]
    return np.where(inside, held, 0.0)


def _dwell_ranges(t: np.ndarray, v: np.ndarray, inside: np.ndarray) -> list[tuple[int, int]]:
    rest = (v == 0.0) & inside
    out, i, n = [], 0, len(rest)
    while i < n:
        if rest[i]:
            j = i
            while j < n and rest[j]:
                j += 1
            if t[j - 1] - t[i] >= 0.2:
                out.append((i, j))
            i = j
        else:
            i += 1
    return out


def _tissue_force(pp: ParamSet, mo: _Motion, forms: dict[str, str], pars: dict[str, dict],
                  stick: dict | None) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free tissue force (N) of one trial with the given effect forms (drift excluded),
    and the tissue depth l (mm)."""
    t, v = mo.t, mo.v
    x = mo.stage - mo.surface                 # tissue coordinate before motion
    vrel = v.copy()
    if "tissue_motion" in forms:
        m, mdot = motion_signal(forms["tissue_motion"], pars["tissue_motion"], t)
        x = x - m
        vrel = vrel - mdot
    l = np.maximum(x, 0.0)
    inside = l > 0.0
    el, fr = base_terms(pp, t, l)
    s = direction(vrel) * inside
    relaxing = "dwell_relaxation" in forms
    if "reversal_presliding" in forms:
        mult = presliding_multiplier(forms["reversal_presliding"], pars["reversal_presliding"],
                                     x, vrel, t) * inside
    else:
        mult = s
    if relaxing:                               # friction holds at rest (static friction)
        rest = (vrel == 0.0) & inside
        if "reversal_presliding" in forms:
            held = presliding_multiplier(forms["reversal_presliding"],
                                         pars["reversal_presliding"], x,
                                         np.where(rest, 1.0, vrel), t) * inside
        else:
            held = _held_direction(s, inside)
        mult = np.where(rest, held, mult)
    fr_eff = fr
    if "velocity_friction" in forms:
        fac = velocity_density_factor(forms["velocity_friction"], pars["velocity_friction"], vrel)
        fr_eff = fr + pp.sigma2 * l * (fac - 1.0)
    if "direction_asymmetry" in forms:
        r = asymmetry_ratio(forms["direction_asymmetry"], pars["direction_asymmetry"], l)
        fr_eff = np.where(mult < 0, fr_eff * r, fr_eff)
    if relaxing:
        # the friction held at rest is the friction at the stop (the base model's bristle term
        # would otherwise keep changing with z during the rest, a decay of its own)
        moving = ~rest
        idx = np.where(moving, np.arange(len(t)), 0)
        np.maximum.accumulate(idx, out=idx)
        fr_eff = np.where(rest, fr_eff[idx], fr_eff)
    f = el + mult * fr_eff
    if "layer_puncture" in forms:
        par = pars["layer_puncture"]
        deepest = np.maximum.accumulate(l)
        for d, w, drop in zip(par["depths_mm"], par["spans_mm"], par["drops_n"]):
            u = (l - d + w) / w
            load = layer_loading(forms["layer_puncture"], u, par)
            intact = (deepest <= d) & (l > 0)
            release = np.clip((d + 0.1 - deepest) / 0.1, 0.0, 1.0)   # drop over 0.1 mm
            f = f + drop * np.where(intact, load, np.where(deepest <= d + 0.1, release, 0.0)
                                    * (l > 0))
    if relaxing:
        form, par = forms["dwell_relaxation"], pars["dwell_relaxation"]
        if form == "prony_dwell":
            for i0, i1 in _dwell_ranges(t, v, inside):
                f_stop = f[i0 - 1] if i0 > 0 else f[i0]
                f[i0:i1] = f_stop * (1.0 - par["drop"] * _prony_shape(par, t[i0:i1] - t[i0]))
        else:
            f = (f + par["rho"] * qlv(f, t, par["taus"], par["weights"])) * inside
    if stick is not None:
        ins = (v > 0) & inside
        trav = np.concatenate([[0.0], np.cumsum(np.where(ins[1:], np.abs(np.diff(x)), 0.0))])
        f = f + np.where(ins, stick["amp_n"] * np.mod(trav / stick["period_mm"], 1.0), 0.0)
    return f, l


def _calibrate_relaxation(pp: ParamSet, mo: _Motion, forms: dict[str, str],
                          pars: dict[str, dict]) -> None:
    """Solve the relaxing fraction rho of a QLV form so that the first trial's dwell loses the
    drawn fraction over min(dwell, 5 s) (F = F_e + rho Q is linear in rho)."""
    par = pars["dwell_relaxation"]
    span = min(5.0, mo.dwell[1] - mo.dwell[0] - 0.05)
    par["span_s"] = span
    if forms["dwell_relaxation"] == "prony_dwell":
        return
    fe_forms = {k: v for k, v in forms.items() if k != "dwell_relaxation"}
    fe_pars = {k: v for k, v in pars.items() if k != "dwell_relaxation"}
    # F_e with the friction held at rest: run with rho = 0
    tmp = dict(par, rho=0.0)
    f_e, _ = _tissue_force(pp, mo, {**fe_forms, "dwell_relaxation": "maxwell_total"},
                           {**fe_pars, "dwell_relaxation": tmp}, None)
    q = qlv(f_e, mo.t, par["taus"], par["weights"])
    i0 = int(np.searchsorted(mo.t, mo.dwell[0] + 0.02))
    i1 = int(np.searchsorted(mo.t, mo.dwell[0] + span))
    fe0, fe1, q0, q1 = f_e[i0], f_e[i1], q[i0], q[i1]
    d = par["drop"]
    # (fe0 + rho q0)(1 - d) = fe1 + rho q1
    den = q1 - (1 - d) * q0
    rho = ((1 - d) * fe0 - fe1) / den if abs(den) > 1e-15 else 0.99
    par["rho"] = float(np.clip(rho, 0.02, 0.99))


def make_case(kind: str | tuple[str, ...], seed: int, forms: dict[str, str] | None = None
              ) -> Case:
    """One blind case of ``kind`` (see :func:`kinds`); ``forms`` overrides the forms drawn.

    ``kind`` may also be a tuple of vocabulary effects (() for none): each then takes its
    library form when it has one, else its first form."""
    if not isinstance(kind, str):
        effs = tuple(kind)
        forms = forms or {e: next((f.name for f in FORMS[e] if f.library), FORMS[e][0].name)
                          for e in effs}
        kind = "none" if not effs else ("pair" if set(effs) == set(PAIR) and len(effs) == 2
                                        else f"{effs[0]}/{forms[effs[0]]}")
    rng = np.random.default_rng(seed)
    effects = kind_effects(kind)
    if forms is None:
        if kind == "pair":
            forms = {e: FORMS[e][int(rng.integers(len(FORMS[e])))].name for e in PAIR}
        elif effects:
            forms = {effects[0]: kind.split("/")[1]}
        else:
            forms = {}
    forms = dict(forms)
    preset, pp = _params(rng)
    measured_scale = rng.random() < 0.5
    if "velocity_friction" in effects:
        n_tr = int(rng.integers(2, 4))
        while True:
            speeds = np.exp(rng.uniform(np.log(1.0), np.log(10.0), n_tr))
            if np.min(np.diff(np.sort(speeds))) > 0.5 and speeds.max() >= 2.5 * speeds.min():
                break
    else:
        n_tr = int(rng.integers(1, 4))
        speeds = np.exp(rng.uniform(np.log(1.0), np.log(10.0), n_tr))
    depths = rng.uniform(12.0, 35.0, n_tr)
    surfaces = rng.uniform(4.0, 16.0, n_tr)
    dwells = rng.uniform(4.0, 6.5, n_tr)
    rates = [float(rng.uniform(76, 100)) if u < 0.5 else float(np.exp(rng.uniform(
        np.log(100), np.log(1000)))) for u in rng.random(n_tr)]
    motions = [_trajectory(rng, surfaces[i], depths[i], speeds[i], dwells[i], rates[i])
               for i in range(n_tr)]
    # scale the base force: paper (0.15-0.4 N peak) or measured (2.3-6.2 N)
    el, fr = base_terms(pp, motions[0].t, motions[0].stage - motions[0].surface)
    peak0 = float(np.max((el + direction(motions[0].v) * fr)[motions[0].v > 0]))
    target = rng.uniform(2.3, 6.2) if measured_scale else rng.uniform(0.15, 0.4)
    pp = _scaled(pp, target / peak0)
    noise = float(np.exp(rng.uniform(np.log(0.008), np.log(0.05)))) if measured_scale else \
        float(rng.uniform(0.002, 0.010))
    info: dict = {"preset": preset, "params": pp, "scale": "measured" if measured_scale else
                  "paper", "peak_n": target, "noise_n": noise, "speeds": speeds.tolist(),
                  "depths_mm": depths.tolist(), "surfaces_mm": surfaces.tolist(),
                  "rates_hz": rates, "min_depth_mm": float(depths.min())}
    pars = {e: _draw_effect(rng, e, f, info) for e, f in forms.items()}
    stick = None
    if kind == OOV:
        stick = {"period_s": rng.uniform(0.3, 1.5),
                 "amp_n": max(rng.uniform(0.05, 0.15) * target, 10 * noise)}
    if "dwell_relaxation" in forms:
        tp = {e: _trial_effect(rng, e, forms[e], p, motions[0].t[-1]) for e, p in pars.items()}
        _calibrate_relaxation(pp, motions[0], forms, tp)
        pars["dwell_relaxation"] = tp["dwell_relaxation"]
        # the relaxed force, not the elastic one, has the drawn insertion peak (F is linear in
        # the base scale, so the drop fraction is kept)
        f_rel, _ = _tissue_force(pp, motions[0], forms, tp, None)
        pp = _scaled(pp, target / float(np.max(f_rel[motions[0].v > 0])))
        info["params"] = pp
    trials, truth, base, support = [], [], [], []
    for i, mo in enumerate(motions):
        tp = {e: _trial_effect(rng, e, forms[e], p, mo.t[-1]) for e, p in pars.items()}
        st = None if stick is None else {"amp_n": stick["amp_n"],
                                         "period_mm": stick["period_s"] * speeds[i]}
        f, _ = _tissue_force(pp, mo, {e: forms[e] for e in forms if e != "sensor_drift"}, tp, st)
        f0, _ = _tissue_force(pp, mo, {}, {}, None)
        if "sensor_drift" in forms:
            f = f + drift_signal(forms["sensor_drift"], tp["sensor_drift"], mo.t, rng)
        tare = rng.uniform(-0.05, 0.05)
        meas = f + tare + rng.normal(0.0, noise, len(mo.t))
        vel = mo.v.copy() if rng.random() < 0.5 else None
        trials.append(Trial(f"trial{i}", mo.t, mo.stage.copy(), meas, vel))
        truth.append(f + tare)
        base.append(f0 + tare)
        support.append(np.abs(f - f0) > 5e-4)
    info["effect_params"] = pars
    if stick is not None:
        info["stick_slip"] = stick
    held = {e: not form_of(e, f).library for e, f in forms.items()}
    return Case(kind, trials, effects, forms, held, truth, base, support, info)


# ------------------------------------------------------------------------------------------
# The blind harness: run the workflow as a user would and grade it against the hidden truth
# (shared by tests/python/test_discrepancy_blind.py and tests/python/discrepancy_confusion.py)
# ------------------------------------------------------------------------------------------
#: cases per kind in a full run
FULL_CASES = 20


def case_seed(kind: str, k: int) -> int:
    """Seed of case k of a kind: fixed by the kind's name (adding kinds moves no other seed)."""
    return (zlib.crc32(kind.encode()) % 100_003) * 1_000 + k


def _num(x: object) -> list[float]:
    if isinstance(x, bool) or x is None:
        return []
    if isinstance(x, (int, float, np.floating, np.integer)):
        return [float(x)]
    if isinstance(x, (list, tuple, np.ndarray)):
        return [v for y in x for v in _num(y)]
    return []


def _rupture_dicts(x: object) -> list[dict]:
    if isinstance(x, dict):
        own = [x] if {"depth_mm", "drop_n"} <= set(x) else []
        return own + [d for v in x.values() for d in _rupture_dicts(v)]
    if isinstance(x, (list, tuple)):
        return [d for v in x for d in _rupture_dicts(v)]
    return []


def bound_check(rep: dict, depth_max_mm: float, peak_n: float) -> list[str]:
    """Named effects' and base parameters outside the bounds the report documents
    (``rep["bounds"]``), plus the report's own list and two physical checks that need no table:
    a layer (rupture) lies inside the inserted depth and its drop is positive and below the
    insertion peak.  A report without a bounds table is itself a violation."""
    out = [f"report: {v}" for v in rep.get("bound_violations") or []]
    b = rep.get("bounds")
    if not isinstance(b, dict):
        return out + ["report documents no parameter bounds"]
    nl, lin = b.get("nonlinear", {}), b.get("linear", {})
    inf = float("inf")

    def lookup(name: str) -> tuple[float, float] | None:
        if name in nl:
            return float(nl[name][0]), float(nl[name][1])
        key = name.split("[")[0]
        if re.match(r"layer\d+_", key):
            key = "layer_" + key.split("_", 1)[1]
        if key in lin:
            lo, hi = lin[key]
            return (-inf if lo is None else float(lo)), (inf if hi is None else float(hi))
        return None

    for e in rep.get("effects", []):
        for k, v in (e.get("parameters") or {}).items():
            name = k.split(" [")[0].strip()
            if "standard error" in k:
                continue
            bd = lookup(name)
            if bd is None:
                continue
            for x in _num(v):
                if not bd[0] - 1e-9 <= x <= bd[1] + 1e-9:
                    out.append(f"{e.get('name')}: {name}={x:.4g} outside [{bd[0]}, {bd[1]}]")
            if name == "layer_depth_mm":
                for x in _num(v):
                    if not 0.0 < x <= depth_max_mm + 2.0:
                        out.append(f"layer at {x:.3g} mm outside the inserted 0-{depth_max_mm:.3g}")
        for r in _rupture_dicts(e.get("parameters")):
            dm, dn = _num(r["depth_mm"]), _num(r["drop_n"])
            if dm and not 0.0 < dm[0] <= depth_max_mm + 2.0:
                out.append(f"rupture at {dm[0]:.3g} mm outside the inserted 0-{depth_max_mm:.3g}")
            if dn and not 0.0 < dn[0] <= peak_n:
                out.append(f"rupture drop {dn[0]:.3g} N not in (0, peak {peak_n:.3g} N]")
    bp = (rep.get("base_model") or {}).get("params") or {}
    beta = float(bp.get("beta", 1.0) or 1.0)
    for pname, lab, scale in (("sigma0", "A", beta), ("sigma1", "C", beta),
                              ("sigma2", "sigma2", 1.0), ("alpha", "alpha", 1.0)):
        if pname not in bp or bp[pname] is None:
            continue
        bd = lookup(lab)
        if bd is None:
            continue
        x = float(bp[pname]) * scale
        if not bd[0] - 1e-9 <= x <= bd[1] + 1e-9:
            out.append(f"base {pname}={float(bp[pname]):.4g} outside its bounds ({lab} in "
                       f"[{bd[0]}, {bd[1]}])")
    if bp.get("f1") is not None and bp.get("f2") is not None:
        if float(bp["f1"]) + min(float(bp["f2"]), 0.0) <= 0.0:
            out.append("base g(l) = f1 + f2 e^-al not positive at every depth")
    return out


def run_case(job: tuple[str, int]) -> dict:
    """Generate case k of a kind, run the workflow blind (``workflow.run`` then
    ``report.build``, as the command does) and grade it against the hidden truth.

    The gap is graded against the noise-free truth: RMSE of (model - truth) where a hidden
    effect changes the force ("support") and overall, base model vs final model."""
    import time as _time

    from reference_py.discrepancy.report import build
    from reference_py.discrepancy.workflow import run

    kind, k = job
    case = make_case(kind, case_seed(kind, k))
    row: dict = {"kind": kind, "k": k, "effects": list(case.effects), "forms": case.forms,
                 "held_out": case.held_out, "n_trials": len(case.trials),
                 "samples": int(sum(len(t.t_s) for t in case.trials)),
                 "scale": case.info["scale"], "noise_n": case.info["noise_n"]}
    t0 = _time.perf_counter()
    try:
        res = run(case.trials)
        rep = build(res, [t.name for t in case.trials])
    except Exception as exc:                      # graded as a miss, with its message
        dt = _time.perf_counter() - t0
        row.update(named=["error"], first="error", unexplained=None, left_structure=None,
                   violations=[],
                   error=f"{type(exc).__name__}: {exc}", runtime_s=dt,
                   runtime_per_trial_s=dt / len(case.trials), support_before=float("nan"),
                   support_after=float("nan"), overall_before=float("nan"),
                   overall_after=float("nan"))
        return row
    dt = _time.perf_counter() - t0
    named = [str(n) for n in rep.get("named") or res.named]
    verdict = rep.get("verdict")
    unexpl = bool(verdict.get("unexplained")) if isinstance(verdict, dict) else None
    by_name = {t.name: i for i, t in enumerate(case.trials)}
    idx = [by_name[p.name] for p in res.preps]
    depth_max = max(float(np.max(case.trials[i].depth_mm)) - case.info["surfaces_mm"][i]
                    for i in range(len(case.trials)))
    peak = max(float(np.max(np.abs(tr))) for tr in case.truth) + 3 * case.info["noise_n"]

    def rmse(preds: list[np.ndarray], on_support: bool) -> float:
        d = np.concatenate([(p - case.truth[i])[case.support[i]] if on_support
                            else (p - case.truth[i]) for p, i in zip(preds, idx)])
        return float(np.sqrt(np.mean(d ** 2))) if len(d) else float("nan")

    # every refusal of every round with its reason (issue 22 item 4: what was not named, and why)
    rounds = [e.get("candidates") or [] for e in rep.get("effects") or []] + \
        [rep.get("final_round") or []]
    row["refused"] = [{"round": j, "name": c.get("name"), "reason": c.get("rejected")}
                      for j, cands in enumerate(rounds) for c in cands if c.get("rejected")]
    row.update(named=named, first=named[0], unexplained=unexpl,
               left_structure=left_structure(res.predictions[-1], [case.truth[i] for i in idx],
                                             [case.trials[i].t_s for i in idx],
                                             float(case.info["noise_n"])),
               violations=bound_check(rep, depth_max, peak), error=None,
               runtime_s=dt, runtime_per_trial_s=dt / len(case.trials),
               support_before=rmse(res.predictions[0], True),
               support_after=rmse(res.predictions[-1], True),
               overall_before=rmse(res.predictions[0], False),
               overall_after=rmse(res.predictions[-1], False))
    return row


def left_structure(preds: list[np.ndarray], truths: list[np.ndarray], times: list[np.ndarray],
                   noise_n: float) -> bool:
    """Whether the final model leaves structure the "unexplained" verdict is there to report,
    judged on the noise-free truth with the verdict's own rule (unexplained.stretches): the
    model's departure from the truth, averaged over 0.5 s, above 3 times the sensor noise for at
    least 0.5 s in some trial.  The verdict sees the noisy record, its tare and its own noise
    estimate; this sees what the record would have been without noise."""
    from reference_py.discrepancy.unexplained import stretches

    return any(stretches(t, pred - truth, noise_n)[2]
               for pred, truth, t in zip(preds, truths, times))


def verdict_against_truth(rows: list[dict]) -> tuple[list[dict], list[dict]]:
    """The graded rows (a verdict and left_structure both known) parted by what the final
    model leaves: (those that leave a stretch the verdict should report, those that do not)."""
    graded = [r for r in rows if r["unexplained"] is not None
              and r.get("left_structure") is not None]
    return ([r for r in graded if r["left_structure"]],
            [r for r in graded if not r["left_structure"]])


def jobs_for(cases: int, kinds_: list[str] | None = None, first: int = 0
             ) -> list[tuple[str, int]]:
    """Cases first .. first + cases - 1 of every kind (the CI subset: 0-3)."""
    return [(kind, k) for kind in (kinds_ or kinds()) for k in range(first, first + cases)]


def run_all(jobs: list[tuple[str, int]], workers: int = 2, progress: bool = False
            ) -> list[dict]:
    """Grade ``jobs`` in a pool of ``workers`` processes (single-threaded BLAS in each); results
    in the order of ``jobs``."""
    import multiprocessing as mp
    import os

    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    if workers <= 1:
        return [run_case(j) for j in jobs]
    ctx = mp.get_context("spawn")
    with ctx.Pool(workers) as pool:
        it = pool.imap(run_case, jobs, chunksize=1)
        if progress:
            from tqdm import tqdm
            it = tqdm(it, total=len(jobs), file=__import__("sys").stderr)
        return list(it)
