"""The robust estimator's bookkeeping: decimated record, refinement trigger, restart, status."""
import numpy as np
import pytest

from reference_py import robust as rb
from reference_py.config import default_config
from reference_py.fmath import F64
from reference_py.params import get_preset
from reference_py.sim.simulate import simulate_force
from reference_py.sim.trajectory import TrajectorySpec, lspb_profile

PRESET = get_preset("paper-10mms")


def _scenario(cycles=1, depth=20.0, dwell=0.3, rest=0.1):
    t, l, v, _ = lspb_profile(TrajectorySpec(depth_mm=depth, dwell_s=dwell, cycles=cycles,
                                             rest_s=rest))
    f = simulate_force(PRESET.params, t, l, v)[0][0]
    f = f + np.random.default_rng(9).normal(0, 2e-3, len(f))
    return np.floor(t * 1e6 + 0.5).astype(np.int64), l, v, f


def _run(est, t, l, v, f):
    outs = []
    for k in range(len(t)):
        outs.append(est.step(t[k:k + 1], l[k:k + 1], v[k:k + 1], f[k:k + 1]))
    return outs


def test_buffer_decimates_and_stays_uniform():
    t, l, v, f = _scenario()
    est = rb.RobustEstimator(F64, default_config(), [PRESET.params.as_list()],
                             rb.RobustConfig(buffer_len=32, min_entries=8, fit_iterations=2))
    inside = np.flatnonzero(l > 0)
    for k in range(inside[-1] + 1):
        est.step(t[k:k + 1], l[k:k + 1], v[k:k + 1], f[k:k + 1])
    n = int(est.count[0])
    assert 16 <= n <= 32
    dt = np.diff(est.buf[0, :n, 0])
    # one sample period times the decimation factor, everywhere
    np.testing.assert_allclose(dt, est.decim[0] * 0.005, rtol=1e-9)
    assert est.buf[1, 0, 0] == 0.0            # the anchor is the last surface sample
    assert est.decim[0] >= 8


def test_refines_once_per_insertion_and_restarts_the_bank():
    t, l, v, f = _scenario(cycles=2)
    # 60 % off in every identified parameter (Model II keeps f2 and alpha fixed)
    p = PRESET.params
    start = p.with_values(sigma0=p.sigma0 * 1.6, sigma1=p.sigma1 / 1.6, sigma2=p.sigma2 * 1.6,
                          f1=p.f1 * 1.6, beta=p.beta / 1.6).as_list()
    # the whole refinement in the step that ends the insertion (slice_entries 0): 2 090 slices
    # of the default size would outlast the 0.1 s at the surface between the two insertions
    est = rb.RobustEstimator(F64, default_config(), [start],
                             rb.RobustConfig(fit_iterations=10, slice_entries=0))
    assert est.slices() == 1
    outs = _run(est, t, l, v, f)
    refined = [k for k, o in enumerate(outs) if o.status[0] & rb.STATUS_REFINED]
    assert len(refined) == 2
    assert [k for k, o in enumerate(outs) if o.status[0] & rb.STATUS_REFINING] == refined
    for k in refined:
        assert l[k] == 0.0 and l[k - 1] > 0.0     # at the sample the needle leaves the tissue
    # after a restart the bank's scaled parameters are centred on the refinement
    assert all(u[0] == 0.0 for u in est.bank.u)
    # (plus the random walk of the samples at the surface since the restart)
    assert 0.01 <= est.bank.P[0][1][1][0] <= 0.0101
    # the refinement moved sigma2 close to the truth from 60 % off
    assert abs(est.bank.th.sigma2[0] / PRESET.params.sigma2 - 1) < 0.05
    assert 0.0 < est.confidence[0] <= 1.0
    assert outs[-1].status[0] & rb.STATUS_CONVERGED
    assert all(np.all(np.isfinite(o.params)) for o in outs)


def test_short_insertion_is_not_refined():
    t, l, v, f = _scenario(depth=0.5, dwell=0.0)
    assert (l > 0).sum() < 90
    est = rb.RobustEstimator(F64, default_config(), [PRESET.params.as_list()],
                             rb.RobustConfig(min_entries=96))
    outs = _run(est, t, l, v, f)
    assert not any(o.status[0] & rb.STATUS_REFINED for o in outs)


def test_invalid_robust_config_is_refused():
    for bad in (dict(buffer_len=33), dict(buffer_len=2), dict(min_entries=97),
                dict(fit_substeps=0), dict(restart_p0_u=0.0), dict(lm_lambda0=float("nan"))):
        with pytest.raises(ValueError):
            rb.RobustEstimator(F64, default_config(), [PRESET.params.as_list()],
                               rb.RobustConfig(**bad))


