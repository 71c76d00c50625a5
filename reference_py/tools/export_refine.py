"""Refining the exported parameters: a batch fit of the reader's replay to the record.

Why.  The bank's estimates at any sample are the ones that let the filters follow the force one
step ahead, with z corrected at every update; the model alone, replayed from depth with the same
values, drifts from the record (on the phantom tissues the best of the run's snapshots still
misses its own record by 15-30 % of the peak force, and the next trial by as much).  What a
reader of the exported file runs is that replay, so the export fits it: starting from the
snapshot export_select.py chose, the identified values are moved to minimise the sum of squared
replay residuals against the measured force less the tare (Levenberg-Marquardt).

The fit, step by step (the C twin firmware/host/export_refine.c does the same operations in the
same order, so C ≡ reference at 0 ULP):

* the unknowns are log changes d_j of the identified values theta_j, so every column of the
  Jacobian has the scale of its effect and no value changes sign; a step multiplies theta_j by
  (2 + d_j) / (2 - d_j), exp(d_j) to second order in + - / alone (the same bits in C and numpy),
  with d_j clipped to [-1.5, 1.5] (a factor between 1/7 and 7 per step);
* the Jacobian at a point comes from replaying it and, for each j, the point with theta_j *
  (1 + H): column (r_j - r_0) / H (forward differences, H = 1e-3; backward where a value sits
  at the top of its range);
* A = J'J and b = J'r are sums over the samples in sample order; a step solves
  (A + lambda diag(A)) d = -b by Cholesky (a zero diagonal entry damped by lambda alone) and
  the values are kept where a reader accepts them (readable());
* every pass replays two steps from the current values at once, damped by lambda and by 10
  lambda, each with its Jacobian rows (the bank is batched: two candidates cost the reference
  little more than one); the better of those that lower the sum of squares is kept with its
  Jacobian, lambda / 10 if it was the lighter, lambda * 10 if the heavier; neither: lambda *
  100.  The fit ends after REFINE_PASSES passes, when a kept step lowers the sum by less than
  REFINE_TOL of it, when lambda exceeds LAMBDA_MAX, or when no step changes a value;
* the standard deviations written with the values are the fit's: s^2 = SSE / (m - P) over the
  m counted samples and P unknowns, var(d) = s^2 (A^-1)_jj at the final values, sd_j =
  |theta_j| sqrt(var(d_j)); where A cannot be factored the run's own sd stays.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import EstimatorConfig
from ..params import LAYER_SET_NAMES, PARAM_NAMES
from .csvio import Trial
from .estconfig import PARAM_MAX
from .export_replay import replay, sum_in_order

#: batched replays at most (the first gives the start's Jacobian)
REFINE_PASSES = 20
#: relative finite-difference step of every value
REFINE_H = 1e-3
#: a kept step that lowers the sum of squares by less than this fraction of it ends the fit
REFINE_TOL = 1e-4
LAMBDA_START = 1e-3
LAMBDA_MAX = 1e8
#: the second, more damped step of every pass is lambda times this; neither kept: times its
#: square; the lighter kept: lambda times LAMBDA_DOWN
LAMBDA_WIDE = 10.0
LAMBDA_DOWN = 0.1
#: clip of every log change per step (a factor (2 + d) / (2 - d): between 1/7 and 7)
STEP_MIN, STEP_MAX = -1.5, 1.5
#: the relaxation strengths' sum stays at or below this (a reader needs each in (0, 1) and their
#: sum < 1): above it they are scaled down together
STRENGTH_MAX = 0.98
#: f1 stays above -f2 times this when f2 < 0 (a reader needs g(0) = f1 + f2 > 0)
G0_MARGIN = 1.01


@dataclass(frozen=True)
class Refined:
    row: list[float]        # the fitted row (the seven values, the strengths, the layer sets)
    sd: dict[int, float]    # the fit's sd of each fitted row entry (absent: not computable)
    rmse_n: float           # RMSE of the fitted values' replay, N
    passes: int             # batched replays done


def fitted_entries(names: tuple[str, ...], row_len: int, model: int) -> list[int]:
    """The row entries the fit moves: the identified values (the seven's identified ones, then
    every relaxation strength and layer set value in the row; Model I's beta is its fixed
    beta0, not a value)."""
    idx = [PARAM_NAMES.index(nm) for nm in PARAM_NAMES
           if nm in names and not (model == 1 and nm == "beta")]
    idx += [j for j in range(len(PARAM_NAMES), row_len)]
    return idx


def readable(row: list[float], n_sets: int = 0) -> list[float]:
    """``row`` kept where a reader accepts it: |value| <= PARAM_MAX, the strengths' sum at most
    STRENGTH_MAX, and g(0) = f1 + f2 > 0 (f1 raised to -f2 * G0_MARGIN when f2 < 0), for the
    row's f1 and every layer set's.  The row: the seven, the strengths, then ``n_sets`` layer
    sets of LAYER_SET_NAMES values (export_replay.py)."""
    out = list(row)
    end = len(out) - len(LAYER_SET_NAMES) * n_sets   # the strengths end here
    total = 0.0
    for j in range(len(out)):
        if len(PARAM_NAMES) <= j < end:
            out[j] = min(out[j], STRENGTH_MAX)
            total = total + out[j]
        else:
            out[j] = max(min(out[j], PARAM_MAX), -PARAM_MAX)
    if total > STRENGTH_MAX:
        scale = STRENGTH_MAX / total
        for j in range(len(PARAM_NAMES), end):
            out[j] = out[j] * scale
    f1, f2 = PARAM_NAMES.index("f1"), PARAM_NAMES.index("f2")
    f1s = [f1] + [end + k * len(LAYER_SET_NAMES) + LAYER_SET_NAMES.index("f1")
                  for k in range(n_sets)]
    for j in f1s:
        if out[f2] < 0.0 and not out[j] + out[f2] > 0.0:
            out[j] = -out[f2] * G0_MARGIN
    return out


def cholesky(M: list[list[float]]) -> list[list[float]] | None:
    """Lower L with L L' = M (row by row), or None when M is not positive definite."""
    n = len(M)
    L = [[0.0] * n for _ in range(n)]
    for i in range(n):
        for j in range(i + 1):
            s = M[i][j]
            for k in range(j):
                s = s - L[i][k] * L[j][k]
            if i == j:
                if not s > 0.0:
                    return None
                L[i][i] = math.sqrt(s)
            else:
                L[i][j] = s / L[j][j]
    return L


