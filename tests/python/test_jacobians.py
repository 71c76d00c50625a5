"""Every hand-derived partial derivative against central finite differences (float64).

>= 200 random (state, parameter, depth, velocity) points across insertion (v > 0), dwell (v = 0)
and retraction (v < 0), with parameters spread a factor 3 around each preset, for both models'
parametrisations (f2 < 0 and f2 > 0, i.e. kappa = 1 and 0).
"""
import numpy as np
import pytest

from reference_py.fmath import F64
from reference_py.model import (ScaledParams, clamp_depth, depth_terms, output, output_du,
                                output_dz, smooth_sign)
from reference_py.params import PARAM_NAMES, PRESETS
from reference_py.rk3 import rk3_step

N_POINTS = 240
REL_TOL = 1e-6
IDENTIFIABLE = PARAM_NAMES  # every parameter has a scaled form


def _points():
    rng = np.random.default_rng(7)
    presets = list(PRESETS.values())
    pts = []
    for i in range(N_POINTS):
        pre = presets[i % len(presets)].params
        nominal = [v * np.exp(rng.uniform(-1.1, 1.1)) for v in pre.as_list()]
        if nominal[4] < 0:        # keep f1 > -f2
            nominal[3] = -nominal[4] + abs(nominal[3] + nominal[4]) + 1e-3
        u = rng.normal(0.0, 0.3, size=len(PARAM_NAMES))
        phase = i % 3
        v = {0: rng.uniform(0.2, 12.0), 1: 0.0, 2: -rng.uniform(0.2, 12.0)}[phase]
        l_a = rng.uniform(0.0, 80.0)
        l_b = max(0.0, l_a + v * 0.005 + (0.0 if phase == 1 else rng.normal(0, 0.01)))
        z = rng.uniform(0.0, 0.4)
        pts.append((nominal, u, z, l_a, l_b, v))
    return pts


POINTS = _points()


def _model(nominal, u, z, l, v):
    sp = ScaledParams(F64, nominal, 1)
    th = sp.theta([F64.arr([x]) for x in u])
    d = depth_terms(F64, th, clamp_depth(F64, F64.arr([l])))
    s = smooth_sign(F64, F64.arr([v]), F64.arr([0.5]))
    return th, d, s, output(th, d, F64.arr([z]), s)


def _check(analytic, f_plus, f_minus, h, what):
    fd = (f_plus - f_minus) / (2.0 * h)
    err = abs(fd - analytic)
    assert err <= REL_TOL * abs(analytic) + 1e-11, f"{what}: analytic {analytic!r} fd {fd!r}"


def test_enough_points_in_every_phase():
    vs = np.array([p[5] for p in POINTS])
    assert (vs > 0).sum() >= 70 and (vs == 0).sum() >= 70 and (vs < 0).sum() >= 70


@pytest.mark.parametrize("idx", range(N_POINTS))
def test_output_partials(idx):
    nominal, u, z, _, l, v = POINTS[idx]
    th, d, s, o = _model(nominal, u, z, l, v)
    hz = 1e-6
    _check(output_dz(th, d, o)[0], _model(nominal, u, z + hz, l, v)[3].h[0],
           _model(nominal, u, z - hz, l, v)[3].h[0], hz, "dh/dz")
    for j, name in enumerate(IDENTIFIABLE):
        hu = 1e-5
        up, um = u.copy(), u.copy()
        up[j] += hu
        um[j] -= hu
        _check(output_du(th, d, F64.arr([z]), o, name)[0], _model(nominal, up, z, l, v)[3].h[0],
               _model(nominal, um, z, l, v)[3].h[0], hu, f"dh/du_{name}")


def _step(nominal, u, z, l_a, l_b, names):
    sp = ScaledParams(F64, nominal, 1)
    th = sp.theta([F64.arr([x]) for x in u])
    return rk3_step(F64, th, F64.arr([z]), F64.arr([l_a]), F64.arr([l_b]), F64.arr([0.005]), 1,
                    names)


@pytest.mark.parametrize("idx", range(N_POINTS))
def test_transition_partials(idx):
    nominal, u, z, l_a, l_b, _ = POINTS[idx]
    res = _step(nominal, u, z, l_a, l_b, IDENTIFIABLE)
    hz = 1e-6
    _check(res.dz_dz0[0], _step(nominal, u, z + hz, l_a, l_b, ()).z[0],
           _step(nominal, u, z - hz, l_a, l_b, ()).z[0], hz, "dz+/dz")
    for j, name in enumerate(IDENTIFIABLE):
        hu = 1e-5
        up, um = u.copy(), u.copy()
        up[j] += hu
        um[j] -= hu
        _check(res.dz_du[name][0], _step(nominal, up, z, l_a, l_b, ()).z[0],
               _step(nominal, um, z, l_a, l_b, ()).z[0], hu, f"dz+/du_{name}")


