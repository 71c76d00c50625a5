"""Preparing a messy recording: velocity, noise level, tare, tissue surface, phases.

Depth may be the robot stage position, so the needle meets the tissue somewhere after zero: the
surface is found from the force onset (a hinge fit around the first clear rise) and reported as an
offset.  The tare is the median force before contact.  Phases come from the depth signal (tissue
depth = stage - surface) and its velocity; the puncture that ends the loading phase is the first
clear drop of the smoothed force during the first insertion.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .effects import V_REST_MM_S, direction, find_dwells, travel_since_reversal
from ..fmath import Array
from .io import Trial

PHASES: tuple[str, ...] = ("out_of_tissue", "loading", "insertion", "dwell", "reversal",
                           "retraction", "after_exit")
#: travel after a reversal that counts as the "first millimetres after a reversal" (mm)
REVERSAL_MM = 3.0
MIN_SAMPLES = 50


class TooShort(Exception):
    """The trial cannot be split into phases (reported and skipped, not fatal)."""


@dataclass
class Prepared:
    """A trial ready for fitting: tare removed, surface found, phases labelled per sample."""

    name: str
    t_s: Array
    stage_mm: Array
    v_mm_s: Array
    force_n: Array            # tare removed
    surface_mm: float         # stage position of the tissue surface
    tare_n: float
    noise_n: float
    puncture_mm: float | None  # tissue depth of the first puncture
    phase: Array              # index into PHASES per sample
    speed_mm_s: float         # median insertion speed
    dwells: list[tuple[int, int]]
    force_sign: float = 1.0   # the recorded force was multiplied by this (-1: pull recorded +)
    depth_sign: float = 1.0   # the recorded depth was multiplied by this (-1: insertion negative)
    note: str = ""


def noise_level(f: Array) -> float:
    """Robust white-noise standard deviation from first differences (N)."""
    d = np.diff(f)
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2.0)) + 1e-12


def smooth(x: Array, w: int) -> Array:
    if w <= 1:
        return x.copy()
    k = np.ones(w) / w
    pad = np.concatenate([np.full(w // 2, x[0]), x, np.full(w - 1 - w // 2, x[-1])])
    return np.convolve(pad, k, mode="valid")


def velocity(tr: Trial) -> Array:
    if tr.velocity_mm_s is not None:
        return tr.velocity_mm_s
    v = np.gradient(tr.depth_mm, tr.t_s)
    return np.where(np.abs(v) < 1e-9, 0.0, v)


def find_surface(t: Array, x: Array, v: Array, f: Array, sigma: float) -> tuple[float, float]:
    """Stage position of the surface and the tare (N), from the force onset of the first insertion.

    Raises TooShort when the force never rises clearly.
    """
    moving = np.nonzero(np.abs(v) > V_REST_MM_S)[0]
    if len(moving) == 0:
        raise TooShort("the depth never changes")
    pre = f[: max(moving[0], 5)]
    base = float(np.median(pre))
    i_max = int(np.argmax(x))
    w = 5
    fs = smooth(f, w)
    thr = 5.0 * sigma / np.sqrt(w) + 1e-3
    above = (fs - base > thr) & (v > V_REST_MM_S)
    above[i_max + 1:] = False
    run = np.convolve(above.astype(float), np.ones(w), mode="full")[w - 1:]
    cand = np.nonzero(run >= w)[0]
    if len(cand) == 0:
        raise TooShort("no force onset found (the needle never meets the tissue)")
    k_on = int(cand[0])
    x_on = float(x[k_on])
    sel = (v > V_REST_MM_S) & (x > x_on - 5.0) & (x < x_on + 2.0)
    sel[i_max + 1:] = False
    xs, fsel = x[sel], f[sel]
    best, s_best = np.inf, x_on
    for s in np.arange(x_on - 5.0, x_on + 0.01, 0.02):
        h = np.maximum(xs - s, 0.0)
        m = np.column_stack([np.ones_like(h), h, h * h])
        coef, *_ = np.linalg.lstsq(m, fsel, rcond=None)
        sse = float(np.sum((fsel - m @ coef) ** 2))
        if sse < best:
            best, s_best = sse, float(s)
    before = (x < s_best - 0.3) & (np.arange(len(x)) <= i_max)
    tare = float(np.median(f[before])) if np.count_nonzero(before) >= 3 else base
    return s_best, tare


def find_puncture(l: Array, s: Array, f: Array, sigma: float) -> float | None:
    """Tissue depth (mm) of the first clear force drop while first inserting, or None."""
    first_back = np.nonzero(s < 0)[0]
    end = int(first_back[0]) if len(first_back) else len(l)
    ins = np.nonzero((s[:end] > 0) & (l[:end] > 0))[0]
    if len(ins) < 10:
        return None
    fs = smooth(f[ins], 7)
    run = np.maximum.accumulate(fs)
    drop_thr = max(4.0 * sigma / np.sqrt(7.0), 0.05 * float(np.max(np.abs(fs))))
    dropped = np.nonzero(run - fs > drop_thr)[0]
    if len(dropped) == 0:
        return None
    k = int(np.argmax(fs[: dropped[0] + 1]))
    return float(l[ins[k]])


def label_phases(l: Array, s: Array, puncture_mm: float | None) -> Array:
    """Phase index per sample (see PHASES) from tissue depth and direction."""
    n = len(l)
    inside = l > 0
    idx = np.arange(n)
    first_in = int(np.argmax(inside)) if inside.any() else n
    last_in = int(n - 1 - np.argmax(inside[::-1])) if inside.any() else -1
    ph = np.full(n, PHASES.index("out_of_tissue"))
    ph[idx > last_in] = PHASES.index("after_exit")
    back_seen = np.maximum.accumulate(s < 0)
    ins = inside & (s > 0)
    loading = ins & ~back_seen
    if puncture_mm is not None:
        loading &= l <= puncture_mm
        # only before the needle first reaches the puncture depth
        loading &= np.maximum.accumulate(l) <= puncture_mm
    else:
        loading[:] = False
    ph[ins] = PHASES.index("insertion")
    ph[loading] = PHASES.index("loading")
    ph[inside & (s == 0)] = PHASES.index("dwell")
    travel = travel_since_reversal(l, s)
    retr = inside & (s < 0)
    ph[retr] = PHASES.index("retraction")
    ph[retr & (travel < REVERSAL_MM)] = PHASES.index("reversal")
    ph[(idx < first_in) & ~inside] = PHASES.index("out_of_tissue")
    return ph


def detect_signs(tr: Trial) -> tuple[float, float]:
    """Sign conventions of a record: (force sign, depth sign) that make insertion positive.

    Depth: the stage's largest excursion from its start is the insertion.  Force: while the
    needle first advances through the deeper half of its stroke the tissue pushes back, so the
    force there (against the median before the stage moves) is positive.
    """
    d = tr.depth_mm - tr.depth_mm[0]
    ds = -1.0 if abs(float(np.min(d))) > abs(float(np.max(d))) else 1.0
    x = ds * tr.depth_mm
    k_max = int(np.argmax(x))
    lo, hi = float(x[0]), float(x[k_max])
    deep = np.zeros(len(x), dtype=bool)
    deep[:k_max + 1] = x[:k_max + 1] > lo + 0.5 * (hi - lo)
    n0 = max(5, int(np.argmax(np.abs(d) > 0.05 * max(abs(hi - lo), 1e-9))))
    base = float(np.median(tr.force_n[:n0]))
    if not deep.any():
        return 1.0, ds
    fs = -1.0 if float(np.median(tr.force_n[deep])) - base < 0 else 1.0
    return fs, ds


def prepare(tr: Trial, force_sign: float = 0.0, depth_sign: float = 0.0) -> Prepared:
    """Tare, surface, phases of one trial; raises TooShort when it cannot be split.

    ``force_sign`` / ``depth_sign``: +1 or -1 to state the record's convention, 0 to detect it
    (:func:`detect_signs`); what was applied is kept in the result and its note."""
    if len(tr.t_s) < MIN_SAMPLES:
        raise TooShort(f"only {len(tr.t_s)} samples (need >= {MIN_SAMPLES})")
    fs_auto, ds_auto = detect_signs(tr)
    fs = force_sign if force_sign else fs_auto
    ds = depth_sign if depth_sign else ds_auto
    note = ""
    if fs < 0 or ds < 0:
        what = [n for n, sg in (("force", fs), ("depth", ds)) if sg < 0]
        how = "as stated" if (force_sign or depth_sign) else "detected"
        note = (f"{tr.name}: {' and '.join(what)} recorded negative on insertion ({how}); "
                "multiplied by -1")
    vel = tr.velocity_mm_s * ds if tr.velocity_mm_s is not None else None
    tr = Trial(tr.name, tr.t_s, tr.depth_mm * ds, tr.force_n * fs, vel)
    v = velocity(tr)
    sigma = noise_level(tr.force_n)
    surface, tare = find_surface(tr.t_s, tr.depth_mm, v, tr.force_n, sigma)
    f = tr.force_n - tare
    l = np.maximum(tr.depth_mm - surface, 0.0)
    s = direction(v) * (l > 0)
    # a record may end in a hold (relaxation tests, hold-only protocols): it has no reversal,
    # retraction or exit, and the effects that live there have no evidence in it
    if not (s > 0).any():
        raise TooShort("the needle never advances inside the tissue")
    punct = find_puncture(l, s, f, sigma)
    ph = label_phases(l, s, punct)
    if np.count_nonzero(l > 0) < 20:
        raise TooShort("fewer than 20 samples inside the tissue")
    fwd = v[(s > 0)]
    speed = float(np.median(np.abs(fwd))) if len(fwd) else 0.0
    return Prepared(tr.name, tr.t_s, tr.depth_mm, v, f, surface, tare, sigma, punct, ph, speed,
                    find_dwells(tr.t_s, l, v), fs, ds, note)
