"""Scoring a candidate effect: information criterion on the fit, improvement on held-out data.

BIC with an effective sample size: residuals of real recordings are correlated (the sensor
averages), which would overstate the evidence of thousands of samples; n_eff = n (1 - rho) /
(1 + rho) with rho the lag-1 autocorrelation of the extended model's residual.

Held-out data: with three or more trials, whole trials (leave one out; each training set still
spans two speeds).  With one or two trials, time blocks of 0.5 s dealt round-robin into three
folds (every phase stays represented in every training set).  The nonlinear parameters stay at
their full-data values; the linear ones are refitted on the training part; per-trial terms of a
held-out trial (its offset, relaxation amplitude) are fitted on that trial alone.
"""
from __future__ import annotations

import numpy as np

from .effects import StateCache, TrialGrid, design
from ..fmath import Array
from .fit import Fit, solve_bounded, solve_linear

BLOCK_S = 0.5
N_FOLDS = 3
#: pseudo-inverse cut-off (on the Gram matrix of unit columns) of the held-out refits: a short dwell
#: split into blocks leaves near-collinear per-trial relaxation columns (hold, fast, slow) on a
#: second or two of training data, and an unregularised solve extrapolates them wildly into the
#: held-out block (held-out errors 100x the fit's).  1e-8 here is a 1e-4 cut on the columns.
HELDOUT_RCOND = 1e-8


def lag1(resid: Array, bounds: list[tuple[int, int]]) -> float:
    num = den = 0.0
    for a, b in bounds:
        r = resid[a:b] - np.mean(resid[a:b])
        num += float(r[1:] @ r[:-1])
        den += float(r @ r)
    return float(np.clip(num / den if den > 0 else 0.0, 0.0, 0.95))


def delta_bic(base: Fit, ext: Fit, bounds: list[tuple[int, int]]) -> float:
    """BIC(base) - BIC(ext): positive when the extension is worth its parameters."""
    rho = lag1(ext.resid, bounds)
    n_eff = ext.n * (1.0 - rho) / (1.0 + rho)
    return float(n_eff * np.log(base.sse / ext.sse) - (ext.k - base.k) * np.log(n_eff))


def delta_bic_local(base: Fit, ext: Fit, bounds: list[tuple[int, int]], rows: Array,
                    own_nl: tuple, n_trials: int) -> float:
    """BIC difference judged in the effect's own phases, with a price that follows sharing.

    The error reduction counts only on ``rows`` (the phases the effect acts on), with the
    effective sample size from the lag-1 autocorrelation of the extended residual there.  A
    parameter shared by the condition costs ln(n_eff); a per-trial parameter is informed by one
    trial's share of the rows only and costs ln(n_eff / n_trials) (a relaxation amplitude per
    trial is not priced as if the whole record had to pay for it).
    """
    r0, r1 = base.resid[rows], ext.resid[rows]
    n = int(np.count_nonzero(rows))
    if n < 5:
        return -np.inf
    sse0, sse1 = float(r0 @ r0), float(r1 @ r1)
    rr = r1 - r1.mean()
    rho = float(np.clip((rr[1:] @ rr[:-1]) / max(rr @ rr, 1e-30), 0.0, 0.95))
    n_eff = max(n * (1.0 - rho) / (1.0 + rho), 2.0)
    k_new = max(ext.k - base.k, 0)
    per_trial_nl = sum(n_trials for p in own_nl if p.per_trial)
    shared_nl = sum(1 for p in own_nl if not p.per_trial)
    lin = max(k_new - per_trial_nl - shared_nl, 0)
    per_trial_lin = lin if lin >= n_trials and n_trials > 1 and lin % n_trials == 0 else 0
    shared = k_new - per_trial_nl - per_trial_lin
    pen = shared * np.log(n_eff) + (per_trial_nl + per_trial_lin) * \
        np.log(max(n_eff / n_trials, 2.0))
    return float(n_eff * np.log(max(sse0, 1e-30) / max(sse1, 1e-30)) - pen)


def folds(grids: list[TrialGrid]) -> tuple[str, list[Array]]:
    """The held-out scheme and, per fold, a boolean mask of held-out rows."""
    sizes = [len(g.t_s) for g in grids]
    n = sum(sizes)
    starts = np.cumsum([0] + sizes)
    if len(grids) >= 3:
        out = []
        for i in range(len(grids)):
            m = np.zeros(n, dtype=bool)
            m[starts[i]:starts[i + 1]] = True
            out.append(m)
        return "whole trials (leave one out)", out
    block = np.concatenate([np.floor((g.t_s - g.t_s[0]) / BLOCK_S).astype(int) for g in grids])
    return f"time blocks ({BLOCK_S} s, {N_FOLDS} folds)", \
        [(block % N_FOLDS) == k for k in range(N_FOLDS)]


def heldout_sse(grids: list[TrialGrid], y: Array, f: Fit, masks: list[Array],
                cache: StateCache | None = None, where: Array | None = None) -> float:
    """Held-out SSE of ``f`` (summed on the rows ``where`` only, when given)."""
    m, labels = design(grids, f.effects, f.nl, cache)
    own_cols = {i: [j for j, lab in enumerate(labels) if lab.endswith(f"[{i}]")]
                for i in range(len(grids))}
    sizes = [len(g.t_s) for g in grids]
    starts = np.cumsum([0] + sizes)
    total = 0.0
    for mask in masks:
        train = ~mask
        # bounded like the fit itself (a friction or stiffness the fit keeps >= 0 must not turn
        # negative on the training rows), its sub-problems cut where the held-out solve cuts
        c = solve_bounded(m[train], y[train], labels, HELDOUT_RCOND,
                          bvls_cut=float(np.sqrt(HELDOUT_RCOND)))
        pred = m @ c
        r = y - pred
        for i in range(len(grids)):
            rows = np.zeros(len(y), dtype=bool)
            rows[starts[i]:starts[i + 1]] = True
            rows &= mask
            if not rows.any():
                continue
            keep = where[rows] if where is not None else np.ones(int(rows.sum()), dtype=bool)
            if not keep.any():
                continue
            if not (train[starts[i]:starts[i + 1]]).any():
                cols = own_cols[i]
                sub = m[np.ix_(rows, cols)]
                r_i = r[rows] - sub @ solve_linear(sub, r[rows], HELDOUT_RCOND)
            else:
                r_i = r[rows]
            r_i = r_i[keep]
            total += float(r_i @ r_i)
    return total
