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

import re
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.linalg import lapack, solve_triangular
from scipy.optimize import least_squares

from .effects import NLParam, StateCache, TrialGrid, design, design_parts, lin_bound, nl_specs
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
    lo, hi = _bounds_of(tuple(labels))
    return lo.copy(), hi.copy()


#: a layer's tenting coefficients k1, k2 (its force k1 u + k2 u^2, u in [0, 1]) are at most this
#: multiple of the trial's largest force: k1 + k2 is the force the layer holds at its rupture.
#: Without the bound a layer that the fitted surface leaves a fraction of a stride thick (one
#: fitting row at u ~ 1e-3) fits that row with k2 ~ 1e6 N, and the prediction between the rows
#: reaches it (measured-like seed 38: 1.5e6 N, RMSE to truth 1.9e4 N)
LAYER_LOAD_MAX_X = 1.0
_LOAD = re.compile(r"layer\d+_load[12]\[(\d+)\]$")


def coef_bounds(labels: list[str], trials: list[TrialGrid]) -> tuple[Array, Array]:
    """Bounds of the linear coefficients: effects.LIN_BOUNDS, and each layer's tenting
    coefficients at most LAYER_LOAD_MAX_X times its trial's largest force."""
    lo, hi = bounds_of(labels)
    for j, lab in enumerate(labels):
        hit = _LOAD.match(lab)
        if hit and int(hit.group(1)) < len(trials):
            hi[j] = min(hi[j], LAYER_LOAD_MAX_X * trials[int(hit.group(1))].peak_n)
    return lo, hi


@lru_cache(maxsize=64)
def _bounds_of(labels: tuple[str, ...]) -> tuple[Array, Array]:
    lo, hi = zip(*(lin_bound(lab) for lab in labels))
    return np.array(lo, dtype=float), np.array(hi, dtype=float)


