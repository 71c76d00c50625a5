"""Insertion-dwell-retraction depth trajectories of the estimator's scenarios (LSPB moves).

The scenario every simulated record of ``nte-ref simulate``, ``evaluate``, ``bench``,
``fixedpoint`` and ``plausible`` follows: from the surface to a depth and back, cycle after cycle,
sampled at a fixed rate with a phase per sample.  The move itself is
:func:`reference_py.sim.motion.lspb_move`, the one the realistic phantom's stage makes too.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..fmath import Array
from .motion import lspb_move, lspb_timing


@dataclass(frozen=True)
class TrajectorySpec:
    depth_mm: float = 50.0        # insertion depth
    speed_mm_s: float = 10.0      # cruise speed of insertion and retraction
    accel_mm_s2: float = 100.0    # blend acceleration
    dwell_s: float = 1.0          # rest at full depth
    rate_hz: float = 200.0        # sample rate
    rest_s: float = 0.1           # rest at the surface before the first and after each cycle
    cycles: int = 1               # identical insertion cycles

    def validate(self) -> None:
        for name in ("depth_mm", "speed_mm_s", "accel_mm_s2", "rate_hz"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be finite and > 0 (got {v!r})")
        for name in ("dwell_s", "rest_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be finite and >= 0 (got {v!r})")
        if self.cycles < 1:
            raise ValueError("cycles must be >= 1")


def lspb_profile(spec: TrajectorySpec) -> tuple[Array, Array, Array, Array]:
    """Sampled (t_s, depth_mm, velocity_mm_s, phase) for the whole scenario.

    phase: 0 out of tissue / rest, 1 insertion (v > 0), 2 dwell, 3 retraction (v < 0).
    """
    spec.validate()
    move = lspb_timing(spec.depth_mm, spec.speed_mm_s, spec.accel_mm_s2)[2]
    cycle = move + spec.dwell_s + move + spec.rest_s
    total = spec.rest_s + spec.cycles * cycle
    n = int(math.floor(total * spec.rate_hz + 1e-9)) + 1
    t = np.arange(n, dtype=np.float64) / spec.rate_hz
    depth = np.zeros(n)
    vel = np.zeros(n)
    phase = np.zeros(n, dtype=np.int8)
    for c in range(spec.cycles):
        t0 = spec.rest_s + c * cycle
        tin = t - t0
        sel = (tin >= 0.0) & (tin <= move)
        p, vv, _ = lspb_move(tin[sel], spec.depth_mm, spec.speed_mm_s, spec.accel_mm_s2)
        depth[sel], vel[sel] = p, vv
        phase[sel] = np.where(vv > 0, 1, 0)
        sel = (tin > move) & (tin < move + spec.dwell_s)
        depth[sel], vel[sel], phase[sel] = spec.depth_mm, 0.0, 2
        tout = tin - (move + spec.dwell_s)
        sel = (tout >= 0.0) & (tout <= move)
        p, vv, _ = lspb_move(tout[sel], spec.depth_mm, spec.speed_mm_s, spec.accel_mm_s2)
        depth[sel], vel[sel] = spec.depth_mm - p, -vv
        phase[sel] = np.where(vv > 0, 3, 2)
    # samples that fall on a segment boundary carry rounding dust (|v| ~ 1e-13): they are at rest
    depth = np.where(np.abs(depth) < 1e-9, 0.0, depth)
    still = np.abs(vel) < 1e-9
    vel = np.where(still, 0.0, vel)
    phase = np.where(still & (phase != 0), np.where(depth > 0.0, 2, 0), phase).astype(np.int8)
    return t, depth, vel, phase
