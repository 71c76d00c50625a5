"""A realistic needle-insertion phantom: multi-layer tissue, relaxation, pre-sliding, a real sensor.

Where ``nte-ref simulate`` produces the paper's Model II force, this simulator produces records
that look like measured robotic insertions (statistics of 331 public trials, see PHANTOM.md): the
stage starts in air and touches the tissue somewhere along its stroke, each tissue layer is tented
until its membrane ruptures, the tip then cuts through the layer while friction grows along the
shaft, the tissue relaxes while the needle is held, the friction turns over gradually when the
motion reverses, and the force sensor adds an offset, a drift and noise.

Everything is physical state driven by the stage motion (no curve patches):

* stage      LSPB moves (linear segments, parabolic blends): insertion over the stroke, a dwell,
             retraction to 0, one cycle per speed; each cycle enters a fresh site of the tissue.
* membrane   the intact membrane at the top of layer i is pushed u = d - b_i mm past its rest
             position (d tip depth below the undeformed surface, b_i the layer's top):
             F_m = R_i [a u/u_i + (1-a) (exp(k u/u_i) - 1)/(exp(k) - 1)], a stiffening tent that
             reaches the rupture force R_i at u = u_i; it then ruptures and its force is released
             as R_i exp(-(t - t_r)/tau_r).
* cutting    while the tip advances through an opened layer j it carries the cutting force C_j;
             it unloads linearly over delta_c mm when the tip backs away from the cut front.
* friction   Coulomb friction per length of shaft inside each cut layer, mu_j L_j, times the
             Dahl direction state s (ds/dx = (sign(dx) - s)/delta_p over stage travel x): it holds
             in a dwell and turns over across a few mm after a reversal; retraction friction is
             rho times insertion friction.
* relaxation a generalized Maxwell (Prony) element of the engaged tissue: branch k has the
             stress sigma_k(t) = int_0^t (beta_k/tau_k) exp(-(t-s)/tau_k) phi(v(s)) ds, with
             phi = sign(v)|v/(1 mm/s)|^n max(0, s sign(v)) (the tissue shears only once the
             contact slides), and the force w(t) sum_k sigma_k, where the engagement
             w = min(d, ell_tip) + sum_j r_j L_j (mm) grows with depth.  In steady sliding it is a
             velocity-dependent friction beta_k phi(v) w; in a dwell it decays with tau_1 (fast)
             and tau_2 (slow).
* elastic    the tent, cutting and grip forces relax with the same time constants (quasi-linear
             viscoelastic: int G(t - s) dE(s), G = g_inf + sum_k g_k exp(-t/tau_k)); a torn
             membrane releases its relaxed force and keeps no memory, the cutting force stays
             >= 0 when the tip backs away, and the grip relaxes per engaged piece of shaft (a
             withdrawn piece takes its own grip away).
* sensor     force_n = +-(F + offset + drift(t) + noise): tare residue, linear drift plus a
             random walk, white noise; optional timestamp jitter, gaps and sign conventions.

Units: mm, s, N throughout.  ``simulate_phantom`` returns the samples and a truth dictionary;
``write_phantom`` writes the CSV (the columns of ``nte-ref simulate``) and a JSON sidecar.
"""
from __future__ import annotations

import argparse
import json
import math
import os
from dataclasses import asdict, dataclass, field, replace
from typing import Any, Sequence

import numpy as np
from scipy.signal import lfilter

Array = np.ndarray

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
_BLEND_MM = 3.0       # cutting-force transition into a layer that has no membrane, mm
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
@dataclass(frozen=True)
class Layer:
    """One tissue layer: the membrane at its top, then the layer's own cutting and friction."""
    name: str
    thickness_mm: float           # from its top (membrane) to the next layer's top
    rupture_n: float              # R: membrane rupture force (0: no membrane, e.g. an incision)
    tent_mm: float                # u_r: tent displacement at rupture
    cutting_n: float              # C: cutting force at the tip while it advances in the layer
    friction_n_mm: float          # mu: Coulomb friction per mm of shaft inside the layer
    viscous: float = 1.0          # r: weight of a mm of this layer in the Maxwell engagement


@dataclass(frozen=True)
class Tissue:
    layers: tuple[Layer, ...]
    maxwell_n_mm: tuple[float, ...] = (0.03, 0.036)   # beta_k: steady stress per mm at 1 mm/s
    maxwell_tau_s: tuple[float, ...] = (0.3, 3.0)     # tau_k
    rate_exponent: float = 0.5                          # n in phi = sign(v)|v/(1 mm/s)|^n
    tip_mm: float = 3.0                                 # ell_tip: engagement of the tip region
    presliding_mm: float = 3.5                          # delta_p: Dahl length
    retraction_ratio: float = 0.9                       # rho: retraction / insertion friction
    unload_mm: float = 0.5                              # delta_c: tip unloading length
    rupture_s: float = 0.015                            # tau_r: membrane release time
    tent_linear: float = 0.25                           # a: linear share of the tent law
    tent_curvature: float = 2.5                         # k: stiffening of the tent law
    relax_g: tuple[float, ...] = (0.1, 0.15)            # g_k: relaxing shares of the elastic
                                                        # forces, one per Maxwell time constant


@dataclass(frozen=True)
class Motion:
    speeds_mm_s: tuple[float, ...] = (2.0,)   # one insertion-dwell-retraction cycle per speed
    stroke_mm: float = 25.0
    accel_mm_s2: float = 20.0
    dwell_s: float = 5.26
    rest_s: float = 1.0                       # at 0 before the first cycle and after each


@dataclass(frozen=True)
class Sensor:
    rate_hz: float = 100.0
    noise_n: float = 0.012
    offset_n: float = 0.0
    drift_n_s: float = 0.0           # linear drift
    walk_n_sqrt_s: float = 0.0       # random-walk drift intensity
    jitter: float = 0.0              # timestamp jitter, fraction of the period (< 0.5)
    gaps: int = 0                    # number of missing stretches
    gap_s: float = 0.3               # length of each
    force_sign: int = 1              # -1: force recorded negative on insertion
    depth_sign: int = 1              # -1: depth recorded negative on insertion