def solve_bounded(m: Array, y: Array, labels: list[str], rcond: float = 1e-12,
                  blocks: list[tuple[int, int]] | None = None, warm: dict | None = None,
                  bounds: tuple[Array, Array] | None = None, bvls_cut: float | None = None
                  ) -> Array:
    """Least squares with the documented coefficient bounds (effects.LIN_BOUNDS, or ``bounds``:
    see :func:`coef_bounds`).

    The free solution is used when it satisfies them (cut-off ``rcond`` on the Gram matrix of the
    unit-scaled columns, i.e. sqrt(rcond) on their singular values, as :func:`solve_linear`);
    otherwise a bounded-variable least-squares solve (BVLS, Stark & Parker) on the unit-scaled
    columns.  Both run on the k x k triangle R of a QR factorisation of the tall system [m y]
    (computed per row block -- ``blocks``, one per trial -- and stacked: each trial has few
    non-zero columns), which has the tall matrix's singular values to rounding; the sub-problems
    of BVLS are cut at the tall least-squares cut-off eps * max(rows, columns) x the largest
    singular value (numpy's default on the samples x k matrix), not at one scaled to k: a cut
    scaled to k keeps near-null directions the tall solve drops, and a held-out fit extrapolates
    them (measured-like seed 38 went 10^3..10^8 N astray).  When every column subset is provably
    above that cut-off (1/|R^-1|_F > cut |R|_F), the sub-problems are solved by QR; otherwise by
    SVD (numpy lstsq).  ``warm`` (a dict kept by the caller across calls with the same columns)
    starts BVLS from the previous call's active set; without it, BVLS starts from the clipped
    free (QR) or minimum-norm (SVD) solution.  Where columns are exactly dependent (in the
    multi-layer base, sigma2's column s l is the bands' friction columns plus r_1 times the first
    membrane's linear load column, which is l / r_1 while the tip advances towards r_1), the
    split of the coefficients along the null direction depends on the start, the fitted values
    m x do not (the optimum of a convex quadratic is unique in m x): a fit's residuals may start
    warm, and its reported coefficients come from a cold solve (:func:`evaluate`).
    ``bvls_cut`` replaces that relative cut-off on the sub-problems: the held-out refit
    (score.heldout_sse) cuts them where its free solve cuts, sqrt(its rcond).
    """
    lo, hi = bounds_of(labels) if bounds is None else bounds
    out = np.zeros(m.shape[1])
    r = _reduce(m, y, blocks, warm)
    k = m.shape[1]
    norms = np.sqrt(np.einsum("ij,ij->j", r[:, :k], r[:, :k]))  # column norms (Q is orthogonal)
    used = norms > 0
    if not used.any():
        return out
    if not used.all():                  # all-zero columns dropped: R of the others
        r = _pad(_qr_r(r[:, np.append(np.flatnonzero(used), k)]))
    k = int(np.count_nonzero(used))
    r_tri, qy, rho2 = r[:k, :k] / norms[used], r[:k, k], float(r[k, k] ** 2)
    lo_s, hi_s = lo[used] * norms[used], hi[used] * norms[used]
    cut = _EPS * max(m.shape[0], k) if bvls_cut is None else bvls_cut
    gram_cut = float(np.sqrt(rcond))
    full_rank, rel_min = _rank_bound(r_tri, needed=min(gram_cut, cut))
    key = tuple(np.flatnonzero(used).tolist()) + (len(labels),)
    start = None
    fast = full_rank and rel_min > cut
    if warm is not None and warm.get("key") == key:
        start = warm["on_bound"]
    tol = 1e-12 * norms[used]
    if full_rank and rel_min > gram_cut:
        x = _solve_upper(r_tri, qy)
    elif start is not None and _surely_outside(r_tri, qy, lo_s - tol, hi_s + tol, gram_cut):
        # BVLS from a warm start reads no x (it solves its free variables afresh): all the
        # free solution would decide is that it is not used, and that is known already
        x = None
    else:
        x = np.linalg.lstsq(r_tri, qy, rcond=gram_cut)[0]
    if x is not None and np.all((x >= lo_s - tol) & (x <= hi_s + tol)):
        out[used] = x / norms[used]
        return out
    if not fast and start is None:
        # start from the minimum-norm solution at the same cut-off (scipy's lsq_linear starts
        # at rcond = eps, where a direction at eps-level either stays or goes by rounding); a
        # warm start solves its free variables afresh, so it needs no x
        x = np.linalg.lstsq(r_tri, qy, rcond=cut)[0]
    x, on_bound = bvls(r_tri, qy, lo_s, hi_s, np.zeros(k) if x is None else x, cut, fast, start,
                       rho2)
    if warm is not None:
        warm["key"], warm["on_bound"] = key, on_bound
    out[used] = x / norms[used]
    return out


_EPS = float(np.finfo(float).eps)
#: safety factor on the error bound of :func:`_surely_outside` (the bound's constants are of
#: order one; this leaves room for what a first-order bound leaves out)
_OUTSIDE_SAFETY = 1e3