def test_reset_clears_the_record():
    t, l, v, f = _scenario()
    # slices of 96 entries: the fit is adopted within the scenario's 0.1 s at the surface
    est = rb.RobustEstimator(F64, default_config(), [PRESET.params.as_list()],
                             rb.RobustConfig(fit_iterations=2, slice_entries=96))
    _run(est, t, l, v, f)
    assert est.has_refined[0]
    est.reset()
    assert est.count[0] == 0 and not est.has_refined[0] and est.confidence[0] == 0.0
    assert not est.inside[0] and est.decim[0] == 1


def test_reset_restores_the_configured_nominal():
    t, l, v, f = _scenario()
    start = [x * 1.3 for x in PRESET.params.as_list()]
    est = rb.RobustEstimator(F64, default_config(), [start], rb.RobustConfig(fit_iterations=3))
    _run(est, t, l, v, f)
    assert est.bank.th.sigma0[0] != pytest.approx(start[0])
    est.reset()
    assert est.bank.th.sigma0[0] == pytest.approx(start[0], rel=1e-15)


def _leaving(l):
    return [k for k in range(1, len(l)) if l[k] == 0.0 and l[k - 1] > 0.0]


def test_refinement_is_sliced_and_adopts_the_same_fit():
    """Default slicing (slice_entries 1, the C library's steps: one buffer entry a sample):
    the refinement runs on the samples from the one that ends the insertion for slices()
    samples, REFINED on the last, and the bank restarts from exactly the fit that the whole
    refinement in one step gives.  The scenario rests 8.6 s at the surface after the
    insertion, 1 720 samples: long enough for the 1 710 slices."""
    t, l, v, f = _scenario(rest=8.6)
    start = [x * 1.3 for x in PRESET.params.as_list()]
    sliced = rb.RobustEstimator(F64, default_config(), [start], rb.RobustConfig())
    whole = rb.RobustEstimator(F64, default_config(), [start], rb.RobustConfig(slice_entries=0))
    n = sliced.slices()
    assert n == 2 * 9 * 95 == 1710
    a, b = _run(sliced, t, l, v, f), _run(whole, t, l, v, f)
    k0 = _leaving(l)[0]
    busy = [k for k, o in enumerate(a) if o.status[0] & rb.STATUS_REFINING]
    assert busy == list(range(k0, k0 + n))
    assert [k for k, o in enumerate(a) if o.status[0] & rb.STATUS_REFINED] == [k0 + n - 1]
    assert [k for k, o in enumerate(b) if o.status[0] & rb.STATUS_REFINED] == [k0]
    for x, y in zip(sliced.prev_theta, whole.prev_theta):
        assert x[0] == y[0]                   # the same bits
    assert sliced.confidence[0] == whole.confidence[0] > 0.0
    # until the adoption the bank went on with its own estimate, not the fit's
    assert not np.array_equal(a[k0 + n - 2].params, b[k0 + n - 2].params)


def test_insertion_during_a_refinement_is_not_recorded():
    """A second insertion that begins before the first one's fit is adopted (22 slices of 96
    entries, 0.1 s = 20 samples at the surface) is not recorded or refined; the first is
    adopted during it."""
    t, l, v, f = _scenario(cycles=2)
    est = rb.RobustEstimator(F64, default_config(), [PRESET.params.as_list()],
                             rb.RobustConfig(fit_iterations=10, slice_entries=96))
    assert est.slices() == 22
    outs = _run(est, t, l, v, f)
    refined = [k for k, o in enumerate(outs) if o.status[0] & rb.STATUS_REFINED]
    k0, k1 = _leaving(l)
    assert refined == [k0 + 21] and l[k0 + 21] > 0.0     # adopted inside the second insertion
    assert not est.refining[0] and est.count[0] == 0


@pytest.mark.parametrize("hold", ["frozen", "predict_only"])
def test_result_dropped_when_held_at_adoption(hold):
    """Held parameters or predict-only switched on while the fit runs: at its last slice the
    result is dropped (no REFINED, the bank not restarted, no confidence).  Slices of 96
    entries: the fit's 18 samples end within the scenario's 0.1 s at the surface."""
    t, l, v, f = _scenario()
    est = rb.RobustEstimator(F64, default_config(), [PRESET.params.as_list()],
                             rb.RobustConfig(slice_entries=96))
    k0 = _leaving(l)[0]
    outs = []
    for k in range(len(t)):
        if k == k0 + 3:
            getattr(est, f"set_{hold}")(True)
        outs.append(est.step(t[k:k + 1], l[k:k + 1], v[k:k + 1], f[k:k + 1]))
    assert sum(bool(o.status[0] & rb.STATUS_REFINING) for o in outs) == est.slices()
    assert not any(o.status[0] & rb.STATUS_REFINED for o in outs)
    assert not est.has_refined[0] and est.confidence[0] == 0.0 and not est.refining[0]