@dataclass(frozen=True)
class PhantomSpec:
    name: str
    tissue: Tissue
    surface_mm: float = 6.0          # stage position at which the tip touches the tissue
    motion: Motion = field(default_factory=Motion)
    sensor: Sensor = field(default_factory=Sensor)

    def validate(self) -> None:
        m, s, ti = self.motion, self.sensor, self.tissue
        _pos("stroke_mm (--stroke)", m.stroke_mm)
        _pos("accel_mm_s2", m.accel_mm_s2)
        _nonneg("dwell_s (--dwell)", m.dwell_s)
        _nonneg("rest_s", m.rest_s)
        if not m.speeds_mm_s:
            raise ValueError("speeds_mm_s (--speed): at least one speed is needed")
        for v in m.speeds_mm_s:
            if not (math.isfinite(v) and 0.0 < v <= 10.0):
                raise ValueError(f"speeds_mm_s (--speed) must be in (0, 10] mm/s (got {v!r})")
        if not (math.isfinite(s.rate_hz) and 20.0 <= s.rate_hz <= 5000.0):
            raise ValueError(f"rate_hz (--rate) must be in [20, 5000] Hz (got {s.rate_hz!r})")
        _nonneg("noise_n (--noise)", s.noise_n)
        for nm, flag in (("offset_n", "--offset"), ("drift_n_s", "--drift")):
            if not math.isfinite(getattr(s, nm)):
                raise ValueError(f"{nm} ({flag}) must be finite")
        _nonneg("walk_n_sqrt_s (--walk)", s.walk_n_sqrt_s)
        if not (0.0 <= s.jitter < 0.5):
            raise ValueError(f"jitter (--jitter) must be in [0, 0.5) (got {s.jitter!r})")
        if s.gaps < 0:
            raise ValueError(f"gaps (--gaps) must be >= 0 (got {s.gaps!r})")
        _pos("gap_s", s.gap_s)
        if s.force_sign not in (1, -1) or s.depth_sign not in (1, -1):
            raise ValueError("force_sign and depth_sign (--force-sign, --depth-sign) must be "
                             "+1 or -1")
        # bounded like nte-ref simulate: a record of at most 10 M samples
        for nm, v, hi in (("stroke_mm (--stroke)", m.stroke_mm, 500.0),
                          ("dwell_s (--dwell)", m.dwell_s, 3600.0), ("rest_s", m.rest_s, 3600.0),
                          ("gaps (--gaps)", s.gaps, 1000)):
            if v > hi:
                raise ValueError(f"{nm} must be <= {hi:g} (got {v!r})")
        n = s.rate_hz * sum(2.0 * m.stroke_mm / v + m.dwell_s + m.rest_s for v in m.speeds_mm_s)
        if n > 10_000_000:
            raise ValueError(f"the record would hold {n:.3g} samples, more than 10,000,000: "
                             f"lower --rate, --stroke or --dwell")
        if not (math.isfinite(self.surface_mm) and 0.0 <= self.surface_mm < m.stroke_mm):
            raise ValueError(f"surface_mm (--surface) must be in [0, stroke) mm "
                             f"(got {self.surface_mm!r})")
        if not ti.layers:
            raise ValueError("the tissue needs at least one layer")
        for ly in ti.layers:
            _pos(f"layer {ly.name}: thickness_mm", ly.thickness_mm)
            _nonneg(f"layer {ly.name}: rupture_n", ly.rupture_n)
            _pos(f"layer {ly.name}: tent_mm", ly.tent_mm)
            _nonneg(f"layer {ly.name}: cutting_n", ly.cutting_n)
            _nonneg(f"layer {ly.name}: friction_n_mm", ly.friction_n_mm)
            _nonneg(f"layer {ly.name}: viscous", ly.viscous)
        if len(ti.maxwell_n_mm) != len(ti.maxwell_tau_s):
            raise ValueError("maxwell_n_mm and maxwell_tau_s need the same length")
        for b in ti.maxwell_n_mm:
            _nonneg("maxwell_n_mm", b)
        for tau in ti.maxwell_tau_s:
            _pos("maxwell_tau_s", tau)
        if len(ti.relax_g) != len(ti.maxwell_tau_s) or any(
                not (math.isfinite(x) and x >= 0.0) for x in ti.relax_g) or sum(ti.relax_g) >= 1.0:
            raise ValueError("relax_g: one share >= 0 per time constant, summing to < 1")
        for nm in ("rate_exponent", "presliding_mm", "retraction_ratio", "unload_mm",
                   "rupture_s", "tent_curvature"):
            _pos(nm, getattr(ti, nm))
        _nonneg("tip_mm", ti.tip_mm)
        if not (0.0 <= ti.tent_linear <= 1.0):
            raise ValueError("tent_linear must be in [0, 1]")


def _pos(name: str, v: float) -> None:
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be finite and > 0 (got {v!r})")