def test_transition_partials_over_many_substeps():
    """The chained sensitivities of several sub-steps are exact derivatives too."""
    nominal, u, z, l_a, l_b, _ = POINTS[5]
    sp = ScaledParams(F64, nominal, 1)

    def run(uu, zz):
        th = sp.theta([F64.arr([x]) for x in uu])
        return rk3_step(F64, th, F64.arr([zz]), F64.arr([l_a]), F64.arr([l_a + 3.0]),
                        F64.arr([0.3]), 7, IDENTIFIABLE)

    res = run(u, z)
    for j, name in enumerate(IDENTIFIABLE):
        up, um = u.copy(), u.copy()
        up[j] += 1e-5
        um[j] -= 1e-5
        _check(res.dz_du[name][0], run(up, z).z[0], run(um, z).z[0], 1e-5, name)


# --- the exponential step (h lambda > EXP_BOUND; JACOBIANS.md §5b) ------------------------
STIFF = range(0, N_POINTS, 4)


def _stiff_dt(nominal, u, l_a, l_b, factor):
    """dt such that h lambda at the larger depth is `factor` (lambda = l sigma0 / g)."""
    th, d, _, _ = _model(nominal, u, 0.0, max(l_a, l_b), 0.0)
    return factor / float((d.l * d.b)[0])


@pytest.mark.parametrize("idx", STIFF)
def test_exponential_step_partials(idx):
    nominal, u, z, l_a, l_b, _ = POINTS[idx]
    l_a, l_b = l_a + 1.0, l_b + 1.0   # in tissue at both ends
    factor = 1.5 + 40.0 * ((idx * 0.37) % 1.0)
    dt = _stiff_dt(nominal, u, l_a, l_b, factor)
    sp = ScaledParams(F64, nominal, 1)

    def run(uu, zz, names=()):
        th = sp.theta([F64.arr([x]) for x in uu])
        return rk3_step(F64, th, F64.arr([zz]), F64.arr([l_a]), F64.arr([l_b]), F64.arr([dt]),
                        1, names)

    res = run(u, z, IDENTIFIABLE)
    # the exponential step ran: z lies between z0 and the quasi-steady state (no overshoot)
    th, dm, _, _ = _model(nominal, u, 0.0, 0.5 * (l_a + l_b), 0.0)
    zq = float((th.beta / dm.b)[0])
    assert min(z, zq) - 1e-12 <= res.z[0] <= max(z, zq) + 1e-12
    assert 0.0 < res.dz_dz0[0] < 1.0
    # z1 is affine in z0: a wide difference is exact but for rounding
    _check(res.dz_dz0[0], run(u, z + 1e-2).z[0], run(u, z - 1e-2).z[0], 1e-2, "dz+/dz")
    for j, name in enumerate(IDENTIFIABLE):
        up, um = u.copy(), u.copy()
        up[j] += 1e-5
        um[j] -= 1e-5
        _check(res.dz_du[name][0], run(up, z).z[0], run(um, z).z[0], 1e-5, f"dz+/du_{name}")


def test_step_is_stable_at_any_rate():
    """|z - zq| never grows, however large h lambda (Kutta's RK3 alone grows past 2.51)."""
    nominal, u, _, _, _, _ = POINTS[1]
    sp = ScaledParams(F64, nominal, 1)
    th = sp.theta([F64.arr([x]) for x in u])
    l = 60.0
    _, d, _, _ = _model(nominal, u, 0.0, l, 0.0)
    lam = float((d.l * d.b)[0])
    zq = float((th.beta / d.b)[0])
    for factor in (0.5, 1.0, 2.0, 2.6, 3.0, 10.0, 1e3, 1e6):
        z0 = zq + 1.0
        res = rk3_step(F64, th, F64.arr([z0]), F64.arr([l]), F64.arr([l]),
                       F64.arr([factor / lam]), 1, ())
        assert abs(res.z[0] - zq) <= 1.0, factor
        assert abs(res.z[0] - zq) <= np.exp(-min(factor, 1.0)) * 1.01, factor
