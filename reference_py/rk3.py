"""One sample of the state equation, stable at every rate, with sensitivities.

The state equation dz/dt = l beta - lambda z, lambda = l b = l sigma0 / g(l), is linear in z.
Each of ``substeps`` equal sub-steps h of the sample interval (depth interpolated linearly
between the two samples) takes one of two steps, chosen from the decay rates lambda at the
sub-step's start, middle and end depths (terms the step computes anyway):

* h * max(lambda) <= EXP_BOUND (1): Kutta's classic RK3 (Butcher tableau c = (0, 1/2, 1),
  a21 = 1/2, a31 = -1, a32 = 2, b = (1/6, 4/6, 1/6)), third order, accurate and monotone
  there (its stability interval on the negative axis ends at h lambda = 2.51);
* otherwise the exponential midpoint step, exact for coefficients frozen at the mid depth:
  z1 = zq + E (z0 - zq), E = exp(-h lambda_m), zq = beta / b_m (the quasi-steady state);
  second order, unconditionally stable (|E| < 1), monotone.

Alongside z the step carries the forward sensitivities dz/dz0 and dz/du_j (the exact derivative
of the *discrete* map, obtained by differentiating every stage; JACOBIANS.md §5, §5b), which
are the transition Jacobian the EKF needs.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .fmath import Array, Real
from .model import (Theta, clamp_depth, decay_du, depth_terms, state_rate, state_rate_du,
                    state_rate_dz)

#: a sub-step whose h * lambda exceeds this takes the exponential step (see above)
EXP_BOUND = 1.0


@dataclass
class Rk3Result:
    z: Array
    dz_dz0: Array
    dz_du: dict[str, Array]


def rk3_step(R: Real, th: Theta, z: Array, l_a: Array, l_b: Array, dt: Array, substeps: int,
             params: tuple[str, ...] = ()) -> Rk3Result:
    """Advance z from depth l_a to depth l_b over dt seconds.

    ``params``: the scaled parameters whose sensitivities are wanted (may be empty).
    """
    n = R.c(float(substeps))
    h = dt / n
    h2 = h * R.c(0.5)
    h6 = h / R.c(6.0)
    twoh = h * R.c(2.0)
    four = R.c(4.0)
    one = R.c(1.0)
    bound = R.c(EXP_BOUND)
    dl = l_b - l_a
    s_z = np.ones_like(z)  # dz/dz0
    s_u = {p: np.zeros_like(z) for p in params}
    # the end of one sub-step is the start of the next: its depth terms are computed once
    d1 = depth_terms(R, th, clamp_depth(R, l_a + dl * (R.c(0.0) / n)))
    for j in range(substeps):
        taum = R.c(float(2 * j + 1)) / (n * R.c(2.0))
        tau1 = R.c(float(j + 1)) / n
        d0 = d1
        dm = depth_terms(R, th, clamp_depth(R, l_a + dl * taum))
        d1 = depth_terms(R, th, clamp_depth(R, l_a + dl * tau1))
        fz0, fzm, fz1 = state_rate_dz(d0), state_rate_dz(dm), state_rate_dz(d1)

        k1 = state_rate(th, d0, z)
        z2 = z + h2 * k1
        k2 = state_rate(th, dm, z2)
        z3 = (z - h * k1) + twoh * k2
        k3 = state_rate(th, d1, z3)

        # sensitivity of z: the same stages, differentiated (the rate is linear in z)
        a1 = fz0 * s_z
        a2 = fzm * (s_z + h2 * a1)
        a3 = fz1 * ((s_z - h * a1) + twoh * a2)
        new_s_z = s_z + h6 * ((a1 + four * a2) + a3)

        new_s_u = {}
        for p in params:
            s = s_u[p]
            q1 = fz0 * s
            r1 = state_rate_du(th, d0, z, p)
            if r1 is not None:
                q1 = q1 + r1
            q2 = fzm * (s + h2 * q1)
            r2 = state_rate_du(th, dm, z2, p)
            if r2 is not None:
                q2 = q2 + r2
            q3 = fz1 * ((s - h * q1) + twoh * q2)
            r3 = state_rate_du(th, d1, z3, p)
            if r3 is not None:
                q3 = q3 + r3
            new_s_u[p] = s + h6 * ((q1 + four * q2) + q3)

        z_rk = z + h6 * ((k1 + four * k2) + k3)

        # the largest decay rate -fz of the sub-step decides (NaN compares false: RK3)
        lo = np.where(fzm < fz0, fzm, fz0)
        lo = np.where(fz1 < lo, fz1, lo)
        stiff = (h * (-lo)) > bound
        if np.any(stiff):
            # exponential midpoint: z1 = zq + E (z0 - zq), exact for frozen mid-depth terms
            lam = -fzm
            E = R.exp(-(h * lam))
            zq = th.beta / dm.b
            dz0 = z - zq
            z_ex = zq + E * dz0
            new_s_z = np.where(stiff, E * s_z, new_s_z)
            one_e = one - E
            for p in params:
                part = decay_du(th, dm, p)
                if part is None:
                    s_ex = E * s_u[p]
                else:
                    lam_u, zq_u = part
                    s_ex = (E * s_u[p] - (dz0 * E) * (h * lam_u)) + one_e * zq_u
                new_s_u[p] = np.where(stiff, s_ex, new_s_u[p])
            z_rk = np.where(stiff, z_ex, z_rk)
        z = z_rk
        s_z, s_u = new_s_z, new_s_u
    return Rk3Result(z, s_z, s_u)