def _nonneg(name: str, v: float) -> None:
    if not (math.isfinite(v) and v >= 0):
        raise ValueError(f"{name} must be finite and >= 0 (got {v!r})")


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
def stage_motion(t_s: Array, motion: Motion) -> tuple[Array, Array, Array, Array, list[dict[str, float]]]:
    """Stage position (mm), velocity (mm/s), phase and cycle index at the times t_s.

    phase: 0 rest, 1 insertion, 2 dwell, 3 retraction.  Also the cycles' time marks.
    """
    x = np.zeros(len(t_s))
    v = np.zeros(len(t_s))
    phase = np.zeros(len(t_s), dtype=np.int8)
    cycle = np.full(len(t_s), -1, dtype=np.int16)
    marks = []
    t0 = motion.rest_s
    for c, speed in enumerate(motion.speeds_mm_s):
        vc, a, D = speed, motion.accel_mm_s2, motion.stroke_mm
        if D * a < vc * vc:
            vc = math.sqrt(D * a)
        tb = vc / a
        dur = D / vc + tb
        t1, t2, t3 = t0 + dur, t0 + dur + motion.dwell_s, t0 + 2 * dur + motion.dwell_s
        for (ta, sgn, base) in ((t0, 1.0, 0.0), (t2, -1.0, D)):
            tau = t_s - ta
            sel = (tau > 0.0) & (tau < dur)
            tt = tau[sel]
            pos = np.where(tt < tb, 0.5 * a * tt * tt,
                           np.where(tt <= dur - tb, 0.5 * a * tb * tb + vc * (tt - tb),
                                    D - 0.5 * a * (dur - tt) ** 2))
            vel = np.where(tt < tb, a * tt, np.where(tt <= dur - tb, vc, a * (dur - tt)))
            x[sel] = base + sgn * pos
            v[sel] = sgn * vel
            phase[sel] = 1 if sgn > 0 else 3
        sel = (t_s >= t1) & (t_s <= t2)
        x[sel], phase[sel] = D, 2
        cycle[(t_s > t0) & (t_s < t3 + motion.rest_s)] = c
        marks.append({"start_s": t0, "insertion_end_s": t1, "retraction_start_s": t2,
                      "retraction_end_s": t3, "speed_mm_s": vc})
        t0 = t3 + motion.rest_s
    return x, v, phase, cycle, marks


def record_duration(motion: Motion) -> float:
    return float(stage_motion(np.zeros(1), motion)[4][-1]["retraction_end_s"] + motion.rest_s)


# ---------------------------------------------------------------------------------------------
@dataclass
class PhantomResult:
    spec: PhantomSpec
    t_s: Array
    depth_mm: Array           # as recorded (depth_sign applied)
    velocity_mm_s: Array      # as recorded
    force_n: Array            # as recorded (force_sign applied, with offset, drift, noise)
    force_true_n: Array       # tissue force without sensor effects (force_sign applied)
    truth: dict[str, Any]     # ground truth; per-sample arrays in truth["samples"]

    def csv_lines(self) -> list[str]:
        lines = ["t_s,depth_mm,velocity_mm_s,force_n,force_true_n"]
        lines += ["%.17g,%.17g,%.17g,%.17g,%.17g" % row for row in
                  zip(self.t_s, self.depth_mm, self.velocity_mm_s, self.force_n,
                      self.force_true_n)]
        return lines


def _tent(u: float, R: float, ur: float, a: float, k: float) -> float:
    if u <= 0.0:
        return 0.0
    return R * (a * u / ur + (1.0 - a) * math.expm1(k * u / ur) / math.expm1(k))


