"""The verdict on what the final model leaves: stretches of the residual that stay above a
multiple of the noise, where they are and what they look like (shape.py)."""
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


def unexplained(preps: list[Prepared], pred: list[Array]) -> list[dict[str, float | str]]:
    """Stretches where the final residual, smoothed over UNEXPLAINED_WINDOW_S, stays above
    UNEXPLAINED_X noise standard deviations: phase, time and depth span, size, and for the
    largest ones what the residual looks like there (shape.classify: drop, slope change, ...)."""
    out: list[dict[str, float | str]] = []
    spans: list[tuple[Prepared, Array, int, int]] = []
    for p, pr in zip(preps, pred):
        r = p.force_n + p.tare_n - pr
        dt = float(np.median(np.diff(p.t_s)))
        w = max(int(round(UNEXPLAINED_WINDOW_S / dt)), 1)
        rs = evmod.smooth(r, w)
        hot = np.abs(rs) > UNEXPLAINED_X * p.noise_n
        if not hot.any():
            continue
        edges = np.flatnonzero(np.diff(np.concatenate([[0], hot.astype(int), [0]])))
        for a, b in zip(edges[::2], edges[1::2]):
            if p.t_s[b - 1] - p.t_s[a] < UNEXPLAINED_WINDOW_S:
                continue
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


__all__ = ["UNEXPLAINED_SHAPES", "UNEXPLAINED_WINDOW_S", "UNEXPLAINED_X", "unexplained"]
