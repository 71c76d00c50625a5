"""The bank's guards: bad samples are counted and held, gaps and the surface handled, never NaN."""
import numpy as np
import pytest

from reference_py import bank as B
from reference_py.config import default_config, paper_config
from reference_py.fmath import F32, F64
from reference_py.params import get_preset
from reference_py.sim.simulate import simulate_force
from reference_py.sim.trajectory import TrajectorySpec, lspb_profile

PRESET = get_preset("paper-10mms")


@pytest.fixture(scope="module")
def scenario():
    t, l, v, phase = lspb_profile(TrajectorySpec(depth_mm=30, dwell_s=0.5))
    f = simulate_force(PRESET.params, t, l, v)[0][0]
    f = f + np.random.default_rng(2).normal(0, 2e-3, len(f))
    return np.floor(t * 1e6 + 0.5).astype(np.int64), l, v, f, phase


def _bank(R=F64, cfg=None):
    return B.FilterBank(R, cfg or default_config(), [PRESET.params.as_list()])


def _feed(bank, t, l, v, f, k0=0, k1=None):
    outs = []
    for k in range(k0, len(t) if k1 is None else k1):
        outs.append(bank.step(t[k:k + 1], l[k:k + 1], v[k:k + 1], f[k:k + 1]))
    return outs


@pytest.mark.parametrize("R", [F64, F32])
@pytest.mark.parametrize("bad,cause", [
    ((np.nan, None, None), B.REJECT_NONFINITE), ((None, np.inf, None), B.REJECT_NONFINITE),
    ((None, None, -np.inf), B.REJECT_NONFINITE), ((600.0, None, None), B.REJECT_RANGE),
    ((None, 1e4, None), B.REJECT_RANGE), ((None, None, 1e9), B.REJECT_RANGE),
    ((-5.0, None, None), B.REJECT_RANGE)])
def test_invalid_sample_is_rejected_counted_and_held(scenario, R, bad, cause):
    t, l, v, f, _ = scenario
    bank = _bank(R)
    _feed(bank, t, l, v, f, 0, 300)
    before = bank.last
    u_before = [u.copy() for u in bank.u]
    k = 300
    vals = [np.array([x if x is not None else d[k]]) for x, d in zip(bad, (l, v, f))]
    out = bank.step(t[k:k + 1], *vals)
    assert out.status[0] == B.STATUS_REJECTED
    assert bank.rejects[cause][0] == 1 and bank.rejects.sum() == 1
    assert out.force_hat[0] == before.force_hat[0] and out.z[0] == before.z[0]
    assert all(np.array_equal(a, b) for a, b in zip(u_before, bank.u))
    rest = _feed(bank, t, l, v, f, k + 1, k + 40)
    assert all(np.isfinite(o.force_hat[0]) and np.all(np.isfinite(o.params)) for o in rest)


def test_time_must_increase(scenario):
    t, l, v, f, _ = scenario
    bank = _bank()
    _feed(bank, t, l, v, f, 0, 100)
    for bad_t in (t[99], t[98], t[99] - 10):
        out = bank.step(np.array([bad_t]), l[100:101], v[100:101], f[100:101])
        assert out.status[0] == B.STATUS_REJECTED
    assert bank.rejects[B.REJECT_TIME][0] == 3


def test_first_sample_initialises_and_out_of_tissue_flagged(scenario):
    t, l, v, f, _ = scenario
    out = _feed(_bank(), t, l, v, f, 0, 3)
    assert out[0].status[0] & B.STATUS_INIT
    assert all(o.status[0] & B.STATUS_OUT_OF_TISSUE for o in out)
    assert all(o.z[0] == 0.0 for o in out)


