"""The force model (paper eqs. 1-4) and its hand-derived partial derivatives.

    dz/dt = l * (beta - sigma0 * z / g(l))                         state equation
    f     = sigma0 * z * l + s(v) * l * (sigma1 * e(l) * (beta - sigma0 * z / g(l)) + sigma2)
    g(l)  = f1 + f2 * e(l),   e(l) = exp(-alpha * l),   s(v) = tanh(v / eps)

Model I identifies f1, f2, sigma0, sigma1, sigma2, alpha with beta = beta0 fixed; Model II
identifies sigma0, sigma1, sigma2, f1, beta with f2 and alpha fixed.  Both are this one function
of seven parameters; the models differ only in which parameters are held fixed.

Every expression is written with its operation order fixed (explicit parentheses), because the C
library repeats the same operations and must produce the same bits.  The derivation of each
partial derivative is in JACOBIANS.md beside this file.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .fmath import Array, Real
from .params import IDX, PARAM_NAMES, f1_kappa


@dataclass
class Theta:
    """Physical parameters of a batch (arrays), with the factors d theta / d u of the scaled form.

    ``ex`` is the excess of f1 over kappa * (-f2) (the part of f1 that is identified) and
    ``mkf2`` = -kappa * f2 = d f1 / d u_f2 (f1 follows f2 so that g(0) stays positive).
    """

    sigma0: Array
    sigma1: Array
    sigma2: Array
    f1: Array
    f2: Array
    alpha: Array
    beta: Array
    ex: Array
    mkf2: Array


class ScaledParams:
    """The log-parametrisation theta = nominal * exp(u) (f1 through its excess); see params.py."""

    def __init__(self, R: Real, nominal: list[float], batch: int) -> None:
        self.R = R
        self.nominal = [R.full(batch, v) for v in nominal]
        self.kappa = R.c(f1_kappa(nominal[IDX["f2"]]))
        self.ex_nominal = R.full(batch, nominal[IDX["f1"]] - f1_kappa(nominal[IDX["f2"]]) *
                                 (-nominal[IDX["f2"]]))

    def theta(self, u: list[Array]) -> Theta:
        """All physical parameters from the seven log-ratios u (index order PARAM_NAMES)."""
        R = self.R
        vals: dict[str, Array] = {}
        for name in PARAM_NAMES:
            if name == "f1":
                continue
            i = IDX[name]
            vals[name] = self.nominal[i] * R.exp(u[i])
        ex = self.ex_nominal * R.exp(u[IDX["f1"]])
        mkf2 = -(self.kappa * vals["f2"])
        f1 = mkf2 + ex
        return Theta(vals["sigma0"], vals["sigma1"], vals["sigma2"], f1, vals["f2"],
                     vals["alpha"], vals["beta"], ex, mkf2)

    def refresh(self, th: Theta, u: list[Array], names: tuple[str, ...]) -> Theta:
        """Theta after the parameters ``names`` changed; f1 is rebuilt when f1 or f2 changed.

        Bit-identical to :meth:`theta` on the new u, but only the changed exponentials are taken.
        """
        R = self.R
        new = Theta(th.sigma0, th.sigma1, th.sigma2, th.f1, th.f2, th.alpha, th.beta, th.ex,
                    th.mkf2)
        for name in names:
            if name == "f1":
                continue
            i = IDX[name]
            setattr(new, name, self.nominal[i] * R.exp(u[i]))
        if "f1" in names:
            new.ex = self.ex_nominal * R.exp(u[IDX["f1"]])
        if "f1" in names or "f2" in names:
            new.mkf2 = -(self.kappa * new.f2)
            new.f1 = new.mkf2 + new.ex
        return new

    def dtheta_du(self, th: Theta, name: str) -> Array:
        """d theta_name / d u_name (for f2 this is the direct factor; f1's share is th.mkf2)."""
        return th.ex if name == "f1" else getattr(th, name)


class BatchScaled(ScaledParams):
    """ScaledParams whose nominal differs per batch element (the bank's: ``cols[j]`` holds
    parameter j's nominal value of every run)."""

    def __init__(self, R: Real, cols: list[tuple[float, ...]], batch: int) -> None:
        self.R = R
        self.nominal = [R.arr(list(col)) for col in cols]
        f2 = np.asarray(cols[IDX["f2"]], dtype=np.float64)
        f1 = np.asarray(cols[IDX["f1"]], dtype=np.float64)
        kappa = np.where(f2 < 0.0, 1.0, 0.0)
        if len(set(kappa.tolist())) > 1:
            raise ValueError("every run of a batch must have the same sign of f2")
        self.kappa = R.c(float(kappa[0]))
        self.ex_nominal = R.arr(f1 - kappa * (-f2))
        if np.any(self.ex_nominal <= 0):
            raise ValueError("nominal f1 must exceed -f2 (g(0) = f1 + f2 must be positive)")


@dataclass
class DepthTerms:
    """Quantities that depend on depth and parameters only, shared by rate and output."""

    l: Array        # depth, mm (clamped at 0)
    e: Array        # exp(-alpha l)
    g: Array        # f1 + f2 e
    inv_g: Array    # 1 / g
    b: Array        # sigma0 / g
    dg_dalpha: Array  # -f2 l e


def depth_terms(R: Real, th: Theta, l: Array) -> DepthTerms:
    e = R.exp(-(th.alpha * l))
    g = th.f1 + th.f2 * e
    inv_g = R.c(1.0) / g
    b = th.sigma0 * inv_g
    dg_dalpha = -(th.f2 * (l * e))
    return DepthTerms(l, e, g, inv_g, b, dg_dalpha)


def clamp_depth(R: Real, l: Array) -> Array:
    """The model sees depth >= 0: out of tissue every depth term vanishes."""
    zero = R.c(0.0)
    return np.where(l > zero, l, zero)


def smooth_sign(R: Real, v: Array, eps: Array) -> Array:
    """s(v) = tanh(v / eps).  Zero during a dwell (v = 0): no friction term while at rest."""
    return R.tanh(v / eps)


def exact_sign(R: Real, v: Array) -> Array:
    one, zero = R.c(1.0), R.c(0.0)
    return np.where(v > zero, one, np.where(v < zero, -one, zero))


# ------------------------------------------------------------------------------------------
# State equation
# ------------------------------------------------------------------------------------------
def state_rate(th: Theta, d: DepthTerms, z: Array) -> Array:
    """dz/dt = l (beta - b z)."""
    return d.l * (th.beta - d.b * z)


def state_rate_dz(d: DepthTerms) -> Array:
    """d(dz/dt)/dz = -l b."""
    return -(d.l * d.b)


def state_rate_du(th: Theta, d: DepthTerms, z: Array, name: str) -> Array | None:
    """d(dz/dt)/d u_name in the scaled form, or None when the rate does not depend on it."""
    if name in ("sigma1", "sigma2"):
        return None
    if name == "sigma0":
        return -(d.l * (z * d.inv_g)) * th.sigma0
    if name == "beta":
        return d.l * th.beta
    # every other parameter acts through g:  d(rate)/dg = l b z / g
    rate_g = d.l * ((d.b * z) * d.inv_g)
    if name == "f1":
        return rate_g * th.ex
    if name == "f2":
        # d g/d u_f2 = e f2 (direct) + mkf2 (f1 follows f2)
        return (rate_g * d.e) * th.f2 + rate_g * th.mkf2
    if name == "alpha":
        return (rate_g * d.dg_dalpha) * th.alpha
    raise ValueError(name)


def decay_du(th: Theta, d: DepthTerms, name: str) -> tuple[Array, Array] | None:
    """The exponential step's partials (JACOBIANS.md §5b): d lambda/d u_name and d zq/d u_name
    for the decay rate lambda = l b and the quasi-steady state zq = beta / b, or None when
    neither depends on u_name (sigma1, sigma2)."""
    lam = d.l * d.b
    zq = th.beta / d.b
    if name in ("sigma1", "sigma2"):
        return None
    if name == "sigma0":
        return lam, -zq
    if name == "beta":
        return lam - lam, zq
    if name == "f1":
        dg = th.ex
    elif name == "f2":
        dg = d.e * th.f2 + th.mkf2
    elif name == "alpha":
        dg = d.dg_dalpha * th.alpha
    else:
        raise ValueError(name)
    # every other parameter acts through g:  d lambda = -lambda dg/g,  d zq = zq dg/g
    G = dg * d.inv_g
    return -(lam * G), zq * G


# ------------------------------------------------------------------------------------------
# Output (measurement) equation
# ------------------------------------------------------------------------------------------
@dataclass
class OutputTerms:
    m: Array    # beta - b z
    fr: Array   # sigma1 e m + sigma2: friction per unit depth, N/mm
    sl: Array   # s(v) l
    h: Array    # the force, N


def output(th: Theta, d: DepthTerms, z: Array, s: Array) -> OutputTerms:
    m = th.beta - d.b * z
    fr = (th.sigma1 * d.e) * m + th.sigma2
    sl = s * d.l
    h = (th.sigma0 * z) * d.l + sl * fr
    return OutputTerms(m, fr, sl, h)


def output_dz(th: Theta, d: DepthTerms, o: OutputTerms) -> Array:
    """dh/dz = sigma0 l - s l sigma1 e b."""
    return th.sigma0 * d.l - o.sl * ((th.sigma1 * d.e) * d.b)


def output_du(th: Theta, d: DepthTerms, z: Array, o: OutputTerms, name: str) -> Array:
    """dh/d u_name in the scaled form."""
    if name == "sigma0":
        return (z * d.l - o.sl * ((th.sigma1 * d.e) * (z * d.inv_g))) * th.sigma0
    if name == "sigma1":
        return (o.sl * (d.e * o.m)) * th.sigma1
    if name == "sigma2":
        return o.sl * th.sigma2
    if name == "beta":
        return (o.sl * (th.sigma1 * d.e)) * th.beta
    h_g = o.sl * ((th.sigma1 * d.e) * ((d.b * z) * d.inv_g))
    if name == "f1":
        return h_g * th.ex
    if name == "f2":
        return (h_g * d.e) * th.f2 + h_g * th.mkf2
    if name == "alpha":
        direct = o.sl * ((th.sigma1 * o.m) * (-(d.l * d.e)))
        return (direct + h_g * d.dg_dalpha) * th.alpha
    raise ValueError(name)


def steady_state_z(R: Real, th: Theta, d: DepthTerms) -> Array:
    """z where dz/dt = 0 at depth l > 0: beta g / sigma0 (0 out of tissue)."""
    zss = (th.beta * d.g) / th.sigma0
    return np.where(d.l > R.c(0.0), zss, R.c(0.0))
