"""Forward simulation of the force model: the ground truth of every synthetic scenario.

The state equation is integrated with the same RK3 step the filters use (float64, 10 sub-steps by
default, depth linear within a sample); the output uses the exact direction sign(v) unless told
otherwise (model-notes §2, §4).  z is reset to 0 whenever the depth is back at 0.
"""
from __future__ import annotations

import numpy as np

from .fmath import F64, Array, Real
from .model import ScaledParams, clamp_depth, depth_terms, exact_sign, output, smooth_sign
from .params import PARAM_NAMES, ParamSet
from .rk3 import rk3_step

SIM_SUBSTEPS = 10


def simulate_force(params: list[ParamSet] | ParamSet, t_s: Array, depth_mm: Array,
                   velocity_mm_s: Array, substeps: int = SIM_SUBSTEPS, sign: str = "exact",
                   eps_mm_s: float = 0.5, R: Real = F64) -> tuple[Array, Array]:
    """Noise-free force (batch, samples) and z for each parameter set along one trajectory."""
    plist = [params] if isinstance(params, ParamSet) else list(params)
    B = len(plist)
    cols = [R.arr([getattr(p, n) for p in plist]) for n in PARAM_NAMES]
    th = _theta_direct(R, cols)
    n = len(t_s)
    force = np.zeros((B, n), dtype=R.dtype)
    zs = np.zeros((B, n), dtype=R.dtype)
    z = R.full(B, 0.0)
    eps = R.full(B, eps_mm_s)
    for k in range(n):
        l = clamp_depth(R, R.full(B, depth_mm[k]))
        if k > 0:
            dt = R.full(B, t_s[k] - t_s[k - 1])
            l_prev = clamp_depth(R, R.full(B, depth_mm[k - 1]))
            z = rk3_step(R, th, z, l_prev, l, dt, substeps).z
        z = np.where(l > 0, z, R.c(0.0))
        vk = R.full(B, velocity_mm_s[k])
        s = exact_sign(R, vk) if sign == "exact" else smooth_sign(R, vk, eps)
        force[:, k] = output(th, depth_terms(R, th, l), z, s).h
        zs[:, k] = z
    return force, zs


def _theta_direct(R: Real, cols: list[Array]):  # type: ignore[no-untyped-def]
    """Theta from physical values (u = 0 with the values themselves as nominal)."""
    nominal_batch = ScaledParams.__new__(ScaledParams)
    nominal_batch.R = R
    nominal_batch.nominal = cols
    f2 = cols[PARAM_NAMES.index("f2")]
    f1 = cols[PARAM_NAMES.index("f1")]
    from .model import Theta
    zero = R.c(0.0)
    kappa = np.where(f2 < zero, R.c(1.0), zero)
    mkf2 = -(kappa * f2)
    return Theta(cols[0], cols[1], cols[2], f1, f2, cols[5], cols[6], f1 - mkf2, mkf2)


def add_noise(force: Array, noise_n: float, seed: int) -> Array:
    rng = np.random.default_rng(seed)
    return force + rng.normal(0.0, noise_n, size=force.shape)