def test_long_gap_restarts_z_at_steady_state_and_recovers(scenario):
    t, l, v, f, phase = scenario
    bank = _bank()
    outs = _feed(bank, t, l, v, f, 0, 700)       # into the dwell at 30 mm
    assert phase[699] == 2
    k = 700
    t_gap = np.array([t[k] + 10_000_000])          # 10 s later, same depth (dwell)
    out = bank.step(t_gap, l[k:k + 1], v[k:k + 1], f[k:k + 1])
    assert out.status[0] & B.STATUS_GAP
    zss = (bank.th.beta * (bank.th.f1 + bank.th.f2 * np.exp(-bank.th.alpha * l[k]))
           / bank.th.sigma0)
    assert abs(out.z[0] - zss[0]) < 0.02 * zss[0]
    assert np.isfinite(out.force_hat[0]) and abs(out.force_hat[0] - f[k]) < 0.01
    del outs


def test_poisoned_covariance_resets_that_filter_alone(scenario):
    t, l, v, f, _ = scenario
    bank = _bank()
    _feed(bank, t, l, v, f, 0, 300)
    bank.P[1][1][1] = np.array([-1.0])             # lost positive-definiteness
    out = bank.step(t[300:301], l[300:301], v[300:301], f[300:301])
    assert out.status[0] & B.STATUS_FILTER_RESET
    p0 = bank._p0(3)
    assert all(bank.P[1][a][b][0] == p0[a][b][0] for a in range(3) for b in range(3))
    # the other filters carried on: their covariances are not the initial one
    assert bank.P[0][1][1][0] < p0[1][1][0] and bank.P[2][1][1][0] < p0[1][1][0]
    assert np.isfinite(out.force_hat[0])
    later = _feed(bank, t, l, v, f, 301, 340)
    assert not any(o.status[0] & B.STATUS_FILTER_RESET for o in later)


@pytest.mark.parametrize("cfg", [default_config(schedule="rotate"), paper_config(),
                                 paper_config(1, "rotate"), default_config(1)])
def test_every_schedule_and_profile_runs_finite(scenario, cfg):
    from dataclasses import replace
    t, l, v, f, _ = scenario
    cfg = replace(cfg, beta0=PRESET.params.beta)
    outs = _feed(_bank(F32, cfg), t, l, v, f)
    fh = np.array([o.force_hat[0] for o in outs])
    assert np.all(np.isfinite(fh)) and np.all([np.all(np.isfinite(o.params_sd)) for o in outs])
    # the estimate follows the measurement
    assert np.sqrt(np.mean((fh[50:] - f[50:]) ** 2)) < 0.01


def test_rotate_updates_one_filter_per_sample(scenario):
    t, l, v, f, _ = scenario
    bank = _bank(cfg=default_config(schedule="rotate"))
    _feed(bank, t, l, v, f, 0, 200)
    names = bank.subsets
    changed = []
    for k in range(200, 206):
        before = [u.copy() for u in bank.u]
        bank.step(t[k:k + 1], l[k:k + 1], v[k:k + 1], f[k:k + 1])
        moved = {n for n in ("sigma0", "sigma1", "sigma2", "f1", "beta")
                 if bank.u[__import__("reference_py.params", fromlist=["IDX"]).IDX[n]][0]
                 != before[__import__("reference_py.params", fromlist=["IDX"]).IDX[n]][0]}
        changed.append(moved)
    for k, moved in enumerate(changed):
        i = (bank.k[0] - 6 + k) % 3
        assert moved <= set(names[i]) and moved, (k, moved, names[i])


def test_invalid_config_is_refused():
    from dataclasses import replace
    for bad in (dict(eps_mm_s=0.0), dict(r_n2=-1.0), dict(model=4), dict(schedule="x"),
                dict(p0_u=float("nan")), dict(substeps=0), dict(q_u={"sigma0": -1.0})):
        with pytest.raises(ValueError):
            B.FilterBank(F64, replace(default_config(), **bad), [PRESET.params.as_list()])
    with pytest.raises(ValueError, match="f1 must exceed"):
        B.FilterBank(F64, default_config(), [PRESET.params.with_values(f1=0.01).as_list()])