def cholesky_solve(L: list[list[float]], b: list[float]) -> list[float]:
    """x with L L' x = b: forward, then backward substitution."""
    n = len(b)
    y = [0.0] * n
    for i in range(n):
        s = b[i]
        for k in range(i):
            s = s - L[i][k] * y[k]
        y[i] = s / L[i][i]
    x = [0.0] * n
    for i in range(n - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, n):
            s = s - L[k][i] * x[k]
        x[i] = s / L[i][i]
    return x


def _normal_equations(res: np.ndarray, steps: list[float]) -> tuple[float, list[list[float]],
                                                                    list[float]]:
    """SSE, A = J'J and b = J'r of one pass (row 0: the values, row 1 + j: entry j moved by
    the relative step steps[j])."""
    r0 = res[0]
    P = res.shape[0] - 1
    J = [(res[1 + j] - r0) / steps[j] for j in range(P)]
    sse = sum_in_order(r0 * r0)
    A = [[0.0] * P for _ in range(P)]
    for i in range(P):
        for j in range(i + 1):
            A[i][j] = sum_in_order(J[i] * J[j])
            A[j][i] = A[i][j]
    b = [sum_in_order(J[i] * r0) for i in range(P)]
    return sse, A, b


def _perturbed(row: list[float], idx: list[int], n_sets: int
               ) -> tuple[list[list[float]], list[float]]:
    """The rows of one Jacobian: each fitted entry moved by its relative step, forward, or
    backward where forward would leave what a reader accepts; neither: the row itself (the
    column stays 0: the fit cannot move that value)."""
    rows, steps = [], []
    for j in idx:
        step, moved = REFINE_H, list(row)
        for h in (REFINE_H, -REFINE_H):
            trial_row = list(row)
            trial_row[j] = row[j] * (1.0 + h)
            if readable(trial_row, n_sets) == trial_row:
                step, moved = h, trial_row
                break
        rows.append(moved)
        steps.append(step)
    return rows, steps