def _surely_outside(r_tri: Array, b: Array, lo: Array, hi: Array, rcond: float) -> bool:
    """Whether numpy's lstsq(r_tri, b, rcond) -- r_tri upper triangular with unit columns; the
    minimum-norm solution on the singular values above rcond x the largest -- certainly leaves
    the box [lo, hi].  False means "not known", never "inside": the caller then solves.

    Made for the multi-layer base, whose triangle has one exactly dependent column: one tiny
    pivot R_pp (the next singular value ~0.04 sigma_1).  With R_pp set to 0 the triangle R0 has
    rank k - 1, and its minimum-norm least-squares solution takes one triangular inverse, of T
    (R without row and column p, still triangular), instead of an SVD (5-10x the cost): b
    loses its part along R0's left null vector w, T solves the rest with x_p = 0, and x loses
    its part along the null vector n.  It is the lstsq solution to rounding when the rank is
    provably the SVD's -- sigma_{k-1} >= 1/|T^-1|_F - |R_pp| clearly above rcond |R|_F >=
    rcond sigma_1, sigma_k <= |R n|/|n| clearly below rcond x the largest column norm <= rcond
    sigma_1 -- and a coefficient is taken to leave the box only by more than a bound on how far
    the two can be apart (a truncated least-squares solution perturbed by rounding and by R_pp,
    times the condition number, for the solution and for its residual, with a safety factor:
    ~1e-7 of the solution there, where the two differ by ~1e-14 and the coefficients BVLS has to
    move lie outside by a fraction of it)."""
    k = r_tri.shape[1]
    if k < 2:
        return False
    diag = np.abs(np.diag(r_tri))
    p = int(np.argmin(diag))
    keep = np.delete(np.arange(k), p)
    with np.errstate(all="ignore"):
        try:
            t_inv = _solve_upper(r_tri[np.ix_(keep, keep)], np.eye(k - 1))
        except np.linalg.LinAlgError:         # another zero pivot: not this case
            return False
        n = np.zeros(k)                       # R0 n = 0
        n[p] = 1.0
        n[:p] = -t_inv[:p, :p] @ r_tri[:p, p]
        sigma_kept = 1.0 / float(np.linalg.norm(t_inv)) - float(diag[p])   # Weyl: R = R0 + R_pp
        sigma_dropped = float(np.linalg.norm(r_tri @ n) / np.linalg.norm(n))
        fro = float(np.linalg.norm(r_tri))
        col_max = float(np.max(np.sqrt(np.einsum("ij,ij->j", r_tri, r_tri))))
        if not (np.isfinite(sigma_kept) and np.isfinite(sigma_dropped)
                and sigma_kept > 2.0 * rcond * fro and sigma_dropped < 0.5 * rcond * col_max):
            return False
        w = np.zeros(k)                       # w^T R0 = 0
        w[p] = 1.0
        w[p + 1:] = -t_inv[p:, p:].T @ r_tri[p, p + 1:]
        b0 = b - w * (w @ b) / (w @ w)        # the part of b that R0 reaches
        x = np.zeros(k)
        x[keep] = t_inv @ b0[keep]
        x -= n * (n @ x) / (n @ n)            # the minimum-norm one
        kappa = fro / sigma_kept
        res = float(np.linalg.norm(b - r_tri @ x))
        err = _OUTSIDE_SAFETY * (k * _EPS + float(diag[p]) / col_max) * kappa * \
            (float(np.linalg.norm(x)) + kappa * res / col_max)
    if not np.isfinite(err):
        return False
    return bool(np.any((x < lo - err) | (x > hi + err)))
#: BVLS stops when no variable violates the optimality conditions by more than this (gradient of
#: the unit-scaled problem), or when an iteration lowers the cost by less than this fraction
BVLS_TOL = 1e-10


def _pad(r: Array) -> Array:
    """A QR triangle with fewer rows than columns (fewer samples than columns) padded square."""
    return r if r.shape[0] >= r.shape[1] else np.vstack([r, np.zeros((r.shape[1] - r.shape[0],
                                                                      r.shape[1]))])


