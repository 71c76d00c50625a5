"""What a realistic phantom is made of: its tissue layers, the stage's motion and the sensor.

The records of :mod:`reference_py.sim.phantom` are fully described by a :class:`PhantomSpec`: the
tissue (a stack of :class:`Layer` and the properties of the whole stack, read by
:mod:`reference_py.sim.tissue`), where the stage touches it, the motion
(:class:`reference_py.sim.motion.Motion`) and the :class:`Sensor`.  The presets and the random
``lab`` tissue (:mod:`reference_py.sim.calibration`) are specs too; ``validate`` is the one check
of every bound the command line promises (its messages name the options).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..config import EstimatorConfig
from .motion import Motion


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
        # bounded like nte-ref simulate (a stroke within the estimator's depth range): a
        # record of at most 10 M samples
        for nm, v, hi in (("stroke_mm (--stroke)", m.stroke_mm, EstimatorConfig.depth_max_mm),
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