def _tissue_force(spec: PhantomSpec, t: Array, x: Array, cycle: Array
                  ) -> tuple[dict[str, Array], list[dict[str, Any]]]:
    """Noise-free tissue force and its components along the stage motion (one fresh site per
    cycle).  Sequential in time: the membranes, the Dahl state and the Maxwell branches are
    hereditary."""
    ti = spec.tissue
    layers = ti.layers
    nl = len(layers)
    tops = np.concatenate([[0.0], np.cumsum([ly.thickness_mm for ly in layers])])
    n = len(t)
    out = {k: np.zeros(n) for k in ("membrane", "cutting", "friction_pos", "friction_neg",
                                    "viscous", "dahl", "tip_depth_mm", "cut_depth_mm",
                                    "engagement_mm", "elastic_instant")}
    branch = np.zeros((len(ti.maxwell_tau_s), n))
    layer_idx = np.full(n, -1, dtype=np.int16)
    rupt_count = np.zeros(n, dtype=np.int16)
    ruptures: list[dict[str, Any]] = []
    beta = [float(b) for b in ti.maxwell_n_mm]
    tau = [float(x) for x in ti.maxwell_tau_s]
    nb = len(tau)
    mu = [ly.friction_n_mm for ly in layers]
    rvis = [ly.viscous for ly in layers]
    tops_l = [float(b) for b in tops]
    a_t, k_t = ti.tent_linear, ti.tent_curvature
    rho, dp, dc, tr_s, tip = (ti.retraction_ratio, ti.presliding_mm, ti.unload_mm, ti.rupture_s,
                              ti.tip_mm)
    n_exp, surf = ti.rate_exponent, spec.surface_mm
    o_mem, o_cut, o_vis = out["membrane"], out["cutting"], out["viscous"]
    o_s, o_d, o_c, o_w = out["dahl"], out["tip_depth_mm"], out["cut_depth_mm"], out["engagement_mm"]
    o_fp, o_fn, o_inst = out["friction_pos"], out["friction_neg"], out["elastic_instant"]
    tl, xl, cl = t.tolist(), x.tolist(), cycle.tolist()
    cur_cycle = -2
    s = 0.0
    sig = [0.0] * nb
    k = 0
    cut = 0.0
    released: list[tuple[float, float]] = []
    recoil: list[tuple[float, float]] = []
    n_rupt = 0
    d_prev = -math.inf
    dt_cached, decay = -1.0, [0.0] * nb
    origin = list(tops_l)
    g = [float(v) for v in ti.relax_g]
    g_inf = 1.0 - sum(g)
    tent_h = [0.0] * nb                     # relaxing parts of the intact membrane's tent force
    tent_prev = 0.0
    grip: list[list[float]] = []            # engaged shaft pieces, deepest last: [length, mu L, t]
    grip_h = [0.0] * nb                     # relaxing parts of the grip (sum of g_k mu L e^..)
    grip_w = 0.0                            # sum of mu L over the engaged pieces
    reach_prev = 0.0
    for i in range(n):
        ti_ = tl[i]
        if cl[i] != cur_cycle:              # a fresh site: intact membranes, nothing cut
            cur_cycle = int(cl[i])
            k, cut, released, recoil, n_rupt = 0, 0.0, [], [], 0
            origin = list(tops_l)
            tent_h, tent_prev = [0.0] * nb, 0.0
            grip, grip_h, grip_w, reach_prev = [], [0.0] * nb, 0.0, 0.0
        d = xl[i] - surf
        dt = ti_ - tl[i - 1] if i > 0 else 0.0
        if i > 0:
            if dt != dt_cached:
                dt_cached, decay = dt, [math.exp(-dt / tk) for tk in tau]
            for b in range(nb):
                tent_h[b] *= decay[b]
                grip_h[b] *= decay[b]
            dx = xl[i] - xl[i - 1]
            if dx != 0.0:
                sg = 1.0 if dx > 0 else -1.0
                s = sg + (s - sg) * math.exp(-abs(dx) / dp)
            vbar = dx / dt
            # the tissue shears only once the contact slides: during pre-sliding (s not yet
            # turned to the new direction) the Maxwell branches are not driven
            slide = max(s * (1.0 if vbar > 0 else -1.0), 0.0) if vbar != 0.0 else 0.0
            phi = math.copysign(abs(vbar) ** n_exp, vbar) * slide
            for b in range(nb):
                target = beta[b] * phi
                sig[b] = target + (sig[b] - target) * decay[b]
        # membranes and the cut front (only an advancing tip cuts or ruptures)
        while True:
            if k < nl and layers[k].rupture_n == 0.0 and d >= tops_l[k]:
                k += 1                          # a layer without membrane opens at its top
                continue
            limit = tops_l[k] if k < nl else math.inf
            if d > cut:
                cut = min(d, limit)
            if k < nl and d > origin[k] and d > d_prev:
                ly = layers[k]
                u = d - origin[k]
                if u >= ly.tent_mm:
                    u0 = max(d_prev - origin[k], 0.0)
                    frac = min(max((ly.tent_mm - u0) / (u - u0), 0.0), 1.0) if u > u0 else 1.0
                    tr = tl[i - 1] + frac * (ti_ - tl[i - 1]) if i > 0 else ti_
                    # the tent has relaxed while it was loaded: the force released is the
                    # relaxed one, and the torn membrane keeps no memory of its loading
                    f_rel = g_inf * ly.rupture_n + sum(
                        tent_h[b] + g[b] * (ly.rupture_n - tent_prev) for b in range(nb))
                    tent_h, tent_prev = [0.0] * nb, 0.0
                    released.append((tr, f_rel))
                    recoil.append((tr, max(min(d, tops_l[k + 1] if k + 1 < nl else math.inf)
                                           - max(cut, 0.0), 0.0)))
                    n_rupt += 1
                    ruptures.append({"cycle": cur_cycle, "layer": k, "name": ly.name,
                                     "time_s": float(tr),
                                     "tip_depth_mm": float(origin[k] + ly.tent_mm),
                                     "stage_mm": float(surf + origin[k] + ly.tent_mm),
                                     "rupture_n": float(ly.rupture_n)})
                    # the tip springs through; a deeper membrane it has already pushed past
                    # its rest position wraps the tip and tents from where the tip now is
                    for q in range(k + 1, nl):
                        origin[q] = max(origin[q], d)
                    k += 1
                    continue
            break
        # tip: membrane being tented, released ruptures, cutting at the front
        f_tent = 0.0
        if k < nl and d > origin[k]:
            ly = layers[k]
            f_tent = _tent(d - origin[k], ly.rupture_n, ly.tent_mm, a_t, k_t)
        for b in range(nb):                 # quasi-linear viscoelastic tent (same tau_k)
            tent_h[b] += g[b] * (f_tent - tent_prev)
        tent_prev = f_tent
        f_inst = f_tent
        f_mem = max(g_inf * f_tent + sum(tent_h), 0.0)   # an unloaded tent loses contact
        pending = 0.0                           # cut length the recoiling tissue has not yet gripped
        if released:
            for (tr, R) in released:
                if ti_ >= tr:
                    f_mem += R * math.exp(-(ti_ - tr) / tr_s)
                    f_inst += R * math.exp(-(ti_ - tr) / tr_s)
            for (tr, ln) in recoil:
                pending += ln * math.exp(-max(ti_ - tr, 0.0) / tr_s)
            if ti_ - released[-1][0] > 40.0 * tr_s:
                released, recoil = [], []
        j = k - 1                               # layer of the cut front
        while j >= 0 and tops_l[j] > cut:
            j -= 1
        f_cut = 0.0
        if d > 0.0 and j >= 0 and cut > 0.0:
            c_j = layers[j].cutting_n
            if j > 0 and layers[j].rupture_n == 0.0:
                # no membrane between the layers: the tip's cutting force changes over the
                # first blend_mm of the new layer (a cut front is not a point)
                c_j = layers[j - 1].cutting_n + (c_j - layers[j - 1].cutting_n) * \
                    min((cut - tops_l[j]) / _BLEND_MM, 1.0)
            # the load builds over the first delta_c of tissue (contact), unloads over delta_c
            # when the tip backs away from the front
            f_cut = c_j * min(max(1.0 - (cut - d) / dc, 0.0), 1.0, cut / dc)
        # shaft inside the cut layers
        reach = max(min(max(d, 0.0), cut) - pending, 0.0)
        fmu = 0.0
        w = min(max(d, 0.0), tip)              # tissue engaged around the tip
        for q in range(nl):
            if reach <= tops_l[q]:
                break
            Lq = min(reach, tops_l[q + 1]) - tops_l[q]
            fmu += mu[q] * Lq
            w += rvis[q] * Lq
        # the grip of each engaged piece of shaft relaxes from the time it was engaged; a
        # withdrawn piece takes its own (least relaxed, deepest) grip with it
        if reach > reach_prev:
            piece = fmu - grip_w
            t_mid = ti_ - 0.5 * dt
            grip.append([reach - reach_prev, piece, t_mid])
            grip_w = fmu
            for b in range(nb):
                grip_h[b] += g[b] * piece * math.exp(-(ti_ - t_mid) / tau[b])
        elif reach < reach_prev:
            gone = reach_prev - reach
            while grip and gone > 0.0:
                top = grip[-1]
                share = min(gone / top[0], 1.0) if top[0] > 0.0 else 1.0
                wq = top[1] * share
                for b in range(nb):
                    grip_h[b] -= g[b] * wq * math.exp(-(ti_ - top[2]) / tau[b])
                if share >= 1.0:
                    gone -= top[0]
                    grip.pop()
                else:                           # part of this piece: nothing more goes
                    top[0] -= gone
                    top[1] -= wq
                    gone = 0.0
            if not grip:
                grip_h = [0.0] * nb
            grip_w = fmu if grip else 0.0
        reach_prev = reach
        f_grip = max(g_inf * grip_w + sum(grip_h), 0.0) if grip else 0.0
        o_mem[i] = f_mem
        o_cut[i] = f_cut
        o_inst[i] = f_inst + f_cut + fmu * (s if s >= 0.0 else rho * s)
        o_fp[i] = f_grip * max(s, 0.0)
        o_fn[i] = f_grip * rho * min(s, 0.0)
        sv = 0.0
        for b in range(nb):
            branch[b, i] = w * sig[b]
            sv += sig[b]
        o_vis[i] = w * sv
        o_s[i] = s
        o_d[i] = d
        o_c[i] = cut
        o_w[i] = w
        layer_idx[i] = j if d > 0.0 else -1
        rupt_count[i] = n_rupt
        d_prev = d
    # the cutting load relaxes through the hereditary integral with the same time constants;
    # the tip cannot pull on the tissue ahead of it, so the load ends at 0 once contact is lost
    out["cutting"] = np.maximum(_relax(t, out["cutting"], g, tau), 0.0)
    out["friction"] = out["friction_pos"] + out["friction_neg"]
    out["total"] = out["membrane"] + out["cutting"] + out["friction"] + out["viscous"]
    for b in range(branch.shape[0]):
        out[f"viscous_branch{b + 1}"] = branch[b]
    out["layer"] = layer_idx
    out["ruptures_so_far"] = rupt_count
    return out, ruptures


