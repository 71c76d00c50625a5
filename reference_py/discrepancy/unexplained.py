"""The verdict on what the final model leaves: stretches of the residual that stay above a
multiple of the noise, where they are and what they look like (shape.py); and a series of
force drops too regular to be tissue layers (stick-slip), which the base model would otherwise
take in as layers and so hide from the residual."""
from __future__ import annotations

import numpy as np

from . import evidence as evmod
from . import shape as shmod
from ..fmath import Array
from .prep import PHASES, Prepared

#: structure left in a phase counts as "unexplained" above this multiple of the noise (RMS of
#: the residual smoothed over UNEXPLAINED_WINDOW_S, against the noise standard deviation)
UNEXPLAINED_X = 3.0
UNEXPLAINED_WINDOW_S = 0.5
#: the largest this many stretches are described by their shape (drop, slope change, ...)
UNEXPLAINED_SHAPES = 10
#: A trial's ruptures are a stick-slip series, not layers, when at least PERIODIC_DROPS_MIN of
#: them have about one size (within PERIODIC_SIZE_RATIO of their median, either way) and fall
#: about evenly along the travel: every gap between them within PERIODIC_GAP_TOL of a whole
#: number (1 to PERIODIC_GAP_MAX: a drop the detector missed) of the series' period.  Tissue
#: can look like that over a few layers: 2 of 23 records of the phantom's lab tissue (seeds
#: 311-333) tore four layers of one size about evenly (2.2 and 4.5 mm apart), so a series
#: needs six; the tests' stick-slip makes 5-40 drops of one size per insertion.
PERIODIC_DROPS_MIN = 6
PERIODIC_SIZE_RATIO = 1.5
PERIODIC_GAP_TOL = 0.15
PERIODIC_GAP_MAX = 3


def stretches(t_s: Array, r: Array, noise_n: float) -> tuple[Array, int, list[tuple[int, int]]]:
    """The residual ``r`` smoothed over UNEXPLAINED_WINDOW_S (a window of ``w`` samples) and the
    stretches [a, b) where it stays above UNEXPLAINED_X times the noise for at least that long."""
    dt = float(np.median(np.diff(t_s)))
    w = max(int(round(UNEXPLAINED_WINDOW_S / dt)), 1)
    rs = evmod.smooth(r, w)
    hot = np.abs(rs) > UNEXPLAINED_X * noise_n
    edges = np.flatnonzero(np.diff(np.concatenate([[0], hot.astype(int), [0]])))
    return rs, w, [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])
                   if t_s[b - 1] - t_s[a] >= UNEXPLAINED_WINDOW_S]


def unexplained(preps: list[Prepared], pred: list[Array]) -> list[dict[str, float | str]]:
    """Stretches where the final residual, smoothed over UNEXPLAINED_WINDOW_S, stays above
    UNEXPLAINED_X noise standard deviations: phase, time and depth span, size, and for the
    largest ones what the residual looks like there (shape.classify: drop, slope change, ...)."""
    out: list[dict[str, float | str]] = []
    spans: list[tuple[Prepared, Array, int, int]] = []
    for p, pr in zip(preps, pred):
        r = p.force_n + p.tare_n - pr
        rs, w, hot_spans = stretches(p.t_s, r, p.noise_n)
        for a, b in hot_spans:
            ph = np.bincount(p.phase[a:b], minlength=len(PHASES))
            l = p.stage_mm[a:b] - p.surface_mm
            out.append({"trial": p.name, "phase": PHASES[int(np.argmax(ph))],
                        "t_from_s": float(p.t_s[a]), "t_to_s": float(p.t_s[b - 1]),
                        "depth_from_mm": float(np.min(l)), "depth_to_mm": float(np.max(l)),
                        "peak_n": float(np.max(np.abs(rs[a:b]))),
                        "rms_n": float(np.sqrt(np.mean(r[a:b] ** 2))),
                        "over_noise": float(np.max(np.abs(rs[a:b])) / p.noise_n)})
            # the smoothing spreads a step over a window: look from a window before to a window
            # after, where the level on either side shows
            spans.append((p, r, max(a - w, 0), min(b + w, len(r))))
    order = sorted(range(len(out)), key=lambda i: -float(out[i]["over_noise"]))
    out = [out[i] for i in order]
    for d, i in zip(out[:UNEXPLAINED_SHAPES], order):
        p, r, a, b = spans[i]
        sh = shmod.classify(p.t_s[a:b], r[a:b])
        k = min(int(np.searchsorted(p.t_s, float(sh["at_s"]))), len(p.t_s) - 1)
        d.update({"looks_like": str(sh["shape"]), "at_s": float(sh["at_s"]),
                  "at_depth_mm": float(p.stage_mm[k] - p.surface_mm),
                  "size_n": float(sh["size_n"]), "frequency_hz": float(sh["frequency_hz"])})
        if "until_s" in sh:                   # a drop or rise that comes back
            d["until_s"] = float(sh["until_s"])
        d["description"] = shmod.describe(sh, float(d["at_depth_mm"]))
    return out


