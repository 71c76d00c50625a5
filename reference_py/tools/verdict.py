"""The closing verdict of ``nte-ref estimate`` (nte-run prints the same line): does the model
follow this file, judged by its innovation against the sensor's own noise?

The line, the last one on stdout (the format is the contract; nte-run follows it to the
character)::

    verdict: innovation RMS {R} mN = {K}x the noise ({S} mN, {SRC}); gated {G} % of updates; {C}

* in tissue: the samples whose status has none of INIT, REJECTED, OUT_OF_TISSUE and
  PREDICT_ONLY (bank.py STATUS_*); R is the RMS of their innovation in mN (``%.3g``), G the
  share of them with GATED, in % (``%.1f``);
* the noise S (mN, ``%.3g``): ``--noise N`` (SRC ``given by --noise``), else the sample standard
  deviation (n - 1) of the force over the leading samples while |depth - depth[0]| <= 0.01 mm,
  when there are at least 20 of them and they are not all equal (SRC ``measured in the first
  {n} samples at rest``);
* K = R / S (``%.1f``); C: K <= 5: ``the model follows this file``, else ``the model does not fit
  this file ({K}x the noise): see nte-discrepancy``.

Other forms: the noise unknown, ``verdict: innovation RMS {R} mN; gated {G} % of updates; noise
unknown (no rest before the stage moves): give --noise N``; predict-only, ``verdict:
predict-only, the force was not read: no verdict``; no sample in tissue, ``verdict: no sample in
tissue: no verdict``.  The robust estimator appends ``; robust refinement: confidence {c},
converged`` (or ``not converged``): the last sample's confidence (``%.3g``) and its CONVERGED
bit (the last refinement's).

A warning (stderr) when the first 2 s in tissue (in-tissue samples with t <= the first one's
t + 2 s) have an innovation RMS above 20 S: the filters started far from this file.

Arithmetic (for the C twin): every value taken as a double, sums in sample order; RMS =
sqrt(sum(x^2) / n); the noise's mean = sum(f) / n, then sqrt(sum((f - mean)^2) / (n - 1)); R
and S are the values in N times 1000, K and the warning's factor the ratios of the values in N;
the comparisons (K <= 5, factor > 20) are made on those doubles, not on the printed text.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..bank import (STATUS_GATED, STATUS_INIT, STATUS_OUT_OF_TISSUE, STATUS_PREDICT_ONLY,
                    STATUS_REJECTED)
from ..fmath import Array
from ..robust import STATUS_CONVERGED

#: status bits of a sample that says nothing about the fit in tissue
NOT_IN_TISSUE = STATUS_INIT | STATUS_REJECTED | STATUS_OUT_OF_TISSUE | STATUS_PREDICT_ONLY
#: the stage is at rest while the depth stays within this of its first value, mm
REST_DEPTH_MM = 0.01
#: fewer leading samples at rest than this measure no noise
MIN_REST_SAMPLES = 20
#: an innovation RMS up to this many times the noise: the model follows the file
FOLLOWS_FACTOR = 5.0
#: the start is judged over this long in tissue, s ...
START_WINDOW_S = 2.0
#: ... and is off when its innovation RMS is above this many times the noise
START_FACTOR = 20.0


@dataclass(frozen=True)
class Noise:
    """The sensor noise the innovation is judged against (N) and where it comes from."""
    sd_n: float
    source: str


def rms(x: Array) -> float:
    """sqrt(sum(x^2) / n), in double, summed in sample order (the C twin's arithmetic)."""
    total = 0.0
    for v in x:
        total += float(v) * float(v)
    return math.sqrt(total / len(x))


def rest_noise(depth_mm: Array, force_n: Array) -> Noise | None:
    """The force's sample standard deviation while the stage is at rest before it moves, or
    None when fewer than MIN_REST_SAMPLES samples lead the record at rest."""
    d0 = float(depth_mm[0])
    n = 0
    while n < len(depth_mm) and abs(float(depth_mm[n]) - d0) <= REST_DEPTH_MM:
        n += 1
    if n < MIN_REST_SAMPLES:
        return None
    total = 0.0
    for v in force_n[:n]:
        total += float(v)
    mean = total / n
    dev = 0.0
    for v in force_n[:n]:
        dev += (float(v) - mean) * (float(v) - mean)
    if not dev > 0.0:
        return None             # a noise-free rest (a simulated record) measures no noise
    return Noise(math.sqrt(dev / (n - 1)), f"measured in the first {n} samples at rest")


def in_tissue(status: Array) -> Array:
    """The samples that judge the fit (none of the NOT_IN_TISSUE bits)."""
    return (np.asarray(status, dtype=np.uint32) & np.uint32(NOT_IN_TISSUE)) == 0


@dataclass(frozen=True)
class Verdict:
    line: str                   # the closing line (stdout)
    warning: str | None         # the start's warning (stderr), if any


def verdict(t_s: Array, depth_mm: Array, force_n: Array, innovation_n: Array, status: Array,
            *, predict_only: bool = False, noise_n: float | None = None,
            confidence: float | None = None) -> Verdict:
    """The verdict on one estimate run (the module's docstring).  ``force_n`` is the force as
    read (converted to N), ``noise_n`` the noise given by --noise (None: measure it),
    ``confidence`` the robust estimator's last confidence (None: the bank)."""
    st = np.asarray(status, dtype=np.uint32)
    robust = ""
    if confidence is not None:
        done = "converged" if int(st[-1]) & STATUS_CONVERGED else "not converged"
        robust = f"; robust refinement: confidence {confidence:.3g}, {done}"
    if predict_only:
        return Verdict("verdict: predict-only, the force was not read: no verdict" + robust, None)
    inside = in_tissue(st)
    m = int(np.count_nonzero(inside))
    if m == 0:
        return Verdict("verdict: no sample in tissue: no verdict" + robust, None)
    inn = np.asarray(innovation_n)[inside]
    r_n = rms(inn)
    gated = 100.0 * int(np.count_nonzero(st[inside] & np.uint32(STATUS_GATED))) / m
    head = f"verdict: innovation RMS {1000.0 * r_n:.3g} mN"
    tail = f"; gated {gated:.1f} % of updates; "
    noise = (Noise(noise_n, "given by --noise") if noise_n is not None
             else rest_noise(depth_mm, force_n))
    if noise is None:
        return Verdict(head + tail + "noise unknown (no rest before the stage moves): give "
                       "--noise N" + robust, None)
    k = r_n / noise.sd_n
    conclusion = ("the model follows this file" if k <= FOLLOWS_FACTOR else
                  f"the model does not fit this file ({k:.1f}x the noise): see nte-discrepancy")
    line = (f"{head} = {k:.1f}x the noise ({1000.0 * noise.sd_n:.3g} mN, {noise.source})"
            f"{tail}{conclusion}{robust}")
    return Verdict(line, start_warning(np.asarray(t_s)[inside], inn, noise.sd_n))


def start_warning(t_s: Array, innovation_n: Array, noise_sd_n: float) -> str | None:
    """The warning when the first START_WINDOW_S of the in-tissue samples (``t_s``,
    ``innovation_n``: those samples only) are off by more than START_FACTOR times the noise."""
    first = np.asarray(t_s) <= float(t_s[0]) + START_WINDOW_S
    k2 = rms(np.asarray(innovation_n)[first]) / noise_sd_n
    if not k2 > START_FACTOR:
        return None
    return (f"warning: the first {START_WINDOW_S:g} s in tissue are {k2:.0f}x the noise off the "
            f"start: set it with --preset, --start or --config")


__all__ = ["Noise", "Verdict", "rest_noise", "rms", "start_warning", "verdict"]