def _relax(t: Array, e: Array, g: Sequence[float], tau: Sequence[float]) -> Array:
    """Hereditary integral int G(t - s) de(s), G = g_inf + sum_k g_k exp(-t/tau_k),
    g_inf = 1 - sum g_k, exact for e linear between samples."""
    n = len(t)
    out = (1.0 - float(sum(g))) * e
    if n < 2:
        return out
    dt = np.diff(t)
    de = np.diff(e)
    for gk, tk in zip(g, tau):
        if gk == 0.0:
            continue
        a = np.exp(-dt / tk)
        c = gk * de * (tk / dt) * (1.0 - a)
        h = np.zeros(n)
        if np.ptp(a) <= 1e-12:                    # uniform steps: one linear filter
            h[1:] = lfilter([1.0], [1.0, -float(a[0])], c)
        else:
            hk, al, cl = 0.0, a.tolist(), c.tolist()
            for i in range(n - 1):
                hk = al[i] * hk + cl[i]
                h[i + 1] = hk
        out = out + h
    return out


def simulate_phantom(spec_or_name: PhantomSpec | str = "skin-on-muscle", rate_hz: float | None = None,
                     seed: int = 1, **overrides: Any) -> PhantomResult:
    """Simulate one record of a preset (by name), of ``"lab"`` (a random tissue drawn from the
    measured distributions with this seed) or of a given spec.

    overrides (optional): speeds_mm_s, stroke_mm, dwell_s, accel_mm_s2, surface_mm, noise_n,
    offset_n, drift_n_s, walk_n_sqrt_s, jitter, gaps, gap_s, force_sign, depth_sign.
    The seed draws the lab tissue (for ``"lab"``) and the sensor's noise, walk, jitter and gaps.
    """
    spec = resolve_spec(spec_or_name, seed)
    spec = apply_overrides(spec, rate_hz=rate_hz, **overrides)
    spec.validate()
    return _simulate_spec(spec, seed)


def resolve_spec(spec_or_name: PhantomSpec | str, seed: int) -> PhantomSpec:
    if isinstance(spec_or_name, PhantomSpec):
        return spec_or_name
    if spec_or_name == LAB:
        return lab_spec(seed)
    if spec_or_name not in PRESETS:
        raise ValueError(f"unknown phantom {spec_or_name!r} (have: {', '.join(PRESETS)}, {LAB})")
    return PRESETS[spec_or_name]


_MOTION_KEYS = ("speeds_mm_s", "stroke_mm", "dwell_s", "accel_mm_s2", "rest_s")
_SENSOR_KEYS = ("rate_hz", "noise_n", "offset_n", "drift_n_s", "walk_n_sqrt_s", "jitter", "gaps",
                "gap_s", "force_sign", "depth_sign")


def apply_overrides(spec: PhantomSpec, **overrides: Any) -> PhantomSpec:
    mo = {k: v for k, v in overrides.items() if k in _MOTION_KEYS and v is not None}
    se = {k: v for k, v in overrides.items() if k in _SENSOR_KEYS and v is not None}
    unknown = set(overrides) - set(_MOTION_KEYS) - set(_SENSOR_KEYS) - {"surface_mm"}
    if unknown:
        raise ValueError(f"unknown phantom option(s): {', '.join(sorted(unknown))}")
    if "speeds_mm_s" in mo:
        mo["speeds_mm_s"] = tuple(float(v) for v in mo["speeds_mm_s"])
    spec = replace(spec, motion=replace(spec.motion, **mo), sensor=replace(spec.sensor, **se))
    if overrides.get("surface_mm") is not None:
        spec = replace(spec, surface_mm=float(overrides["surface_mm"]))
    return spec


