"""Forward simulation of the force model: the ground truth of every synthetic scenario.

The state equation is integrated with the same RK3 step the filters use (float64, 10 sub-steps by
default, depth linear within a sample); the output uses the exact direction sign(v) unless told
otherwise (MODEL.md §2, §4).  z is reset to 0 whenever the depth is back at 0.  The sub-step's
algebra is :mod:`reference_py.sim.kernel`'s, shared with the workflow's fast simulator.
"""
from __future__ import annotations

import numpy as np

from ..fmath import F64, Array, Real
from ..model import Theta, clamp_depth, depth_terms, exact_sign, output, smooth_sign
from ..params import PARAM_NAMES, ParamSet
from .kernel import rk3_affine, substep_fractions

SIM_SUBSTEPS = 10


def simulate_force(params: list[ParamSet] | ParamSet, t_s: Array, depth_mm: Array,
                   velocity_mm_s: Array, substeps: int = SIM_SUBSTEPS, sign: str = "exact",
                   eps_mm_s: float = 0.5, R: Real = F64) -> tuple[Array, Array]:
    """Noise-free force (batch, samples) and z for each parameter set along one trajectory.

    The state equation is linear in z, so one RK3 sub-step is an affine map z -> a z + c whose
    coefficients depend only on depth and parameters.  They are computed for every sub-step at
    once (vectorised), and only the cheap recurrence runs sample by sample.  The stages are the
    same as :func:`reference_py.rk3.rk3_step`'s (test_simulate checks the two agree).
    """
    plist = [params] if isinstance(params, ParamSet) else list(params)
    B = len(plist)
    cols = [R.arr([getattr(p, n) for p in plist])[:, None] for n in PARAM_NAMES]
    th = _theta_direct(R, cols)
    n = len(t_s)
    l_all = clamp_depth(R, R.arr(depth_mm))
    z = R.full(B, 0.0)
    zs = np.zeros((B, n), dtype=R.dtype)
    if n > 1:
        a_sub, c_sub = _affine_substeps(R, th, l_all, R.arr(np.diff(t_s)), substeps)
        for k in range(1, n):
            for j in range(substeps):
                z = a_sub[:, k - 1, j] * z + c_sub[:, k - 1, j]
            z = np.where(l_all[k] > 0, z, R.c(0.0))
            zs[:, k] = z
    v = R.arr(velocity_mm_s)[None, :]
    s = exact_sign(R, v) if sign == "exact" else smooth_sign(R, v, R.c(eps_mm_s))
    force = output(th, depth_terms(R, th, l_all[None, :]), zs, s).h
    return force, zs


def _affine_substeps(R: Real, th, l: Array, dt: Array, substeps: int  # type: ignore[no-untyped-def]
                     ) -> tuple[Array, Array]:
    """Coefficients (batch, samples-1, substeps) of z -> a z + c for every RK3 sub-step."""
    h = (dt / R.c(float(substeps)))[None, :, None]
    tau0, taum, tau1 = (f[None, None, :] for f in substep_fractions(substeps, R))
    l_a = l[:-1][None, :, None]
    dl = (l[1:] - l[:-1])[None, :, None]
    thx = _theta_direct(R, [getattr(th, nm)[:, :, None] for nm in PARAM_NAMES])
    # stage rates are p - q z with p = l beta, q = l b
    pq = []
    for tau in (tau0, taum, tau1):
        d = depth_terms(R, thx, clamp_depth(R, l_a + dl * tau))
        pq.append((d.l * thx.beta, d.l * d.b))
    a, c = rk3_affine(h, tuple(pq), R)
    shape = (a.shape[0], len(dt), substeps)
    return np.broadcast_to(a, shape), np.broadcast_to(c, shape)


def _theta_direct(R: Real, cols: list[Array]):  # type: ignore[no-untyped-def]
    """Theta from physical values (u = 0 with the values themselves as nominal)."""
    f2 = cols[PARAM_NAMES.index("f2")]
    f1 = cols[PARAM_NAMES.index("f1")]
    zero = R.c(0.0)
    kappa = np.where(f2 < zero, R.c(1.0), zero)
    mkf2 = -(kappa * f2)
    return Theta(cols[0], cols[1], cols[2], f1, f2, cols[5], cols[6], f1 - mkf2, mkf2)


def add_noise(force: Array, noise_n: float, seed: int) -> Array:
    rng = np.random.default_rng(seed)
    return force + rng.normal(0.0, noise_n, size=force.shape)