def _reduce(m: Array, y: Array, blocks: list[tuple[int, int]] | None,
            memo: dict | None = None) -> Array:
    """The (k+1) x (k+1) triangle of the QR factorisation of [m y] (k = columns of m): its k x k
    block R, last column Q^T y and corner rho give min |m x - y|^2 = min |R x - Q^T y|^2 + rho^2.
    With row ``blocks``, each block is factorised on its non-zero columns and the triangles are
    stacked and factorised again (a tall-skinny QR: as backward stable as one factorisation).
    Householder QR is backward stable column by column, so R of the unit-scaled columns is this
    R's columns scaled, and an all-zero column of m stays an all-zero column of R.  ``memo``
    (kept by a fit, whose y does not change) holds ``parts`` and ``cols``, the blocks as
    effects.design_parts made them (each block's values on the columns it can fill), and the
    triangles of the last ones seen: a block whose part is the same object is not factorised
    again (a Jacobian column that moves one trial's surface changes one block)."""
    k = m.shape[1]
    if blocks is None or len(blocks) < 2:
        return _pad(_qr_r(np.column_stack([m, y])))
    parts = memo.get("parts") if memo is not None else None
    if parts is not None and len(parts) != len(blocks):
        parts = None
    cols = memo.get("cols") if parts is not None else None   # type: ignore[union-attr]
    tri = []
    for i, (a, b) in enumerate(blocks):
        hit = None
        if parts is not None:
            kept = memo.setdefault(("qr", i), [])   # type: ignore[union-attr]
            hit = next((r for part, r in kept if part is parts[i]), None)
        if hit is None:
            # the block's non-zero columns (a float is true where it is not 0, or NaN), read
            # off the part design_parts made when there is one: the rest of its row is 0
            blk, blk_cols = (parts[i], cols[i]) if cols is not None else (m[a:b], None)
            nz_in = np.flatnonzero(blk.any(axis=0))
            nz = nz_in if blk_cols is None else blk_cols[nz_in]
            rb = _qr_r(np.column_stack([blk[:, nz_in], y[a:b]]))
            hit = np.zeros((rb.shape[0], k + 1))
            hit[:, np.append(nz, k)] = rb
            if parts is not None:
                kept.insert(0, (parts[i], hit))
                del kept[_QR_KEEP:]
        tri.append(hit)
    return _pad(_qr_r(np.vstack(tri)))


#: triangles kept per trial block (the design cache keeps as many arrays per trial)
_QR_KEEP = 4


def _qr_r(a: Array) -> Array:
    """R of a Householder QR factorisation (LAPACK dgeqrf), min(rows, columns) x columns."""
    qr, _, info = _geqrf(a)
    if info != 0:
        raise np.linalg.LinAlgError(f"dgeqrf: info {info}")
    top = qr[:min(a.shape)]
    return np.where(_below_diagonal(top.shape), 0.0, top)     # np.triu, its mask made once


@lru_cache(maxsize=256)
def _below_diagonal(shape: tuple[int, int]) -> Array:
    """The mask np.triu clears (below the diagonal) for a matrix of ``shape``: the fits take
    R of the same few shapes thousands of times."""
    mask = np.tri(shape[0], shape[1], k=-1, dtype=bool)
    mask.flags.writeable = False
    return mask


def _geqrf(a: Array) -> tuple[Array, Array, int]:
    qr, tau, _, info = lapack.dgeqrf(a)
    return qr, tau, int(info)


def _rank_bound(r_tri: Array, needed: float = 0.0) -> tuple[bool, float]:
    """Whether R is invertible, and a lower bound on sigma_min / sigma_max of R -- and of every
    subset of its columns, whose smallest singular value is no smaller and largest no larger:
    1 / (|R^-1|_F |R|_F).

    ``needed``: the caller only asks whether the bound is above this.  R^-1 holds 1/R_ii on its
    diagonal, so the bound is at most min |R_ii| / |R|_F; when that is below half of ``needed``
    (room for rounding), R^-1 is not formed and (False, that upper bound) returned -- the answer
    to the caller's question as the full computation gives it (the multi-layer base's triangle,
    with an exactly dependent column, every time)."""
    k = r_tri.shape[1]
    d = np.abs(np.diag(r_tri))
    if k == 0 or not np.all(d > 0):
        return False, 0.0
    upper = float(np.min(d) / np.linalg.norm(r_tri))
    if upper < 0.5 * needed:
        return False, upper
    with np.errstate(all="ignore"):
        inv = _solve_upper(r_tri, np.eye(k))
        bound = 1.0 / (np.linalg.norm(inv) * np.linalg.norm(r_tri))
    return (bool(np.isfinite(bound)) and bound > 0), float(bound) if np.isfinite(bound) else 0.0