def _simulate_spec(spec: PhantomSpec, seed: int) -> PhantomResult:
    se = spec.sensor
    rng = np.random.default_rng([seed, 0x5E75])   # the sensor's own stream
    total = record_duration(spec.motion)
    n = int(math.floor(total * se.rate_hz)) + 1
    t = np.arange(n) / se.rate_hz
    if se.jitter > 0.0:
        t = t + rng.uniform(-se.jitter, se.jitter, n) / se.rate_hz
        t[0] = 0.0
    x, v, phase, cycle, marks = stage_motion(t, spec.motion)
    comp, ruptures = _tissue_force(spec, t, x, cycle)
    f_true = comp["total"]
    drift = se.drift_n_s * t
    if se.walk_n_sqrt_s > 0.0:
        steps = rng.normal(0.0, 1.0, n) * se.walk_n_sqrt_s * np.sqrt(np.diff(t, prepend=t[0]))
        drift = drift + np.cumsum(steps)
    noise = rng.normal(0.0, se.noise_n, n) if se.noise_n > 0.0 else np.zeros(n)
    meas = f_true + se.offset_n + drift + noise
    keep = np.ones(n, dtype=bool)
    gaps = []
    for _ in range(se.gaps):
        g0 = float(rng.uniform(0.0, t[-1] - se.gap_s))
        keep &= ~((t > g0) & (t < g0 + se.gap_s))
        gaps.append([g0, g0 + se.gap_s])
    fs, ds = float(se.force_sign), float(se.depth_sign)
    samples = {name: arr[keep] for name, arr in comp.items()}
    samples.update({"phase": phase[keep], "cycle": cycle[keep], "drift_n": drift[keep],
                    "stage_mm": x[keep]})
    tops = np.concatenate([[0.0], np.cumsum([ly.thickness_mm for ly in spec.tissue.layers])])
    truth: dict[str, Any] = {
        "name": spec.name, "seed": seed,
        "surface_mm": spec.surface_mm,
        "layer_tops_mm": tops[:-1].tolist(),
        "ruptures": ruptures,
        "ruptures_per_cycle": [sum(r["cycle"] == c for r in ruptures)
                               for c in range(len(spec.motion.speeds_mm_s))],
        "cycles": marks,
        "gaps_s": gaps,
        "force_sign": se.force_sign, "depth_sign": se.depth_sign,
        "spec": asdict(spec),
        "samples": samples,
    }
    return PhantomResult(spec, t[keep], ds * x[keep], ds * v[keep], fs * meas[keep],
                         fs * f_true[keep], truth)


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
    comp, _ = _tissue_force(probe, t, x, cycle)
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


# ---------------------------------------------------------------------------------------------
# Statistics measured on a record the way the 331 trials were summarised.
def record_stats(t_s: Array, depth_mm: Array, force_n: Array, cycle_marks: Sequence[dict[str, float]],
                 surface_mm: float | None = None) -> dict[str, float]:
    """Figures of the first cycle of a record (force and depth positive on insertion).

    baseline: median force in the rest before the stage starts; peak: maximum during insertion;
    ruptures: drops > 0.15 N within 0.1 s during insertion (on a 50 ms moving average; drops
    closer than 0.15 s count once);
    dwell decay: fall of the force over the dwell relative to its start (0.1 s means); retraction
    minimum; turn-over: stage travel from the reversal until the force first crosses zero.
    """
    m = cycle_marks[0]
    f = np.asarray(force_n, dtype=float)
    t = np.asarray(t_s, dtype=float)
    base = float(np.median(f[t < m["start_s"]])) if np.any(t < m["start_s"]) else 0.0
    f = f - base
    dtm = float(np.median(np.diff(t)))
    win = max(1, int(round(0.05 / dtm)))
    fs = np.convolve(f, np.ones(win) / win, mode="same")
    ins = (t >= m["start_s"]) & (t <= m["insertion_end_s"] - 0.05)
    peak = float(np.max(f[ins]))
    ruptures = count_drops(t, fs, ins)

    def mean_near(t0: float, t1: float) -> float:
        sel = (t >= t0) & (t <= t1)
        return float(np.mean(f[sel]))
    f_start = mean_near(m["insertion_end_s"], m["insertion_end_s"] + 0.1)
    f_end = mean_near(m["retraction_start_s"] - 0.1, m["retraction_start_s"])
    ret = (t >= m["retraction_start_s"]) & (t <= m["retraction_end_s"])
    rmin = float(np.min(fs[ret]))
    ir = np.flatnonzero(ret)
    cross = ir[np.flatnonzero(fs[ir] < 0.0)]
    x_rev = float(np.max(np.abs(depth_mm)))
    turn = float(x_rev - abs(depth_mm[cross[0]])) if cross.size else float("nan")
    imin = ir[int(np.argmin(fs[ir]))]
    dw = (t >= m["insertion_end_s"]) & (t <= m["retraction_start_s"])
    tau_fast, tau_slow = dwell_time_scales(t[dw] - m["insertion_end_s"], f[dw])
    out = {"peak_n": peak, "ruptures": float(ruptures),
           "dwell_decay_pct": 100.0 * (f_start - f_end) / f_start,
           "dwell_tau_fast_s": tau_fast, "dwell_tau_slow_s": tau_slow,
           "retraction_min_n": rmin, "turnover_mm": turn,
           "min_travel_mm": float(x_rev - abs(depth_mm[imin]))}
    if surface_mm is not None:
        out["surface_mm"] = float(surface_mm)
    return out


_TAU_FAST_GRID = np.geomspace(0.05, 1.0, 24)
_TAU_SLOW_GRID = np.geomspace(1.0, 20.0, 24)


def dwell_time_scales(t: Array, f: Array) -> tuple[float, float]:
    """Time constants (fast, slow) of f = c0 + c1 exp(-t/tau_1) + c2 exp(-t/tau_2) fitted by
    least squares over a log grid (tau_1 0.05-1 s, tau_2 1-20 s; the c linear)."""
    if t.size < 8:
        return float("nan"), float("nan")
    e1 = np.exp(-t[None, :] / _TAU_FAST_GRID[:, None])
    e2 = np.exp(-t[None, :] / _TAU_SLOW_GRID[:, None])
    n1, n2 = len(_TAU_FAST_GRID), len(_TAU_SLOW_GRID)
    A = np.empty((n1, n2, t.size, 3))            # every pair's design matrix at once
    A[..., 0] = 1.0
    A[..., 1] = e1[:, None, :]
    A[..., 2] = e2[None, :, :]
    q, r = np.linalg.qr(A)
    coef = np.linalg.solve(r, np.einsum("ijnk,n->ijk", q, f)[..., None])[..., 0]
    sse = np.sum((np.einsum("ijnk,ijk->ijn", A, coef) - f) ** 2, axis=-1)
    i, j = np.unravel_index(int(np.argmin(sse)), sse.shape)
    return float(_TAU_FAST_GRID[i]), float(_TAU_SLOW_GRID[j])


