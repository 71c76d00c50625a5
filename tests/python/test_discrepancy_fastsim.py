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