def _solve_upper(r: Array, b: Array) -> Array:
    """solve_triangular(r, b, check_finite=False) for an upper-triangular r: the very LAPACK call
    it makes (dtrtrs; on r^T as a lower triangle when r is not Fortran-ordered), without its
    argument handling, which costs more than the solve itself at these sizes (k <= ~100) and
    runs thousands of times per fit."""
    if b.size == 0 or r.dtype != np.float64 or b.dtype != np.float64:
        return solve_triangular(r, b, check_finite=False)
    if r.flags.f_contiguous:
        x, info = lapack.dtrtrs(r, b, lower=0, trans=0)
    else:
        x, info = lapack.dtrtrs(r.T, b, lower=1, trans=1)
    if info > 0:
        raise np.linalg.LinAlgError(f"singular matrix: resolution failed at diagonal {info - 1}")
    if info < 0:
        raise ValueError(f"illegal value in {-info}-th argument of internal trtrs")
    return x


def _free_solve(a: Array, b: Array, cut: float, fast: bool) -> Array:
    """Least squares on the free columns: QR when they are known to be well above the tall
    cut-off, else the SVD with it (numpy lstsq)."""
    if fast:
        q, rr = np.linalg.qr(a)
        return _solve_upper(rr, q.T @ b)
    return np.linalg.lstsq(a, b, rcond=cut)[0]


def bvls(a: Array, b: Array, lo: Array, hi: Array, x0: Array, cut: float, fast: bool,
         start: Array | None = None, const: float = 0.0) -> tuple[Array, Array]:
    """Bounded-variable least squares, min |a x - b|^2 + const with lo <= x <= hi (Stark &
    Parker 1995; the steps of scipy's lsq_linear method 'bvls', written for the reduced system).

    ``x0``: an unconstrained solution, clipped to the bounds to start; or ``start``, an active set
    (-1 at the lower bound, +1 at the upper, 0 free) from a previous solve.  Returns x and the
    final active set."""
    n = a.shape[1]
    on_bound = np.zeros(n)
    x = x0.copy()
    if start is not None:
        on_bound = start.copy()
        x = np.where(on_bound < 0, lo, np.where(on_bound > 0, hi, np.clip(x, lo, hi)))
    else:
        on_bound[x <= lo] = -1.0
        on_bound[x >= hi] = 1.0
        x = np.clip(x, lo, hi)
    free = np.flatnonzero(on_bound == 0)
    # until the least-squares solution on the free variables is feasible: violators to bounds
    while free.size:
        bound = on_bound != 0
        z = _free_solve(a[:, free], b - a[:, bound] @ x[bound], cut, fast)
        low, up = z < lo[free], z > hi[free]
        x[free[low]], on_bound[free[low]] = lo[free[low]], -1.0
        x[free[up]], on_bound[free[up]] = hi[free[up]], 1.0
        ok = ~(low | up)
        x[free[ok]] = z[ok]
        if ok.all():
            break
        free = free[ok]
    r = a @ x - b
    cost = 0.5 * (float(r @ r) + const)
    g = a.T @ r
    for _ in range(n):
        viol = g * on_bound
        viol[on_bound == 0] = np.abs(g[on_bound == 0])
        if np.max(viol, initial=0.0) < BVLS_TOL:
            break
        on_bound[int(np.argmax(g * on_bound))] = 0.0
        while True:
            free = np.flatnonzero(on_bound == 0)
            bound = on_bound != 0
            xf = x[free]
            z = _free_solve(a[:, free], b - a[:, bound] @ x[bound], cut, fast)
            low = np.flatnonzero(z < lo[free])
            up = np.flatnonzero(z > hi[free])
            if low.size or up.size:
                v = np.concatenate([low, up])
                steps = np.concatenate([lo[free][low] - xf[low], hi[free][up] - xf[up]]) / \
                    (z[v] - xf[v])
                j = int(np.argmin(steps))
                x[free] = xf + steps[j] * (z - xf)
                on_bound[free[v[j]]] = -1.0 if j < low.size else 1.0
            else:
                x[free] = z
                break
        r = a @ x - b
        new = 0.5 * (float(r @ r) + const)
        done = cost - new < BVLS_TOL * cost
        cost = new
        g = a.T @ r
        if done:
            break
    return x, on_bound


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