def count_drops(t: Array, fs: Array, sel: Array, drop_n: float = 0.15, within_s: float = 0.1,
                merge_s: float = 0.15) -> int:
    """Number of drops larger than drop_n within within_s, both ends inside sel; drops whose
    marked samples are closer than merge_s count as one."""
    idx = np.flatnonzero(sel)
    if idx.size < 2:
        return 0
    seg_t, seg_f = t[idx], fs[idx]
    j_end = np.searchsorted(seg_t, seg_t + within_s, side="right")
    # forward running minimum over (k, j_end[k]) by a sparse-table of minima
    n = seg_f.size
    levels = [seg_f]
    span = 1
    while 2 * span <= n:
        prev = levels[-1]
        levels.append(np.minimum(prev[:-span], prev[span:]) if prev.size > span else prev)
        span *= 2
    lo = np.arange(n) + 1
    hi = np.minimum(j_end, n)                     # exclusive
    length = hi - lo
    ok = length > 0
    lvl = np.zeros(n, dtype=int)
    lvl[ok] = np.floor(np.log2(length[ok])).astype(int)
    fmin = np.full(n, np.inf)
    for L in np.unique(lvl[ok]):
        rows = np.flatnonzero(ok & (lvl == L))
        tab = levels[L]
        w = 1 << L
        fmin[rows] = np.minimum(tab[lo[rows]], tab[hi[rows] - w])
    mark = np.flatnonzero((seg_f - fmin) > drop_n)
    if mark.size == 0:
        return 0
    return int(1 + np.count_nonzero(np.diff(seg_t[mark]) > merge_s))


def result_stats(res: PhantomResult) -> dict[str, float]:
    fs, ds = res.spec.sensor.force_sign, res.spec.sensor.depth_sign
    st = record_stats(res.t_s, ds * res.depth_mm, fs * res.force_n, res.truth["cycles"],
                      res.truth["surface_mm"])
    st["noise_mn"] = 1e3 * res.spec.sensor.noise_n
    st["rate_hz"] = res.spec.sensor.rate_hz
    return st


def lab_statistics(n: int = 100, first_seed: int = 1) -> dict[str, Any]:
    """Statistics over n lab records (seeds first_seed ...): p10/median/p90 and rupture shares."""
    rows = [result_stats(simulate_phantom(LAB, seed=s)) for s in range(first_seed, first_seed + n)]
    return summarise(rows)


def summarise(rows: list[dict[str, float]]) -> dict[str, Any]:
    out: dict[str, Any] = {"n": len(rows)}
    for key in ("rate_hz", "noise_mn", "surface_mm", "peak_n", "dwell_decay_pct",
                "dwell_tau_fast_s", "dwell_tau_slow_s", "retraction_min_n", "turnover_mm",
                "min_travel_mm"):
        vals = np.array([r[key] for r in rows if key in r and np.isfinite(r[key])])
        out[key] = tuple(float(q) for q in np.percentile(vals, [10, 50, 90])) if vals.size else None
    counts = np.array([int(r["ruptures"]) for r in rows])
    out["ruptures"] = {k: float(np.mean(np.minimum(counts, 5) == k)) for k in range(6)}
    return out


def format_stats_table(stats: dict[str, Any], presets: dict[str, dict[str, float]] | None = None,
                       first_seed: int = 1) -> str:
    """The lab statistics beside the measured ones (and one row per preset)."""
    lines = [f"{'figure':22s} {'measured p10/med/p90':>24s} {'phantom lab p10/med/p90':>26s}"]
    labels = {"rate_hz": "sampling, Hz", "noise_mn": "noise, mN", "surface_mm": "surface, mm",
              "peak_n": "insertion peak, N", "dwell_decay_pct": "dwell decay, %",
              "dwell_tau_fast_s": "dwell fast tau, s", "dwell_tau_slow_s": "dwell slow tau, s",
              "retraction_min_n": "retraction min, N", "turnover_mm": "turn-over travel, mm"}
    ranges = {"dwell_tau_fast_s": "~0.3", "dwell_tau_slow_s": "2 - 5"}
    for key, label in labels.items():
        meas = ranges.get(key) or " / ".join(f"{v:.3g}" for v in MEASURED[key])
        ph = stats.get(key)
        ph_txt = " / ".join(f"{v:.3g}" for v in ph) if ph else "-"
        lines.append(f"{label:22s} {meas:>24s} {ph_txt:>26s}")
    mr = MEASURED["ruptures"]
    pr = stats["ruptures"]
    meas_r = f"{mr[0]:.0%} {mr[1]:.0%} {mr[2]:.0%} {mr[3]:.0%} {mr[4] + mr[5]:.0%}"
    ph_r = f"{pr[0]:.0%} {pr[1]:.0%} {pr[2]:.0%} {pr[3]:.0%} {pr[4] + pr[5]:.0%}"
    lines.append(f"{'ruptures 0/1/2/3/4+':22s} {meas_r:>24s} {ph_r:>26s}")
    mt = stats.get("min_travel_mm")
    if mt:
        lines.append(f"{'min. travel, mm':22s} {'(not measured)':>24s} "
                     f"{' / '.join(f'{v:.3g}' for v in mt):>26s}")
    last = first_seed + stats["n"] - 1
    lines.append(f"(phantom: {stats['n']} lab records, seeds {first_seed}..{last}; turn-over = stage "
                 "travel from the reversal to the first zero crossing)")
    if presets:
        lines.append("")
        lines.append(f"{'preset':16s} {'peak N':>7s} {'rupt':>5s} {'decay %':>8s} "
                     f"{'ret.min N':>10s} {'turn mm':>8s} {'surface':>8s}")
        for name, st in presets.items():
            lines.append(f"{name:16s} {st['peak_n']:7.2f} {int(st['ruptures']):5d} "
                         f"{st['dwell_decay_pct']:8.1f} {st['retraction_min_n']:10.2f} "
                         f"{st['turnover_mm']:8.2f} {st['surface_mm']:8.1f}")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# Files and the command line
