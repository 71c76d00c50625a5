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

from dataclasses import dataclass

import numpy as np

from ..fmath import Array
from ..params import ParamSet
from ..sim.kernel import exp_affine, rk3_affine, substep_fractions

SUBSTEPS = 10


def _b_of_l(l: Array, p: float, q: float, alpha: float, decay: Array | None = None) -> Array:
    """b(l); ``decay``: exp(-alpha l) when the caller has it already."""
    return 1.0 / (p + q * (np.exp(-alpha * l) if decay is None else decay))


@dataclass(frozen=True)
class Stages:
    """What a simulation along one depth record needs that no parameter changes: the sub-step
    length of each sample interval, every sub-step's stage depths (:func:`stage_depths`) and
    whether each sample's end is in the tissue.  A fit that moves p, g0 or alpha, not where
    the tissue is, simulates on the same Stages again (effects.trial_inputs keeps them)."""

    n: int               # samples
    substeps: int
    h: Array             # (n - 1,)
    ls: Array            # (2 substeps + 1, n - 1)
    inside: Array        # (n - 1,)


def stage_depths(t_s: Array, l_mm: Array, substeps: int = SUBSTEPS) -> Stages:
    """The Stages of depth ``l_mm`` (already >= 0) sampled at ``t_s``."""
    n = len(t_s)
    if n < 2:
        return Stages(n, substeps, np.zeros(0), np.zeros((2 * substeps + 1, 0)), np.zeros(0, bool))
    dt = np.diff(t_s)
    la, lb = l_mm[:-1], l_mm[1:]
    dl = lb - la
    h = dt / substeps
    # every sub-step's stage depths at once: its start, its middle, its end -- which is the next
    # sub-step's start (the same fraction, the same float), so computed once:
    # rows 0..substeps the sub-step boundaries, then the middles; shape (2 substeps + 1, n - 1)
    ls = np.maximum(la + dl * _stage_fractions(substeps), 0.0)
    return Stages(n, substeps, h, ls, l_mm[1:] > 0.0)


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
    return state_on_stages(stage_depths(t_s, l_mm, substeps), p, q, alpha, beta, stiff_from)


def state_on_stages(st: Stages, p: float, q: float, alpha: float, beta: float = 1.0,
                    stiff_from: float | None = None, decay: Array | None = None) -> Array:
    """:func:`state_trajectory` on the record's Stages; ``decay``: exp(-alpha st.ls) when the
    caller has it (a fit moving p or g0 keeps alpha)."""
    z = np.zeros(st.n)
    if st.n < 2:
        return z
    substeps, h, ls = st.substeps, st.h, st.ls
    d = ls * _b_of_l(ls, p, q, alpha, decay)
    start, mid, end = slice(0, substeps), slice(substeps + 1, None), slice(1, substeps + 1)
    sa, sc = rk3_affine(h, ((ls[start] * beta, d[start]), (ls[mid] * beta, d[mid]),
                            (ls[end] * beta, d[end])))
    if stiff_from is not None:
        stiff = np.max(d, axis=0) * h > stiff_from    # per sample, over every stage
        if stiff.any():
            ea, ec = exp_affine(h, ls[mid] * beta, d[mid])
            sa, sc = np.where(stiff, ea, sa), np.where(stiff, ec, sc)
    # the sample's map is the sub-steps' maps composed, first sub-step innermost
    big_a, big_c = sa[0], sc[0]
    for j in range(1, substeps):
        big_a, big_c = sa[j] * big_a, sa[j] * big_c + sc[j]
    big_a = np.where(st.inside, big_a, 0.0).tolist()
    big_c = np.where(st.inside, big_c, 0.0).tolist()
    out = [0.0]
    append = out.append
    zk = 0.0
    for a_k, c_k in zip(big_a, big_c):     # zip, not indexing: the loop is the hot spot
        zk = a_k * zk + c_k
        append(zk)
    return np.asarray(out)


_FRACTIONS: dict[int, Array] = {}


def _stage_fractions(substeps: int) -> Array:
    """kernel.substep_fractions as a column (2 substeps + 1, 1): the sub-steps' starts and the
    last one's end (the other ends are the next starts, the very same floats), then their
    middles; made once per sub-step count: a fit simulates thousands of times with one count."""
    fr = _FRACTIONS.get(substeps)
    if fr is None:
        first, middle, last = substep_fractions(substeps)
        assert np.array_equal(first[1:], last[:-1])
        fr = np.concatenate([first, last[-1:], middle])[:, None]
        fr.flags.writeable = False
        _FRACTIONS[substeps] = fr
    return fr


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
