"""The small dense EKF kernels every filter of the bank uses (state dimension n <= 4 here:
Model III's filter 1 carries z, sigma0 and two relaxation strengths).

Matrices are lists of lists of batch arrays (P[i][j] has shape (batch,)).  Every product is an
explicit sum in a fixed order — k = 0, 1, ..., n-1, accumulated left to right — and only the upper
triangle of a covariance is computed and then mirrored, so the result is symmetric by construction
and the C library can repeat the operations one for one.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .fmath import Array, Real

Matrix = list[list[Array]]


def _dot(a: list[Array], b: list[Array]) -> Array:
    acc = a[0] * b[0]
    for k in range(1, len(a)):
        acc = acc + a[k] * b[k]
    return acc


def predict_covariance(P: Matrix, f: list[Array], q: list[Array]) -> Matrix:
    """P <- F P F^T + diag(q) for the bank's transition F = [[f], [0, I]]: z's row f (dz/dz0,
    dz/du) and the parameters a random walk.

    With that F the product needs f twice and copies the rest (no product by 0 or 1):
      (F P)[0][j] = sum_k f[k] P[k][j],   (F P)[a][j] = P[a][j]  (a >= 1)
      out[0][0]   = sum_k (F P)[0][k] f[k] + q[0]
      out[0][b]   = (F P)[0][b]           (F[b] is the unit row b, b >= 1)
      out[a][b]   = P[a][b] + (q[a] if a == b)
    The dense product's other terms are products by 0, which add nothing to a finite sum (a
    zero's sign aside); a non-finite P fails positive_definite either way.
    """
    n = len(P)
    fp = [_dot(f, [P[k][j] for k in range(n)]) for j in range(n)]
    out: Matrix = [[None] * n for _ in range(n)]  # type: ignore[list-item]
    out[0][0] = _dot(fp, f) + q[0]
    for b in range(1, n):
        out[0][b] = fp[b]
        out[b][0] = fp[b]
    for a in range(1, n):
        for b in range(a, n):
            v = P[a][b] + q[a] if a == b else P[a][b]
            out[a][b] = v
            out[b][a] = v
    return out


@dataclass
class Update:
    x: list[Array]
    P: Matrix
    innovation: Array   # y - h, before the update
    s: Array            # innovation variance h P h^T + R
    nis: Array          # innovation^2 / s
    accepted: Array     # bool: the gate let the update through


def joseph_update(R: Real, x: list[Array], P: Matrix, h: list[Array], innovation: Array,
                  r: Array, gate2: Array, open_gate: Array | bool = False,
                  step: Array | None = None, hold: bool = False) -> Update:
    """Scalar measurement update in Joseph form, behind an innovation gate.

    S = h P h^T + r,  K = P h^T / S,  x += K y,  P = (I - K h) P (I - K h)^T + K r K^T.
    When y^2 > gate2 S the measurement is rejected and x, P are returned unchanged, unless
    ``open_gate`` (per batch element) forces it through.  ``step``: the update is bounded
    by bound_step on its parameter part x[1:] (None: no bound).  ``hold``: the gain's rows
    1.. are 0, so x[1:] stays bit for bit and P follows that gain (the Joseph form is right
    for any gain; the parameters held, FilterBank.set_frozen).
    """
    n = len(x)
    pht = [_dot(P[i], h) for i in range(n)]
    s = _dot(h, pht) + r
    k = [np.zeros_like(pht[i]) if hold and i > 0 else pht[i] / s for i in range(n)]
    y2 = innovation * innovation
    nis = y2 / s
    # the gate decides without the division (the NIS spans 1e-10..1e4: no fixed-point word
    # holds it; y^2 and gate2 S fit one, tools/fixedpoint.py); S <= 0 or NaN as y^2 / S did
    one, zero = R.c(1.0), R.c(0.0)
    accepted = np.where(s > zero, y2 <= gate2 * s, (s < zero) & (y2 >= zero)) | open_gate
    a = [[(one if i == j else zero) - k[i] * h[j] for j in range(n)] for i in range(n)]
    ap = [[_dot(a[i], [P[m][j] for m in range(n)]) for j in range(n)] for i in range(n)]
    newP: Matrix = [[None] * n for _ in range(n)]  # type: ignore[list-item]
    for i in range(n):
        for j in range(i, n):
            v = _dot(ap[i], a[j]) + (k[i] * r) * k[j]
            v = np.where(accepted, v, P[i][j])
            newP[i][j] = v
            newP[j][i] = v
    newx = [np.where(accepted, x[i] + k[i] * innovation, x[i]) for i in range(n)]
    if step is not None:
        newx = bound_step(x, newx, step)
    return Update(newx, newP, innovation, s, nis, accepted)


def bound_step(x: list[Array], xu: list[Array], step: Array) -> list[Array]:
    """The update's step bound, measured on the parameters x[1:]: where the largest
    |xu[a] - x[a]| over a >= 1 exceeds ``step``, every xu[a], the state x[0] included, becomes
    x[a] + (xu[a] - x[a]) * (step / largest) — the whole update shortened, its direction kept;
    elsewhere xu stands bit for bit.  The largest is taken in order a = 1, 2, ... from 0 with a
    strict comparison, so a NaN difference is passed over; a non-finite update is left to the
    bank's guard, which resets the filter.  Why a bound (config.U_STEP_MAX): the filters
    identify log-parameters, and a step far beyond ~0.3 leaves the region where
    h(u + du) ~ h(u) + h' du.  Why z is shortened with them: the gain moves z and the
    parameters together, each by the share of the innovation the other does not explain; z's
    full share beside a shortened parameter part over-explains the innovation, and at a
    reversal that overshoot was the next sample's innovation, gated, reopened and overshot
    again (measured-like seed 156: the posterior force 5-9 N off a -0.9 N retraction).
    Chosen against z's full share on the step bound's `select` records, confirmed on
    `held` (README "Model III's step bound")."""
    big = np.zeros_like(x[1])
    for a in range(1, len(x)):
        d = np.abs(xu[a] - x[a])
        big = np.where(d > big, d, big)
    over = big > step
    scale = step / big
    return [np.where(over, x[a] + (xu[a] - x[a]) * scale, xu[a]) for a in range(len(x))]


def positive_definite(R: Real, P: Matrix) -> Array:
    """Sylvester's criterion: every leading principal minor > 0 (n <= 4), all entries finite."""
    n = len(P)
    zero = R.c(0.0)
    ok = P[0][0] > zero
    if n >= 2:
        d2 = P[0][0] * P[1][1] - P[0][1] * P[1][0]
        ok = ok & (d2 > zero)
    if n >= 3:
        c0 = P[1][1] * P[2][2] - P[1][2] * P[2][1]
        c1 = P[1][0] * P[2][2] - P[1][2] * P[2][0]
        c2 = P[1][0] * P[2][1] - P[1][1] * P[2][0]
        d3 = (P[0][0] * c0 - P[0][1] * c1) + P[0][2] * c2
        ok = ok & (d3 > zero)
    if n >= 4:
        # Laplace expansion along the first two rows: 2x2 minors of rows 0, 1 (s) times the
        # complementary minors of rows 2, 3 (c), columns (i, j)
        def m2(r: int, i: int, j: int) -> Array:
            return P[r][i] * P[r + 1][j] - P[r][j] * P[r + 1][i]
        d4 = (((((m2(0, 0, 1) * m2(2, 2, 3) - m2(0, 0, 2) * m2(2, 1, 3))
                 + m2(0, 0, 3) * m2(2, 1, 2)) + m2(0, 1, 2) * m2(2, 0, 3))
               - m2(0, 1, 3) * m2(2, 0, 2)) + m2(0, 2, 3) * m2(2, 0, 1))
        ok = ok & (d4 > zero)
    # P is symmetric by construction (predict_covariance and joseph_update write both
    # triangles from one value): the upper triangle holds every value
    for i in range(n):
        for j in range(i, n):
            ok = ok & np.isfinite(P[i][j])
    return ok
