"""Kutta's RK3 step converges at third order to an accurate ODE solution."""
import numpy as np
from scipy.integrate import solve_ivp

from reference_py.fmath import F64
from reference_py.params import PARAM_NAMES, get_preset
from reference_py.rk3 import rk3_step
from reference_py.sim.simulate import _theta_direct


def _theta(p):
    return _theta_direct(F64, [F64.arr([getattr(p, n)]) for n in PARAM_NAMES])


def _exact(p, z0, la, lb, dt):
    def rhs(t, z):
        l = la + (lb - la) * t / dt
        g = p.f1 + p.f2 * np.exp(-p.alpha * l)
        return l * (p.beta - p.sigma0 * z / g)
    sol = solve_ivp(rhs, (0.0, dt), [z0], method="DOP853", rtol=1e-13, atol=1e-15)
    return sol.y[0, -1]


def test_third_order_convergence():
    p = get_preset("paper-10mms").params
    th = _theta(p)
    z0, la, lb, dt = 0.05, 30.0, 45.0, 0.4   # large enough for a visible truncation error
    exact = _exact(p, z0, la, lb, dt)
    errors = []
    for n in (8, 16, 32, 64):
        z = rk3_step(F64, th, F64.arr([z0]), F64.arr([la]), F64.arr([lb]), F64.arr([dt]), n).z
        errors.append(abs(z[0] - exact))
    ratios = [errors[i] / errors[i + 1] for i in range(len(errors) - 1)]
    print("RK3 errors", errors, "ratios", ratios)
    for r in ratios:
        assert 7.0 < r < 9.0, ratios
    assert errors[-1] < 1e-7


def test_one_substep_is_accurate_at_200hz():
    """The filters use one sub-step per 5 ms sample: its error is far below the noise."""
    p = get_preset("paper-10mms").params
    th = _theta(p)
    exact = _exact(p, 0.1, 49.95, 50.0, 0.005)
    z = rk3_step(F64, th, F64.arr([0.1]), F64.arr([49.95]), F64.arr([50.0]), F64.arr([0.005]), 1).z
    assert abs(z[0] - exact) < 1e-8
