"""The stage's motion: LSPB moves and the phantom's insertion-dwell-retraction cycles.

Every synthetic record is driven by the same move: ``distance`` mm with linear segments and
parabolic blends (LSPB) -- accelerate at ``accel`` to the cruise speed, cruise, brake at ``accel``
-- or a triangle when the distance is too short to reach the cruise speed.  It is written once,
here: :func:`reference_py.sim.trajectory.lspb_profile` samples the estimator's scenarios from
it (depth from 0, a phase per sample) and :func:`stage_motion` the phantom's stage (one cycle per
speed, from rest in air; the tissue surface lies somewhere along the stroke).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..fmath import Array


def lspb_timing(distance: float, speed: float, accel: float) -> tuple[float, float, float]:
    """Cruise speed actually reached, blend time and duration (s) of a 0 -> distance move."""
    v = speed
    if distance * accel < v * v:          # too short to reach the cruise speed: triangular
        v = math.sqrt(distance * accel)
    tb = v / accel
    return v, tb, distance / v + tb


def lspb_move(t: Array, distance: float, speed: float, accel: float) -> tuple[Array, Array, float]:
    """Position and velocity of a 0 -> distance LSPB move at times t (s); also its duration.

    Before the start the move is at 0 and after its end at ``distance`` (t is clipped)."""
    v, tb, duration = lspb_timing(distance, speed, accel)
    t = np.clip(t, 0.0, duration)
    pos = np.where(t < tb, 0.5 * accel * t * t,
                   np.where(t <= duration - tb, 0.5 * accel * tb * tb + v * (t - tb),
                            distance - 0.5 * accel * (duration - t) ** 2))
    vel = np.where(t < tb, accel * t, np.where(t <= duration - tb, v, accel * (duration - t)))
    return pos, vel, duration


@dataclass(frozen=True)
class Motion:
    """The phantom's stage: one insertion-dwell-retraction cycle per speed."""
    speeds_mm_s: tuple[float, ...] = (2.0,)   # one insertion-dwell-retraction cycle per speed
    stroke_mm: float = 25.0
    accel_mm_s2: float = 20.0
    dwell_s: float = 5.26
    rest_s: float = 1.0                       # at 0 before the first cycle and after each


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
        a, D = motion.accel_mm_s2, motion.stroke_mm
        vc, _, dur = lspb_timing(D, speed, a)
        t1, t2, t3 = t0 + dur, t0 + dur + motion.dwell_s, t0 + 2 * dur + motion.dwell_s
        for (ta, sgn, base) in ((t0, 1.0, 0.0), (t2, -1.0, D)):
            tau = t_s - ta
            # open at both ends: the samples on a boundary belong to the rest or the dwell
            sel = (tau > 0.0) & (tau < dur)
            pos, vel, _ = lspb_move(tau[sel], D, speed, a)
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
    """Length (s) of the phantom's record: the last cycle's end and the rest after it."""
    return float(stage_motion(np.zeros(1), motion)[4][-1]["retraction_end_s"] + motion.rest_s)
