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
from ..sim.kernel import rk3_affine, substep_fractions

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
    big_a = np.ones(n - 1)
    big_c = np.zeros(n - 1)
    # Python floats, as the arrays' own precision is the one to keep
    for f0, fm, f1 in zip(*(f.tolist() for f in substep_fractions(substeps))):
        l0 = np.maximum(la + dl * f0, 0.0)
        lm = np.maximum(la + dl * fm, 0.0)
        l1 = np.maximum(la + dl * f1, 0.0)
        d0, dm, d1 = l0 * _b_of_l(l0, p, q, alpha), lm * _b_of_l(lm, p, q, alpha), \
            l1 * _b_of_l(l1, p, q, alpha)
        sa, sc = rk3_affine(h, ((l0 * beta, d0), (lm * beta, dm), (l1 * beta, d1)))
        # the sample's map is the sub-steps' maps composed, first sub-step innermost
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
