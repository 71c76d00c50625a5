"""What a stretch of residual looks like, so the "unexplained" verdict can say more than its size.

The residual (data less model, N) over a stretch is fitted by a handful of shapes, each by linear
least squares (its break time or frequency on a grid), and the shape with the lowest Bayesian
information criterion wins, provided it beats a constant level by ``SHAPE_BIC_MIN``:

- ``drop`` / ``rise``: a level that changes at once, c + h H(t - t0): the data fall (h < 0: a
  rupture, a layer letting go) or rise (h > 0) against the model at t0 -- and, if the level comes
  back within the stretch, c + h on [t0, t1) only (``until_s``: a layer found at the wrong depth,
  a tear the model has but later, a transient);
- ``slope change``: c + s max(t - t0, 0): the data start to climb or fall away from the model at t0
  (a stiffness, a cutting force or a friction the model lacks from there on);
- ``oscillation``: c + a sin(w t) + b cos(w t), at least ``SHAPE_MIN_CYCLES`` periods in the
  stretch: a motion line, stick-slip, a resonance;
- ``trend``: c + b t, the residual drifts over the whole stretch;
- ``no simple shape`` when nothing beats a level: the residual is off, in no form named here.

What the tool names is a description of the residual, not an effect: the report's vocabulary of
effects stays in ``effects``.
"""
from __future__ import annotations

import numpy as np

from ..fmath import Array

#: a shape must beat a constant level by this BIC difference to be named (strong evidence)
SHAPE_BIC_MIN = 10.0
#: an oscillation shows at least this many periods within the stretch
SHAPE_MIN_CYCLES = 2.0
#: break times tried: this many, evenly spaced over the stretch's inner 90 %
SHAPE_BREAKS = 60
#: pulse edges tried: this many, evenly spaced over the stretch (every pair of them)
SHAPE_PULSE_EDGES = 25
#: frequencies tried (Hz): this many on a log grid up to a quarter of the sampling rate
SHAPE_FREQUENCIES = 60


def _fit(cols: list[Array], y: Array) -> tuple[float, Array]:
    a = np.column_stack(cols)
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    return float(np.sum((y - a @ coef) ** 2)), coef


def _bic(sse: float, n: int, k: int) -> float:
    return n * float(np.log(max(sse, 1e-300) / n)) + k * float(np.log(n))


def classify(t_s: Array, residual_n: Array) -> dict[str, float | str]:
    """The residual's shape over one stretch: ``shape`` (one of the names above), ``at_s`` (the
    break, the pulse's start, or the stretch's middle), ``size_n`` (the step or pulse height, the
    change of level after the break by the stretch's end, the oscillation's amplitude, the trend's
    change over the stretch, or the largest departure), ``frequency_hz`` for an oscillation (else
    0) and ``until_s`` where a drop or rise comes back within the stretch."""
    t = np.asarray(t_s, dtype=float)
    y = np.asarray(residual_n, dtype=float)
    n = len(y)
    one = np.ones(n)
    mid = float(0.5 * (t[0] + t[-1])) if n else 0.0
    bump = {"shape": "no simple shape", "at_s": mid, "frequency_hz": 0.0,
            "size_n": float(np.max(np.abs(y - np.median(y)))) if n else 0.0}
    if n < 12 or t[-1] <= t[0]:
        return bump
    span = float(t[-1] - t[0])
    tc = t - t[0]
    level = _bic(_fit([one], y)[0], n, 1)
    best: tuple[float, dict[str, float | str]] = (level - SHAPE_BIC_MIN, bump)

    def consider(bic: float, shape: dict[str, float | str]) -> None:
        nonlocal best
        if bic < best[0]:
            best = (bic, shape)

    sse, coef = _fit([one, tc], y)
    consider(_bic(sse, n, 2), {"shape": "trend", "at_s": mid, "frequency_hz": 0.0,
                               "size_n": float(coef[1] * span)})
    for t0 in np.linspace(t[0] + 0.05 * span, t[-1] - 0.05 * span, SHAPE_BREAKS):
        after = (t >= t0).astype(float)
        sse, coef = _fit([one, after], y)
        consider(_bic(sse, n, 3), {"shape": "drop" if coef[1] < 0 else "rise",
                                   "at_s": float(t0), "frequency_hz": 0.0,
                                   "size_n": float(coef[1])})
        hinge = np.maximum(t - t0, 0.0)
        sse, coef = _fit([one, hinge], y)
        consider(_bic(sse, n, 3), {"shape": "slope change", "at_s": float(t0),
                                   "frequency_hz": 0.0, "size_n": float(coef[1] * (t[-1] - t0))})
    edges = np.linspace(t[0], t[-1], SHAPE_PULSE_EDGES)
    for i, t0 in enumerate(edges[:-1]):
        for t1 in edges[i + 1:]:
            inside = ((t >= t0) & (t < t1)).astype(float)
            if inside.all() or not inside.any():
                continue
            sse, coef = _fit([one, inside], y)
            consider(_bic(sse, n, 4), {"shape": "drop" if coef[1] < 0 else "rise",
                                       "at_s": float(t0), "until_s": float(t1),
                                       "frequency_hz": 0.0, "size_n": float(coef[1])})
    rate = 1.0 / float(np.median(np.diff(t)))
    f_lo = SHAPE_MIN_CYCLES / span
    f_hi = rate / 4.0
    if f_hi > f_lo:
        for fq in np.geomspace(f_lo, f_hi, SHAPE_FREQUENCIES):
            w = 2.0 * np.pi * fq * tc
            sse, coef = _fit([one, np.sin(w), np.cos(w)], y)
            consider(_bic(sse, n, 4), {"shape": "oscillation", "at_s": mid,
                                       "frequency_hz": float(fq),
                                       "size_n": float(np.hypot(coef[1], coef[2]))})
    return best[1]


def describe(shape: dict[str, float | str], depth_at_mm: float) -> str:
    """One phrase for the verdict, e.g. "a drop of 0.80 N at 12.3 s, depth 18.4 mm"."""
    kind = str(shape["shape"])
    size = abs(float(shape["size_n"]))
    at = float(shape["at_s"])
    if kind in ("drop", "rise"):
        back = f", back at {float(shape['until_s']):.1f} s" if "until_s" in shape else ""
        return f"a {kind} of {size:.3g} N at {at:.1f} s, depth {depth_at_mm:.1f} mm{back}"
    if kind == "slope change":
        return (f"a slope change at {at:.1f} s, depth {depth_at_mm:.1f} mm "
                f"({float(shape['size_n']):+.3g} N by the stretch's end)")
    if kind == "oscillation":
        return f"an oscillation of {size:.3g} N at {float(shape['frequency_hz']):.2f} Hz"
    if kind == "trend":
        return f"a trend of {float(shape['size_n']):+.3g} N over the stretch"
    return f"no simple shape (largest departure {size:.3g} N)"
