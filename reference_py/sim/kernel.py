"""One Kutta RK3 sub-step of the state equation, as the affine map z -> a z + c.

The state equation dz/dt = l (beta - b(l) z) is linear in z, and within a sample the depth is
linear in time, so every stage rate is p - q z with p = l beta and q = l b(l) taken at the
sub-step's start, middle and end.  The sub-step is then an affine map of its start value whose
coefficients depend on depth and parameters only: both forward simulators compute them for all
sub-steps at once with numpy and keep only a cheap recurrence per sample.  They differ in what
they vectorise over and in how they run the recurrence (:func:`reference_py.sim.simulate.
simulate_force`: batches of parameter sets in any working precision, one map per sub-step;
:func:`reference_py.discrepancy.fastsim.state_trajectory`: float64, the sub-steps composed into
one map per sample), so the algebra of the step lives here, once.

The stages are those of :func:`reference_py.rk3.rk3_step`, the filters' own step (with
sensitivities); that one stays apart: it is the twin of the C library.  Where a fit wanders
into stiff parameters, the fits' simulator steps a sample exactly instead (:func:`exp_affine`,
the same kind of affine map), so both sub-steps live here.
"""
from __future__ import annotations

import numpy as np

from ..fmath import F64, Array, Real


def substep_fractions(substeps: int, R: Real = F64) -> tuple[Array, Array, Array]:
    """Where the stages of each of ``substeps`` equal sub-steps fall in a sample, as fractions
    of the sample (start, middle, end of sub-step j), each of shape (substeps,)."""
    nsub = R.c(float(substeps))
    j = np.arange(substeps, dtype=np.float64)
    return (R.arr(j) / nsub, R.arr(2.0 * j + 1.0) / (nsub * R.c(2.0)), R.arr(j + 1.0) / nsub)


def rk3_affine(h: Array, rates: tuple[tuple[Array, Array], ...], R: Real | None = None
               ) -> tuple[Array, Array]:
    """(a, c) of one RK3 sub-step of length h, z -> a z + c, from the rates p - q z at its start,
    middle and end: ``rates`` = ((p1, q1), (p2, q2), (p3, q3)), broadcast against h.

    With R the constants are R's, so a float32 simulation rounds every operation in float32;
    without, they are Python floats, which take the precision of the arrays they meet."""
    (p1, q1), (p2, q2), (p3, q3) = rates
    half, six, two, four = (0.5, 6.0, 2.0, 4.0) if R is None else \
        (R.c(0.5), R.c(6.0), R.c(2.0), R.c(4.0))
    h2, h6, twoh = h * half, h / six, h * two
    # each stage as an affine function (coefficient on z, constant) of the sub-step's start z:
    # k1 = p1 - q1 z;  z2 = z + h2 k1;  k2 = p2 - q2 z2;  z3 = z - h k1 + 2h k2;  k3 = p3 - q3 z3
    k1a, k1c = -q1, p1
    z2a, z2c = 1 + h2 * k1a, h2 * k1c
    k2a, k2c = -q2 * z2a, p2 - q2 * z2c
    z3a, z3c = (1 - h * k1a) + twoh * k2a, (-h * k1c) + twoh * k2c
    k3a, k3c = -q3 * z3a, p3 - q3 * z3c
    a = 1 + h6 * ((k1a + four * k2a) + k3a)
    c = h6 * ((k1c + four * k2c) + k3c)
    return a, c


def exp_affine(h: Array, p: Array, q: Array) -> tuple[Array, Array]:
    """(a, c) of the exact step of dz/dt = p - q z over h with p and q frozen (q >= 0):
    z -> e^{-qh} z + (1 - e^{-qh}) p / q, written as a = e^{-qh}, c = p h phi(qh), phi(x) =
    (1 - e^{-x}) / x (-> 1 as x -> 0, so no division by a vanishing q).  Stable for every qh and,
    when qh is large, z lands on the quasi-static value p / q, where an explicit step needs
    qh <~ 2.5: the fits' integrator for stiff samples (fastsim.state_trajectory)."""
    x = q * h
    small = x < 1e-8
    phi = np.where(small, 1.0 - 0.5 * x, -np.expm1(-x) / np.where(small, 1.0, x))
    return np.exp(-x), p * h * phi