def periodic_drops(preps: list[Prepared], ruptures: list[list[dict[str, float]]]
                   ) -> list[dict[str, float | str]]:
    """Per trial whose ruptures (evidence.ruptures: depth_mm, t_s, drop_n) hold a stick-slip
    series (see PERIODIC_DROPS_MIN), one verdict entry like unexplained()'s, looks_like
    "periodic drops": where the series runs, its drop and period."""
    out: list[dict[str, float | str]] = []
    for p, rr in zip(preps, ruptures):
        if len(rr) < PERIODIC_DROPS_MIN:
            continue
        drop = np.array([float(r["drop_n"]) for r in rr])
        mid = float(np.median(drop))
        same = (drop >= mid / PERIODIC_SIZE_RATIO) & (drop <= mid * PERIODIC_SIZE_RATIO)
        if int(np.sum(same)) < PERIODIC_DROPS_MIN:
            continue
        depth = np.array([float(r["depth_mm"]) for r in rr])[same]
        t = np.array([float(r["t_s"]) for r in rr])[same]
        order = np.argsort(depth)
        depth, t = depth[order], t[order]
        gaps = np.diff(depth)
        if np.min(gaps) <= 0.0:
            continue
        # the period: the gaps of one period (a missed drop makes a gap of two or three)
        period = float(np.median(gaps[gaps <= 1.5 * np.min(gaps)]))
        whole = np.round(gaps / period)
        if np.any(whole < 1) or np.any(whole > PERIODIC_GAP_MAX) or \
                np.any(np.abs(gaps / period - whole) > PERIODIC_GAP_TOL):
            continue
        every_s = float(np.median(np.diff(t) / whole))
        out.append({"trial": p.name, "phase": "insertion",
                    "t_from_s": float(t[0]), "t_to_s": float(t[-1]),
                    "depth_from_mm": float(depth[0]), "depth_to_mm": float(depth[-1]),
                    "peak_n": mid, "rms_n": mid, "over_noise": mid / p.noise_n,
                    "looks_like": "periodic drops", "at_s": float(t[0]),
                    "at_depth_mm": float(depth[0]), "size_n": -mid,
                    "frequency_hz": 1.0 / every_s if every_s > 0 else 0.0,
                    "drops": len(depth), "period_mm": period,
                    "description": (f"{len(depth)} drops of about {mid:.3g} N every "
                                    f"{period:.2g} mm ({every_s:.2g} s) from depth "
                                    f"{depth[0]:.1f} to {depth[-1]:.1f} mm: stick-slip, not "
                                    "layers")})
    return out


__all__ = ["PERIODIC_DROPS_MIN", "PERIODIC_GAP_MAX", "PERIODIC_GAP_TOL", "PERIODIC_SIZE_RATIO",
           "UNEXPLAINED_SHAPES", "UNEXPLAINED_WINDOW_S", "UNEXPLAINED_X", "periodic_drops",
           "stretches", "unexplained"]