def _pass(cfg: EstimatorConfig, precision: str, trial: Trial, points: list[list[float]],
          idx: list[int], surface_mm: float, tare_n: float
          ) -> tuple[list[tuple[float, list[list[float]], list[float]]], int]:
    """One batched replay of every point and its Jacobian rows: per point SSE, A and b; and
    the counted samples."""
    rows: list[list[float]] = []
    steps = []
    for pt in points:
        moved, st = _perturbed(pt, idx, len(cfg.layer_sets))
        rows += [list(pt)] + moved
        steps.append(st)
    rep = replay(cfg, precision, trial, rows, surface_mm, tare_n)
    n = 1 + len(idx)
    out = [_normal_equations(rep.residuals[c * n:(c + 1) * n], steps[c])
           for c in range(len(points))]
    return out, rep.residuals.shape[1]


def _step(row: list[float], idx: list[int], A: list[list[float]], b: list[float],
          lam: float, n_sets: int) -> list[float]:
    """The values after the damped step solving (A + lam diag(A)) d = -b (diag 0: 1); the
    row itself when the system cannot be solved."""
    P = len(idx)
    M = [list(r) for r in A]
    for i in range(P):
        M[i][i] = A[i][i] + lam * (A[i][i] if A[i][i] > 0.0 else 1.0)
    L = cholesky(M)
    if L is None:
        return list(row)
    d = cholesky_solve(L, [-x for x in b])
    if not all(math.isfinite(x) for x in d):
        return list(row)
    moved = list(row)
    for k, j in enumerate(idx):
        dk = min(max(d[k], STEP_MIN), STEP_MAX)
        moved[j] = row[j] * ((2.0 + dk) / (2.0 - dk))
    return readable(moved, n_sets)


def refine(cfg: EstimatorConfig, precision: str, trial: Trial, start: list[float],
           names: tuple[str, ...], surface_mm: float, tare_n: float) -> Refined:
    """Fit the identified entries of ``start`` (a row as a reader builds it, with the values
    of cfg.layer_sets after it: export_replay.py) to the record."""
    idx = fitted_entries(names, len(start), cfg.model)
    row = list(start)
    (first,), m = _pass(cfg, precision, trial, [row], idx, surface_mm, tare_n)
    sse, A, b = first
    passes = 1
    lam = LAMBDA_START
    P = len(idx)
    while passes < REFINE_PASSES and P > 0 and math.isfinite(sse) and lam <= LAMBDA_MAX:
        # two damped steps replayed together: lam and LAMBDA_WIDE * lam
        light = _step(row, idx, A, b, lam, len(cfg.layer_sets))
        heavy = _step(row, idx, A, b, lam * LAMBDA_WIDE, len(cfg.layer_sets))
        if light == row and heavy == row:
            break
        (r1, r2), _ = _pass(cfg, precision, trial, [light, heavy], idx, surface_mm, tare_n)
        passes += 1
        if r1[0] < sse and r1[0] <= r2[0]:
            row, (sse2, A, b), lam = light, r1, lam * LAMBDA_DOWN
        elif r2[0] < sse:
            row, (sse2, A, b), lam = heavy, r2, lam * LAMBDA_WIDE
        else:
            lam = lam * LAMBDA_WIDE * LAMBDA_WIDE
            continue
        gain = (sse - sse2) / sse
        sse = sse2
        if gain < REFINE_TOL:
            break
    sd: dict[int, float] = {}
    L = cholesky(A) if (P > 0 and m > P) else None
    if L is not None:
        s2 = sse / (m - P)
        for k, j in enumerate(idx):
            e = [0.0] * P
            e[k] = 1.0
            var = cholesky_solve(L, e)[k]
            if var > 0.0:
                sd[j] = abs(row[j]) * math.sqrt(s2 * var)
    rmse = math.sqrt(sse / m) if m > 0 else math.nan
    return Refined(row, sd, rmse, passes)


__all__ = ["REFINE_PASSES", "REFINE_H", "REFINE_TOL", "Refined", "cholesky", "cholesky_solve",
           "fitted_entries", "refine"]