def truth_path(csv_path: str | os.PathLike[str]) -> str:
    """The sidecar of FILE.csv is FILE.truth.json."""
    base = os.fspath(csv_path)
    return (base[:-4] if base.lower().endswith(".csv") else base) + ".truth.json"


def truth_json(res: PhantomResult) -> str:
    def plain(obj: Any) -> Any:
        if isinstance(obj, dict):
            return {str(k): plain(v) for k, v in obj.items()}
        if isinstance(obj, (list, tuple)):
            return [plain(v) for v in obj]
        if isinstance(obj, np.ndarray):
            return obj.tolist()
        if isinstance(obj, np.generic):
            return obj.item()
        return obj
    return json.dumps(plain(res.truth), separators=(",", ":"))


def write_phantom(csv_path: str | os.PathLike[str], res: PhantomResult) -> str:
    """Write the record (CSV) and its ground truth (JSON sidecar); returns the sidecar's path."""
    from .safe_write import Outputs
    side = truth_path(csv_path)
    with Outputs() as outs:                     # both files or neither
        outs.write_lines(outs.add(side, "--out"), [truth_json(res)])
        outs.write_lines(outs.add(csv_path, "--out"), res.csv_lines())
        outs.commit()
    return side


def _speeds(text: str) -> tuple[float, ...]:
    try:
        vals = tuple(float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a comma-separated list of speeds: {text!r}") \
            from None
    return vals


def _sign(text: str) -> int:
    if text not in ("1", "+1", "-1"):
        raise argparse.ArgumentTypeError(f"must be +1 or -1 (got {text!r})")
    return int(text)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``nte-ref phantom``."""
    p.add_argument("name", nargs="?", default="skin-on-muscle",
                   help=f"preset ({', '.join(PRESETS)}) or '{LAB}' (random tissue drawn from the "
                        "measured distributions; the seed picks it); default skin-on-muscle")
    p.add_argument("--out", metavar="FILE.csv",
                   help="record to write (the ground truth goes to FILE.truth.json)")
    p.add_argument("--seed", type=int, default=1, metavar="K",
                   help="seed of the sensor noise (and of the lab tissue), default 1")
    p.add_argument("--rate", type=float, metavar="HZ", help="sample rate (default: the preset's)")
    p.add_argument("--speed", type=_speeds, metavar="MM_S[,MM_S...]",
                   help="cruise speed(s), one insertion cycle per speed (default: the preset's)")
    p.add_argument("--stroke", type=float, metavar="MM", help="stage stroke (default 25)")
    p.add_argument("--dwell", type=float, metavar="S", help="dwell at full stroke (default 5.26)")
    p.add_argument("--surface", type=float, metavar="MM",
                   help="stage position where the tip touches the tissue (default: the preset's)")
    p.add_argument("--noise", type=float, metavar="N", help="white force noise sd (default 0.012)")
    p.add_argument("--offset", type=float, metavar="N", help="sensor offset after tare")
    p.add_argument("--drift", type=float, metavar="N_S", help="linear sensor drift, N/s")
    p.add_argument("--walk", type=float, metavar="N_SQRT_S", help="random-walk drift intensity")
    p.add_argument("--jitter", type=float, metavar="F",
                   help="timestamp jitter, fraction of the period, in [0, 0.5)")
    p.add_argument("--gaps", type=int, metavar="K", help="number of missing stretches (0.3 s)")
    p.add_argument("--force-sign", type=_sign, metavar="+1|-1",
                   help="-1: force recorded negative on insertion")
    p.add_argument("--depth-sign", type=_sign, metavar="+1|-1",
                   help="-1: depth recorded negative on insertion")
    p.add_argument("--stats", action="store_true",
                   help="print the lab phantom's statistics beside the measured ones (and each "
                        "preset's) instead of writing a record")
    p.add_argument("--trials", type=int, default=100, metavar="N",
                   help="lab records for --stats (default 100)")
    p.add_argument("--first-seed", type=int, default=1001, metavar="K",
                   help="first lab seed for --stats (default 1001: seeds 1-100 tuned the "
                        "generator, 1001 on were not looked at while tuning)")


def run(a: argparse.Namespace) -> int:
    """Handler of ``nte-ref phantom``: bad values raise ValueError (the caller exits 2)."""
    if a.stats:
        if a.trials < 1:
            raise ValueError(f"--trials must be >= 1 (got {a.trials})")
        if a.first_seed < 0:
            raise ValueError(f"--first-seed must be >= 0 (got {a.first_seed})")
        stats = lab_statistics(a.trials, a.first_seed)
        presets = {n: result_stats(simulate_phantom(n, seed=1)) for n in PRESETS}
        print(format_stats_table(stats, presets, a.first_seed))
        return 0
    if not a.out:
        raise ValueError("--out FILE.csv is required (or --stats)")
    res = simulate_phantom(a.name, rate_hz=a.rate, seed=a.seed, speeds_mm_s=a.speed,
                           stroke_mm=a.stroke, dwell_s=a.dwell, surface_mm=a.surface,
                           noise_n=a.noise, offset_n=a.offset, drift_n_s=a.drift,
                           walk_n_sqrt_s=a.walk, jitter=a.jitter, gaps=a.gaps,
                           force_sign=a.force_sign, depth_sign=a.depth_sign)
    side = write_phantom(a.out, res)
    tr = res.truth
    print(f"wrote {len(res.t_s)} samples ({res.t_s[-1]:.2f} s) to {a.out} and the truth to "
          f"{side}: surface at {tr['surface_mm']:.2f} mm, ruptures per cycle "
          f"{tr['ruptures_per_cycle']}")
    return 0
