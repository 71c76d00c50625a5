"""Fast float64 forward simulation of the state equation, for fitting.

The state equation dz/dt = l (beta - b(l) z), b = sigma0 / g(l), is linear in z.  One Kutta RK3
sub-step (the same stages as :func:`reference_py.rk3.rk3_step`, depth linear within a sample) is
therefore an affine map z -> a z + c whose coefficients depend on depth and parameters only.  All
sub-step maps are computed at once with numpy and composed per sample; only the scalar recurrence
z_{k+1} = A_k z_k + C_k runs sample by sample (a plain Python loop over floats, ~0.2 us/sample).
Out of tissue (l <= 0) z is reset to 0, as in :func:`reference_py.tools.simulate.simulate_force`.

Fitting uses the normalised state zh = z / beta (z scales exactly with beta), which depends only
on b(l) = 1 / (p + q exp(-alpha l)) with p = f1 / sigma0 and q = f2 / sigma0.
"""
from __future__ import annotations

import numpy as np

from ..fmath import Array
from ..params import ParamSet

SUBSTEPS = 10


def _b_of_l(l: Array, p: float, q: float, alpha: float) -> Array:
    return 1.0 / (p + q * np.exp(-alpha * l))


def state_trajectory(t_s: Array, l_mm: Array, p: float, q: float, alpha: float,
                     beta: float = 1.0, substeps: int = SUBSTEPS) -> Array:
    """z at every sample for depth ``l_mm`` (already >= 0), with b(l) = 1/(p + q e^{-alpha l}).

    Cost: O(n * substeps) vectorised work plus an O(n) scalar loop.
    """
    n = len(t_s)
    z = np.zeros(n)
    if n < 2:
        return z
    dt = np.diff(t_s)
    la, lb = l_mm[:-1], l_mm[1:]
    dl = lb - la
    h = dt / substeps
    h2, h6, twoh = h * 0.5, h / 6.0, h * 2.0
    big_a = np.ones(n - 1)
    big_c = np.zeros(n - 1)
    nn = float(substeps)
    for j in range(substeps):
        l0 = np.maximum(la + dl * (j / nn), 0.0)
        lm = np.maximum(la + dl * ((2 * j + 1) / (nn * 2.0)), 0.0)
        l1 = np.maximum(la + dl * ((j + 1) / nn), 0.0)
        d0, dm, d1 = l0 * _b_of_l(l0, p, q, alpha), lm * _b_of_l(lm, p, q, alpha), \
            l1 * _b_of_l(l1, p, q, alpha)
        c0, cm, c1 = l0 * beta, lm * beta, l1 * beta
        # stages as affine functions (coef on z, constant) of the sub-step's start value z
        k1a, k1c = -d0, c0
        z2a, z2c = 1.0 + h2 * k1a, h2 * k1c
        k2a, k2c = -dm * z2a, cm - dm * z2c
        z3a, z3c = (1.0 - h * k1a) + twoh * k2a, (-h * k1c) + twoh * k2c
        k3a, k3c = -d1 * z3a, c1 - d1 * z3c
        sa = 1.0 + h6 * ((k1a + 4.0 * k2a) + k3a)
        sc = h6 * ((k1c + 4.0 * k2c) + k3c)
        big_a, big_c = sa * big_a, sa * big_c + sc
    inside = (l_mm[1:] > 0.0)
    big_a = np.where(inside, big_a, 0.0).tolist()
    big_c = np.where(inside, big_c, 0.0).tolist()
    out = [0.0] * n
    zk = 0.0
    for k in range(n - 1):
        zk = big_a[k] * zk + big_c[k]
        out[k + 1] = zk
    return np.asarray(out)


def exact_sign(v: Array) -> Array:
    return np.sign(v)


def simulate_force_fast(params: ParamSet, t_s: Array, depth_mm: Array, velocity_mm_s: Array,
                        substeps: int = SUBSTEPS) -> tuple[Array, Array]:
    """Force (N) and z along one trajectory: the fast twin of ``simulate_force`` (sign = exact)."""
    l = np.maximum(np.asarray(depth_mm, dtype=float), 0.0)
    t = np.asarray(t_s, dtype=float)
    p, q = params.f1 / params.sigma0, params.f2 / params.sigma0
    z = state_trajectory(t, l, p, q, params.alpha, params.beta, substeps)
    e = np.exp(-params.alpha * l)
    g = params.f1 + params.f2 * e
    b = params.sigma0 / g
    s = exact_sign(np.asarray(velocity_mm_s, dtype=float))
    f = params.sigma0 * z * l + s * l * (params.sigma1 * e * (params.beta - b * z) + params.sigma2)
    return f, z
