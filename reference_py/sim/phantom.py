"""One record of the realistic phantom: the tissue force as a sensor records it, and its truth.

Where ``nte-ref simulate`` produces the paper's Model II force, this simulator produces records
that look like measured robotic insertions (statistics of 331 public trials, see PHANTOM.md): the
stage starts in air and touches the tissue somewhere along its stroke, each tissue layer is tented
until its membrane ruptures, the tip then cuts through the layer while friction grows along the
shaft, the tissue relaxes while the needle is held, the friction turns over gradually when the
motion reverses (:mod:`reference_py.sim.tissue`), and the force sensor adds an offset, a drift
and noise:

* sensor     force_n = +-(F + offset + drift(t) + noise): tare residue, linear drift plus a
             random walk, white noise; optional timestamp jitter, gaps and sign conventions.


Units: mm, s, N throughout.  ``simulate_phantom`` returns the samples and a truth dictionary;
``csv_lines`` and ``truth_json`` are the two files ``nte-ref phantom`` writes (the CSV has the
columns of ``nte-ref simulate``).
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from ..fmath import Array
from .calibration import LAB, PRESETS, lab_spec
from .motion import record_duration, stage_motion
from .spec import PhantomSpec
from .tissue import tissue_force


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
    comp, ruptures = tissue_force(spec, t, x, cycle)
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
