"""The fitting simulator and the effect library agree with the reference forward model."""
import numpy as np
import pytest

from reference_py.discrepancy.fastsim import simulate_force_fast
from reference_py.discrepancy.effects import known_force_term, simulate_extended
from reference_py.params import PRESETS
from reference_py.sim.simulate import simulate_force
from reference_py.sim.trajectory import TrajectorySpec, lspb_profile


@pytest.mark.parametrize("preset", sorted(PRESETS))
@pytest.mark.parametrize("speed,rate", [(10.0, 200.0), (2.5, 83.0)])
def test_fast_simulator_matches_reference(preset: str, speed: float, rate: float) -> None:
    t, d, v, _ = lspb_profile(TrajectorySpec(depth_mm=45.0, speed_mm_s=speed, dwell_s=1.5,
                                             rate_hz=rate, cycles=2))
    rng = np.random.default_rng(3)
    t = t + rng.uniform(0, 0.3 / rate, len(t)) * (np.arange(len(t)) > 0)  # irregular times
    p = PRESETS[preset].params
    ref, _ = simulate_force(p, t, d, v)
    fast, _ = simulate_force_fast(p, t, d, v)
    ext = simulate_extended(p, {}, t, d, v)
    assert np.max(np.abs(fast - ref[0])) <= 1e-9
    assert np.max(np.abs(ext - ref[0])) <= 1e-9


def test_known_force_term_is_the_effect_alone() -> None:
    t, d, v, _ = lspb_profile(TrajectorySpec(depth_mm=40.0, speed_mm_s=5.0, dwell_s=3.0))
    p = PRESETS["paper-10mms"].params
    term = known_force_term(p, {"sensor_drift": {"drift": 1e-3}}, t, d, v)
    assert np.allclose(term, 1e-3 * (t - 0.5 * (t[0] + t[-1])))
    relax = known_force_term(p, {"dwell_relaxation": {"tau_fast_s": 0.3, "tau_slow_s": 3.0,
                                                      "relax_fast": 0.02, "relax_slow": 0.04}},
                             t, d, v)
    moving = np.abs(v) > 0.02
    assert np.max(np.abs(relax[moving])) <= 1e-15 and relax.min() < -0.04


def test_exponential_step_is_exact_for_frozen_rates() -> None:
    """kernel.exp_affine against the closed form z(h) = p/q + (z0 - p/q) e^{-qh}, from a
    vanishing qh (where p/q cannot be formed) to a very stiff one."""
    from reference_py.sim.kernel import exp_affine
    h, p, z0 = 0.01, 2.0, 0.3
    for q in (0.0, 1e-9, 1.0, 50.0, 1e4, 1e7):
        a, c = exp_affine(np.array(h), np.array(p), np.array(q))
        x = q * h
        if x < 1e-6:      # (1 - e^-x) / x by its series: p / q would cancel catastrophically
            exact = z0 * np.exp(-x) + p * h * (1.0 - x / 2.0 + x * x / 6.0)
        else:
            exact = p / q + (z0 - p / q) * np.exp(-x)
        assert abs(float(a * z0 + c) - exact) <= 1e-12 * max(1.0, abs(exact)), q


def _ramp(rate_hz: float = 100.0) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(0.0, 12.0, 1.0 / rate_hz)
    l = np.interp(t, [0.0, 1.0, 6.0, 8.0, 11.0], [0.0, 0.0, 12.0, 12.0, 0.0])
    return t, l


def test_stiff_samples_step_exactly_and_others_do_not_move() -> None:
    """Where a fit wanders into stiff parameters (lambda h = l b h up to 90 per sample here),
    4 RK3 sub-steps blow up; with ``stiff_from`` those samples take exponential sub-steps and
    follow 400 RK3 sub-steps (lambda h < 0.1 each, converged) closely, at 4 sub-steps' cost.
    Parameters that are not stiff give the very same numbers as plain RK3."""
    from reference_py.discrepancy.fastsim import state_trajectory
    t, l = _ramp()
    p, q, alpha = 0.001, 0.01, 0.3                   # b up to 790 /mm: lambda h up to 90
    fine = state_trajectory(t, l, p, q, alpha, substeps=400)
    plain = state_trajectory(t, l, p, q, alpha, substeps=4)
    stiff = state_trajectory(t, l, p, q, alpha, substeps=4, stiff_from=1.0)
    scale = float(np.max(np.abs(fine)))
    assert not np.all(np.abs(plain - fine) <= 0.5 * scale)   # RK3 alone: unstable here
    assert np.max(np.abs(stiff - fine)) <= 2e-3 * scale, np.max(np.abs(stiff - fine)) / scale
    p, q = 2.0, 3.0                                  # b <= 0.5 /mm: lambda h <= 0.06
    assert np.array_equal(state_trajectory(t, l, p, q, alpha, substeps=4, stiff_from=1.0),
                          state_trajectory(t, l, p, q, alpha, substeps=4))
