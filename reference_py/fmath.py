"""Portable arithmetic shared bit for bit by the reference and the C library.

Every quantity of the estimator lives in one working precision, float64 or float32, held by a
:class:`Real`.  Only the IEEE-754 operations + - * / and sqrt (all correctly rounded, so equal on
every conforming machine), comparisons, and integer<->float conversions are used.  ``exp`` and
``tanh`` are built here from those operations, because libm's versions differ between C libraries
(glibc and newlib disagree by one ulp on about a tenth of the inputs).

All functions work element-wise on numpy arrays, so one call can advance a whole batch of
independent runs; each element sees exactly the scalar operation sequence the C code performs.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[Any]

# exp(x) = 2^k * exp(r), k = nearest integer to x/ln2, r = x - k*ln2 in [-ln2/2, ln2/2].
# ln2 is split in a high part whose low bits are zero (so k*LN2_HI is exact for the k that occur)
# and a low part (Cody & Waite).  exp(r) is a Taylor polynomial evaluated by Horner's rule; its
# degree gives a truncation error below half an ulp on [-ln2/2, ln2/2].
_LN2_HI_F64 = 6.93147180369123816490e-01
_LN2_LO_F64 = 1.90821492927058770002e-10
_LN2_HI_F32 = 6.93359375e-01  # 0x3f318000: 9 significant bits
_LN2_LO_F32 = -2.12194440e-04
_LOG2E = 1.4426950408889634
_EXP_DEGREE_F64 = 13
_EXP_DEGREE_F32 = 7
# |x| is clamped here: 2^k stays a normal number (no subnormal or overflow path is needed).
_EXP_XMAX_F64 = 700.0
_EXP_XMAX_F32 = 80.0
# tanh(x) rounds to exactly 1 beyond these arguments.
_TANH_XMAX_F64 = 19.5
_TANH_XMAX_F32 = 9.5


def _inv_factorials(degree: int) -> list[float]:
    coeffs = [1.0]
    for n in range(1, degree + 1):
        coeffs.append(coeffs[-1] / float(n))
    return coeffs


_CONSTANTS: dict[str, dict[str, Any]] = {}


@dataclass(frozen=True)
class Real:
    """A working precision: its dtype and every constant the numeric path uses, already rounded."""

    dtype: Any
    name: str

    @property
    def is_f32(self) -> bool:
        return self.dtype == np.float32

    def c(self, value: float) -> Any:
        """A constant in this precision (rounded once from its float64 value)."""
        return self.dtype(value)

    def arr(self, values: Any) -> Array:
        return np.asarray(values, dtype=np.float64).astype(self.dtype)

    def full(self, shape: Any, value: float) -> Array:
        return np.full(shape, self.c(value), dtype=self.dtype)

    # --- constants of the portable exp -----------------------------------------------------
    def exp_constants(self) -> dict[str, Any]:
        cached = _CONSTANTS.get(self.name)
        if cached is None:
            cached = _CONSTANTS[self.name] = self._make_exp_constants()
        return cached

    def _make_exp_constants(self) -> dict[str, Any]:
        if self.is_f32:
            hi, lo, deg, xmax = _LN2_HI_F32, _LN2_LO_F32, _EXP_DEGREE_F32, _EXP_XMAX_F32
        else:
            hi, lo, deg, xmax = _LN2_HI_F64, _LN2_LO_F64, _EXP_DEGREE_F64, _EXP_XMAX_F64
        return {
            "ln2_hi": self.c(hi),
            "ln2_lo": self.c(lo),
            "log2e": self.c(_LOG2E),
            "xmax": self.c(xmax),
            "coeffs": [self.c(v) for v in _inv_factorials(deg)],
            "tanh_xmax": self.c(_TANH_XMAX_F32 if self.is_f32 else _TANH_XMAX_F64),
        }

    def exp(self, x: Array) -> Array:
        """exp(x) for |x| <= xmax (clamped outside), from + - * / and int<->float conversions."""
        k = self.exp_constants()
        x = np.asarray(x, dtype=self.dtype)
        x = np.where(x > k["xmax"], k["xmax"], x)
        x = np.where(x < -k["xmax"], -k["xmax"], x)
        t = x * k["log2e"]
        half = self.c(0.5)
        # round half away from zero, then truncate toward zero: exactly C's (int32_t) cast
        t = np.where(t >= self.c(0.0), t + half, t - half)
        n = t.astype(np.int32)
        nf = n.astype(self.dtype)
        r = (x - nf * k["ln2_hi"]) - nf * k["ln2_lo"]
        coeffs = k["coeffs"]
        p = np.full_like(r, coeffs[-1])
        for c in reversed(coeffs[:-1]):
            p = p * r + c
        return p * self.pow2(n)

    def pow2(self, n: Array) -> Array:
        """2**n for integer n in the normal range, assembled from the exponent bits."""
        n = np.asarray(n, dtype=np.int64)
        if self.is_f32:
            return ((n + 127) << 23).astype(np.uint32).view(np.float32)
        return ((n + 1023) << 52).astype(np.uint64).view(np.float64)

    def tanh(self, x: Array) -> Array:
        """tanh(x) = sign(x) (1 - e)/(1 + e) with e = exp(-2|x|); exactly +-1 for large |x|."""
        k = self.exp_constants()
        x = np.asarray(x, dtype=self.dtype)
        a = np.abs(x)
        a_clamped = np.where(a > k["tanh_xmax"], k["tanh_xmax"], a)
        e = self.exp(-(a_clamped + a_clamped))
        one = self.c(1.0)
        t = (one - e) / (one + e)
        t = np.where(a > k["tanh_xmax"], one, t)
        return np.where(x < self.c(0.0), -t, t)


F64 = Real(np.float64, "float64")
F32 = Real(np.float32, "float32")


def real_for(precision: str) -> Real:
    if precision == "float64":
        return F64
    if precision == "float32":
        return F32
    raise ValueError(f"unknown precision {precision!r} (expected float64 or float32)")