def trial_rows(trials: list[TrialGrid]) -> list[tuple[int, int]]:
    """Row range of each trial in the stacked design matrix."""
    s = np.cumsum([0] + [len(g.t_s) for g in trials])
    return [(int(s[i]), int(s[i + 1])) for i in range(len(trials))]


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
    c = solve_bounded(mm, yy, labels, blocks=trial_rows(trials) if rows is None else None,
                      bounds=coef_bounds(labels, trials))
    resid = y - m @ c
    used = np.any(mm != 0, axis=0)
    # a parameter that only refines an effect's form counts once it has left its plain value
    n_nl = sum(len(trials) if p.per_trial else 1 for p in nl_specs(effects)
               if p.screened or not np.all(np.asarray(nl[p.name]) == p.init))
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
    blocks = trial_rows(trials)
    warm: dict = {}          # the bounded solve's last active set: the next call starts there
    lims: dict = {}
    stack = _BlockStack(blocks)

    def res(x: Array) -> Array:
        nl = _unpack(x, nl0, slots)
        parts, cols, labels = design_parts(trials, effects, nl, cache)
        m, finite = stack.update(parts, cols, len(labels))
        warm["parts"], warm["cols"] = parts, cols
        if not finite:
            return np.full_like(y, 10.0)     # a failed simulation is a very bad fit
        if lims.get("labels") != labels:
            lims["labels"], lims["bounds"] = labels, coef_bounds(labels, trials)
        return y - m @ solve_bounded(m, y, labels, blocks=blocks, warm=warm,
                                     bounds=lims["bounds"])

    sol = least_squares(res, x0, bounds=(lo, hi), method="trf", x_scale=1.0, diff_step=1e-5,
                        max_nfev=max_nfev, xtol=1e-6, ftol=1e-8)
    out = evaluate(trials, y, effects, _unpack(sol.x, nl0, slots), cache)
    out.nl_se = _nl_se(sol.jac, out, slots, len(trials))
    return out


class _BlockStack:
    """The design (effects.design) assembled from its trial parts (effects.design_parts) into
    one array kept across a fit's residual calls: a part that is the same object as last time
    (design_parts hands back the cached array when the trial's values did not move, as for every
    trial but one in a Jacobian column that moves one surface) is neither copied again nor
    checked for finiteness again, and the zeros around the parts are written once.  The array is
    overwritten by the next call: a caller must not keep it."""

    def __init__(self, rows: list[tuple[int, int]]) -> None:
        self.rows = rows
        self.buf: Array | None = None
        self.cols: list[Array | None] = [None] * len(rows)
        self.parts: list[Array | None] = [None] * len(rows)
        self.finite = [False] * len(rows)

    def update(self, parts: list[Array], cols: list[Array], n_cols: int) -> tuple[Array, bool]:
        """The design and whether every entry is finite (the zeros around the parts are)."""
        shape = (self.rows[-1][1], n_cols)
        if self.buf is None or self.buf.shape != shape or \
                any(c is not kept for c, kept in zip(cols, self.cols)):
            self.buf = np.zeros(shape)
            self.cols = list(cols)
            self.parts = [None] * len(self.rows)
        for i, (part, (a, b)) in enumerate(zip(parts, self.rows)):
            if part is not self.parts[i]:
                self.buf[a:b, cols[i]] = part
                self.parts[i] = part
                self.finite[i] = bool(np.all(np.isfinite(part)))
        return self.buf, all(self.finite)


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
