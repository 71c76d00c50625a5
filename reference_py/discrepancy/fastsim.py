"""Fast float64 forward simulation of the state equation, for fitting.

The state equation dz/dt = l (beta - b(l) z), b = sigma0 / g(l), is linear in z.  One Kutta RK3
sub-step (the same stages as :func:`reference_py.rk3.rk3_step`, depth linear within a sample) is
therefore an affine map z -> a z + c whose coefficients depend on depth and parameters only
(:mod:`reference_py.sim.kernel`, shared with ``simulate_force``).  All sub-step maps are computed
at once with numpy and composed per sample; only the scalar recurrence
z_{k+1} = A_k z_k + C_k runs sample by sample (a plain Python loop over floats, ~0.2 us/sample).
Out of tissue (l <= 0) z is reset to 0, as in :func:`reference_py.sim.simulate.simulate_force`.

Fitting uses the normalised state zh = z / beta (z scales exactly with beta), which depends only
on b(l) = 1 / (p + q exp(-alpha l)) with p = f1 / sigma0 and q = f2 / sigma0.
"""
from __future__ import annotations

import numpy as np

from ..fmath import Array
from ..params import ParamSet
from ..sim.kernel import exp_affine, rk3_affine, substep_fractions

SUBSTEPS = 10


def _b_of_l(l: Array, p: float, q: float, alpha: float) -> Array:
    return 1.0 / (p + q * np.exp(-alpha * l))


def state_trajectory(t_s: Array, l_mm: Array, p: float, q: float, alpha: float,
                     beta: float = 1.0, substeps: int = SUBSTEPS,
                     stiff_from: float | None = None) -> Array:
    """z at every sample for depth ``l_mm`` (already >= 0), with b(l) = 1/(p + q e^{-alpha l}).

    ``stiff_from``: a sample whose sub-step would see lambda h = l b h above this takes
    exponential sub-steps instead (kernel.exp_affine, rates frozen at the sub-step's middle:
    second order, stable at any lambda h), where RK3 would need ever more sub-steps to stay
    stable (a fit that wanders into stiff parameters asked for 100-150 per sample).

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
    # every sub-step's three stage depths at once: shape (3, substeps, n - 1)
    fr = np.stack(substep_fractions(substeps))[:, :, None]
    ls = np.maximum(la + dl * fr, 0.0)
    d = ls * _b_of_l(ls, p, q, alpha)
    sa, sc = rk3_affine(h, ((ls[0] * beta, d[0]), (ls[1] * beta, d[1]), (ls[2] * beta, d[2])))
    if stiff_from is not None:
        stiff = np.max(d, axis=(0, 1)) * h > stiff_from    # per sample, over every stage
        if stiff.any():
            ea, ec = exp_affine(h, ls[1] * beta, d[1])
            sa, sc = np.where(stiff, ea, sa), np.where(stiff, ec, sc)
    # the sample's map is the sub-steps' maps composed, first sub-step innermost
    big_a, big_c = sa[0], sc[0]
    for j in range(1, substeps):
        big_a, big_c = sa[j] * big_a, sa[j] * big_c + sc[j]
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
