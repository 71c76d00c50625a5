"""Fitting the (extended) model to one or more trials by variable projection.

The force is linear in the output coefficients once the nonlinear parameters (the base model's
p, g0, alpha, each trial's surface correction, and any effect's time constants, depths,
frequencies) are fixed (effects.design).  The linear coefficients are therefore solved exactly by
least squares inside every residual evaluation, and scipy's bounded least_squares searches only the
few nonlinear ones (log-parameters where the sign is known).  One parameter set is shared by all
trials: they are the same needle and tissue; only layers, surfaces and per-trial effect terms
(relaxation amplitude, motion phase) belong to one trial.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from scipy.optimize import lsq_linear

from .effects import NLParam, StateCache, TrialGrid, design, lin_bound, nl_specs
from ..fmath import Array


@dataclass
class Fit:
    """A fitted model: its effects, nonlinear values, linear coefficients and residual."""

    effects: tuple[str, ...]
    nl: dict[str, Array]
    coef: dict[str, float]
    sse: float
    n: int
    k: int          # parameters: nonlinear scalars + linear columns that are not identically 0
    resid: Array
    #: standard errors of the free nonlinear values (name -> value or per-trial array), from the
    #: Jacobian of the variable-projection residual at the solution (white-noise approximation)
    nl_se: dict[str, Array] | None = None


def bounds_of(labels: list[str]) -> tuple[Array, Array]:
    lo, hi = zip(*(lin_bound(lab) for lab in labels))
    return np.array(lo, dtype=float), np.array(hi, dtype=float)


def solve_bounded(m: Array, y: Array, labels: list[str], rcond: float = 1e-12) -> Array:
    """Least squares with the documented coefficient bounds (effects.LIN_BOUNDS).

    The free solution is used when it satisfies them (the common case, fast); otherwise a
    bounded least-squares solve (scipy lsq_linear, BVLS) on the unit-scaled columns.
    """
    c = solve_linear(m, y, rcond)
    lo, hi = bounds_of(labels)
    if np.all((c >= lo - 1e-12) & (c <= hi + 1e-12)):
        return c
    norms = np.sqrt(np.einsum("ij,ij->j", m, m))
    used = norms > 0
    ms = m[:, used] / norms[used]
    res = lsq_linear(ms, y, bounds=(lo[used] * norms[used], hi[used] * norms[used]),
                     method="bvls", lsmr_tol=None)
    out = np.zeros(m.shape[1])
    out[used] = res.x / norms[used]
    return out


def solve_linear(m: Array, y: Array, rcond: float = 1e-12) -> Array:
    """Least-squares coefficients with column scaling (columns may be all zero).

    Solved through the small Gram matrix of the unit-scaled columns: LAPACK's tall least squares
    is 40x slower here when OpenBLAS spreads a 3000 x 15 problem over threads, and the fits call
    this thousands of times.  Near-collinear columns are handled by the pseudo-inverse cut-off.
    """
    norms = np.sqrt(np.einsum("ij,ij->j", m, m))
    scale = np.where(norms > 0, 1.0 / np.where(norms > 0, norms, 1.0), 0.0)
    ms = m * scale
    gram = ms.T @ ms
    coef, *_ = np.linalg.lstsq(gram, ms.T @ y, rcond=rcond)
    return coef * scale


def _slots(specs: list[NLParam], free: set[str], n_tr: int) -> list[tuple[NLParam, int | None]]:
    out: list[tuple[NLParam, int | None]] = []
    for par in specs:
        if par.name in free:
            out += [(par, i) for i in range(n_tr)] if par.per_trial else [(par, None)]
    return out


def _get(nl: dict[str, Array], par: NLParam, i: int | None) -> float:
    return float(nl[par.name][i]) if i is not None else float(nl[par.name])


def _pack(nl: dict[str, Array], slots: list[tuple[NLParam, int | None]]) -> tuple[Array, Array, Array]:
    x, lo, hi = [], [], []
    for par, i in slots:
        val = min(max(_get(nl, par, i), par.lo), par.hi)
        if par.log:
            x.append(np.log(val)); lo.append(np.log(par.lo)); hi.append(np.log(par.hi))
        else:
            x.append(val); lo.append(par.lo); hi.append(par.hi)
    xa, la, ha = np.array(x), np.array(lo), np.array(hi)
    span = ha - la
    return np.clip(xa, la + 1e-9 * span, ha - 1e-9 * span), la, ha


def _unpack(x: Array, nl0: dict[str, Array], slots: list[tuple[NLParam, int | None]]
            ) -> dict[str, Array]:
    nl = {k: np.array(v, dtype=float, copy=True) for k, v in nl0.items()}
    for xv, (par, i) in zip(x, slots):
        val = float(np.exp(xv)) if par.log else float(xv)
        if i is None:
            nl[par.name] = np.array(val)
        else:
            nl[par.name][i] = val
    return nl


def evaluate(trials: list[TrialGrid], y: Array, effects: tuple[str, ...], nl: dict[str, Array],
             cache: StateCache | None = None, rows: Array | None = None) -> Fit:
    """Solve the linear coefficients for fixed nonlinear values (optionally on ``rows`` only)."""
    m, labels = design(trials, effects, nl, cache)
    mm, yy = (m, y) if rows is None else (m[rows], y[rows])
    c = solve_bounded(mm, yy, labels)
    resid = y - m @ c
    used = np.any(mm != 0, axis=0)
    n_nl = sum(len(trials) if p.per_trial else 1 for p in nl_specs(effects))
    r = resid if rows is None else resid[rows]
    return Fit(effects, nl, dict(zip(labels, c.tolist())), float(r @ r), len(yy),
               int(np.count_nonzero(used)) + n_nl, resid)


def fit(trials: list[TrialGrid], y: Array, effects: tuple[str, ...], nl0: dict[str, Array],
        free: set[str], cache: StateCache | None = None, max_nfev: int = 60) -> Fit:
    """Least-squares fit of the nonlinear parameters named in ``free`` (others held at nl0)."""
    cache = cache if cache is not None else StateCache()
    slots = _slots(nl_specs(effects), free, len(trials))
    if not slots:
        return evaluate(trials, y, effects, nl0, cache)
    x0, lo, hi = _pack(nl0, slots)

    def res(x: Array) -> Array:
        nl = _unpack(x, nl0, slots)
        m, labels = design(trials, effects, nl, cache)
        if not np.all(np.isfinite(m)):
            return np.full_like(y, 10.0)     # a failed simulation is a very bad fit
        return y - m @ solve_bounded(m, y, labels)

    sol = least_squares(res, x0, bounds=(lo, hi), method="trf", x_scale=1.0, diff_step=1e-5,
                        max_nfev=max_nfev, xtol=1e-6, ftol=1e-8)
    out = evaluate(trials, y, effects, _unpack(sol.x, nl0, slots), cache)
    out.nl_se = _nl_se(sol.jac, out, slots, len(trials))
    return out


def _nl_se(jac: Array, f: Fit, slots: list[tuple[NLParam, int | None]], n_tr: int
           ) -> dict[str, Array]:
    """Standard errors of the nonlinear values: s^2 (J^T J)^-1, mapped from log space."""
    s2 = f.sse / max(f.n - f.k, 1)
    jtj = jac.T @ jac
    try:
        cov = np.linalg.pinv(jtj, rcond=1e-10) * s2
    except np.linalg.LinAlgError:
        cov = np.full(jtj.shape, np.nan)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    out: dict[str, Array] = {}
    for j, (par, i) in enumerate(slots):
        val = float(f.nl[par.name]) if i is None else float(f.nl[par.name][i])
        se = val * sd[j] if par.log else sd[j]
        if i is None:
            out[par.name] = np.array(se)
        else:
            out.setdefault(par.name, np.full(n_tr, np.nan))[i] = se
    return out
