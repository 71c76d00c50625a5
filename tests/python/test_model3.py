"""Model III (reference_py/MODEL.md §3b): its new partial derivatives against central finite
differences (JACOBIANS.md §7, §8: the turn-over length's carried sensitivity too), the
exactness of the direction state's per-sample update, the
relaxation memory in both directions (decay in a hold, overshoot and recovery at an unloading),
the configuration's switches, and Models I and II untouched by the new fields.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from reference_py.bank import FilterBank, filter_subsets, identified_names
from reference_py.config import default_config
from reference_py.fmath import F64
from reference_py.model import clamp_depth, depth_terms, output, output_du, output_dz
from reference_py.params import MODEL_PARAMS, PARAM_NAMES, PRESETS, RELAX_NAMES, get_preset
from reference_py.relax import relax_fractions, relax_output, relax_terms
from reference_py.tools.csvio import time_us

N_POINTS = 240
REL_TOL = 1e-6
NAMES3 = MODEL_PARAMS[3]


def _bank(batch: int, **kw) -> FilterBank:
    cfg = replace(default_config(3), **kw)
    nominal = [get_preset("paper-10mms").params.as_list()] * batch
    return FilterBank(F64, cfg, nominal)


def _points(rng: np.random.Generator):
    """Random states over insertion, dwell and retraction: z, the nine log-ratios, depth, the
    direction state and its sensitivity to u_delta, both memories and both decays (a =
    exp(-dt/tau) in (0, 1))."""
    B = N_POINTS
    z = rng.uniform(0.0, 0.4, B)
    u = rng.normal(0.0, 0.4, (10, B))
    l = rng.uniform(0.05, 80.0, B)
    s = rng.uniform(-1.0, 1.0, B)
    q = rng.normal(0.0, 0.5, B)
    m = rng.normal(0.0, 0.3, (2, B))
    a = rng.uniform(0.01, 0.999, (2, B))
    return z, u, l, (s, q, u[9].copy()), m, a


def _h_and_row(bank: FilterBank, z, u, l, sq, m, a):
    """The predicted force and its Jacobian row over (z, u of every Model III parameter).  The
    direction state moves with u_delta by its sensitivity q (first order: what the filter's
    linearisation assumes), s = s0 + q (u_delta - u0_delta), u0_delta the drawn point's."""
    R = F64
    s0, q, u0_delta = sq
    s = s0 + q * (u[9] - u0_delta)
    bank.u = [R.arr(x) for x in u]
    bank.th = bank.scaled.theta(bank.u)
    bank.G = [bank.scaled.nominal[7 + k] * R.exp(bank.u[7 + k]) for k in range(2)]
    bank.mrel = [R.arr(x) for x in m]
    bank._a_rel = [R.arr(x) for x in a]
    d = depth_terms(R, bank.th, clamp_depth(R, R.arr(l)))
    zz = R.arr(z)
    o = output(bank.th, d, zz, R.arr(s))
    dyn = [nm for nm in NAMES3 if nm in PARAM_NAMES]
    row = [output_dz(bank.th, d, o)] + [output_du(bank.th, d, zz, o, nm) for nm in dyn]
    row.append((d.l * o.fr) * R.arr(q))      # bank._measure's delta row
    h, row = relax_output(R, bank.G, bank._a_rel, bank.mrel, NAMES3, o.h, row)
    # the order of the row: z, the dynamic parameters, delta, then the strengths
    return h, row[:1 + len(dyn)] + row[2 + len(dyn):] + [row[1 + len(dyn)]]


def test_output_partials_against_finite_differences():
    rng = np.random.default_rng(11)
    z, u, l, s, m, a = _points(rng)
    bank = _bank(N_POINTS)
    _, row = _h_and_row(bank, z, u, l, s, m, a)
    coords = ["z"] + list(NAMES3)
    from reference_py.params import IDX
    for j, name in enumerate(coords):
        step = 1e-6
        zp, zm, up, um = z.copy(), z.copy(), u.copy(), u.copy()
        if name == "z":
            zp, zm = z + step, z - step
        else:
            up[IDX[name]] += step
            um[IDX[name]] -= step
        hp, _ = _h_and_row(bank, zp, up, l, s, m, a)
        hm, _ = _h_and_row(bank, zm, um, l, s, m, a)
        fd = (hp - hm) / (2.0 * step)
        err = np.abs(fd - row[j])
        scale = np.abs(row[j]) + 1e-9
        assert np.all(err <= REL_TOL * scale + 1e-9), (name, float(np.max(err / scale)))


def test_direction_update_is_exact():
    """The per-sample update is the exact solution of ds/dl = (1 - s sign(dl))/delta: two steps
    equal one of their sum, and a fine Runge-Kutta integration agrees; s holds when dl = 0;
    after a reversal s crosses 0 within delta ln 2 (from s = 1)."""
    bank = _bank(3, presliding_mm=1.5)
    R = F64
    restart = np.zeros(3, dtype=bool)
    bank.sdir = R.arr([0.3, -0.7, 1.0])
    dl = np.array([0.8, 0.4, -0.6])
    one = bank._direction(R.arr(dl), R.arr([0.0, 0.0, 0.0]), restart)[0]
    bank.sdir = R.arr([0.3, -0.7, 1.0])
    half = bank._direction(R.arr(dl / 2), R.arr([0.0] * 3), restart)[0]
    bank.sdir = half
    two = bank._direction(R.arr(dl), R.arr(dl / 2), restart)[0]
    assert np.allclose(one, two, rtol=0, atol=1e-15)
    for s0, d in ((0.3, 0.8), (-0.7, 0.4), (1.0, -0.6)):
        s, n = s0, 20000
        h = abs(d) / n
        sig = np.sign(d)
        f = lambda x: (sig - x) / 1.5  # noqa: E731  (ds/d|l| = (sign - s)/delta)
        for _ in range(n):
            k1 = f(s)
            k2 = f(s + h / 2 * k1)
            k3 = f(s + h / 2 * k2)
            k4 = f(s + h * k3)
            s += h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        bank.sdir = R.arr([s0] * 3)
        exact = bank._direction(R.arr([d] * 3), R.arr([0.0] * 3), restart)[0][0]
        assert abs(exact - s) < 1e-12
    bank.sdir = R.arr([0.42] * 3)
    held = bank._direction(R.arr([5.0] * 3), R.arr([5.0] * 3), restart)[0]
    assert np.all(held == 0.42)
    bank.sdir = R.arr([1.0] * 3)
    cross = bank._direction(R.arr([1.5 * np.log(2.0) + 1e-9] * 3), R.arr([0.0] * 3),
                            restart)[0]
    assert np.all(cross > 0.0)   # moving in: stays 1
    bank.sdir = R.arr([1.0] * 3)
    back = bank._direction(R.arr([0.0] * 3), R.arr([1.5 * np.log(2.0) * 1.001] * 3),
                           restart)[0]
    assert np.all(back < 0.0)    # turned over within delta ln 2


def _direction_run(bank: FilterBank, depth: np.ndarray, u_delta: float):
    """The direction state and its carried sensitivity over a depth record, delta = nominal
    e^u_delta (bank._direction sample by sample, no filter)."""
    R = F64
    bank.delta = bank.scaled.nominal[9] * R.exp(R.arr([u_delta]))
    bank.sdir, bank.sdir_du = R.arr([0.0]), R.arr([0.0])
    bank.turned = np.zeros(1, dtype=bool)
    out = []
    for k in range(1, len(depth)):
        s, q, turned = bank._direction(R.arr(depth[k:k + 1]), R.arr(depth[k - 1:k]),
                                       np.zeros(1, dtype=bool))
        bank.sdir, bank.sdir_du, bank.turned = s, q, turned
        out.append((float(s[0]), float(q[0]), bool(turned[0])))
    return np.array(out)


def test_turnover_length_sensitivity_against_finite_differences():
    """ds/du_delta carried from sample to sample (JACOBIANS.md §8) equals a central finite
    difference of the whole record's direction state in u_delta once the motion has turned
    (25 mm in at 2 mm/s, a dwell, 12 mm back, 4 mm in again, 100 Hz): before the first
    reversal it is held at 0 by design (the entry is no turn-over), after it the entry's share
    has faded by e^(-25/delta)."""
    bank = _bank(1, presliding_mm=2.0)
    depth = np.concatenate([np.arange(0.0, 25.0, 0.02), np.full(300, 25.0),
                            np.arange(25.0, 13.0, -0.02), np.arange(13.0, 17.0, 0.02)])
    run = _direction_run(bank, depth, 0.0)
    step = 1e-5
    fd = (_direction_run(bank, depth, step)[:, 0] - _direction_run(bank, depth, -step)[:, 0]) / (
        2 * step)
    turned = run[:, 2] > 0.5
    first = int(np.argmax(turned))
    assert 1249 <= first <= 1551                       # the first sample moving out
    assert np.all(run[:first, 1] == 0.0)
    err = np.abs(run[turned, 1] - fd[turned])
    assert np.max(fd[turned]) > 0.5                    # a real sensitivity, not ~0
    # what is left is the entry's share the carried sensitivity drops by design: at the end of
    # the entry s = 1 - e^(-l/delta), ds/du = -(l/delta) e^(-l/delta) = 4.7e-5 at 25 mm, and
    # it only fades (times E) afterwards
    entry = (25.0 / 2.0) * np.exp(-25.0 / 2.0)
    assert np.max(err) <= 1.01 * entry + 1e-8, float(np.max(err))
    assert np.all(np.diff(err) <= 1e-9)              # fading, never growing


def test_relaxation_memory_both_directions():
    """A held elastic force F decays to F (1 - sum g); at a sudden unloading to -F the force
    overshoots below -F (1 - sum g) and then recovers towards it (the memory effect)."""
    bank = _bank(1)
    R = F64
    dt = 0.01
    bank._a_rel = [R.exp(-(R.arr([dt]) / t)) for t in bank.c.tau]
    g_sum = float(sum(relax_fractions(R, bank.G))[0])
    F = 2.0
    f = []
    for k in range(3000):
        fe = R.arr([F if k < 2000 else -F])
        _, mp, M = relax_terms(R, bank.G, bank._a_rel, bank.mrel, fe)
        f.append(float((fe - M)[0]))
        bank.mrel = mp
    f = np.array(f)
    assert 0.39 < g_sum < 0.41            # the nominal strengths 0.15 + 0.25
    assert f[0] > 0.95 * F                # loading: the memories still empty
    assert abs(f[1999] - F * (1 - g_sum)) < 1e-3 * F
    assert np.all(np.diff(f[:2000]) < 0)  # decays monotonically in the hold
    assert f[2000] < -F * (1 - g_sum) - 0.3 * F  # overshoot at the unloading
    assert abs(f[-1] + F * (1 - g_sum)) < 0.05 * F
    assert np.all(np.diff(f[2001:]) > 0)  # and recovers


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_strengths_stay_physical_for_every_u(precision):
    """g_i = G_i / (1 + sum G) with G = nominal e^u: every strength >= 0 and their sum < 1 in
    the working precision for every |u| <= 10 (the largest u_max the configuration accepts)."""
    from reference_py.fmath import real_for
    R = real_for(precision)
    cfg = default_config(3)
    bank = FilterBank(R, cfg, [get_preset("paper-10mms").params.as_list()] * 5)
    grid = np.linspace(-10.0, 10.0, 41)
    for u0 in grid:
        bank.G = [bank.scaled.nominal[7 + k] * R.exp(R.arr([u0, -u0, u0, 0.0, 10.0 * (1 - 2 * k)]))
                  for k in range(2)]
        g = relax_fractions(R, bank.G)
        assert np.all(g[0] >= 0) and np.all(g[1] >= 0) and np.all(g[0] + g[1] < 1), u0


def test_switches_select_the_identified_parameters():
    cfg = default_config(3)
    assert identified_names(cfg) == NAMES3
    assert filter_subsets(cfg)[0] == ("sigma0",) + RELAX_NAMES
    assert filter_subsets(cfg)[1] == ("f1", "sigma1", "delta")
    nodir = replace(cfg, direction_memory=False)
    assert "delta" not in identified_names(nodir) and filter_subsets(nodir)[1] == ("f1",
                                                                                   "sigma1")
    one = replace(cfg, relax_branches=1)
    assert identified_names(one)[-2:] == ("g_fast", "delta")
    assert filter_subsets(one)[0] == ("sigma0", "g_fast")
    off = replace(cfg, relaxation=False)
    assert identified_names(off) == MODEL_PARAMS[2] + ("delta",)
    assert filter_subsets(off)[0] == ("sigma0",)
    for bad in (dict(relax_branches=3), dict(presliding_mm=0.0), dict(tau_fast_s=-1.0),
                dict(tau_slow_s=4000.0), dict(presliding_mm=float("nan"))):
        with pytest.raises(ValueError):
            replace(cfg, **bad).validate()
    with pytest.raises(ValueError, match="sum < 1"):
        FilterBank(F64, cfg, [get_preset("paper-10mms").params.as_list() + [0.5, 0.6]])
    with pytest.raises(ValueError, match="Models I and II only"):
        from reference_py.robust import RobustEstimator
        RobustEstimator(F64, cfg, [get_preset("paper-10mms").params.as_list()])


@pytest.mark.parametrize("model", [1, 2])
def test_models_1_and_2_ignore_the_new_fields(model):
    from model3_truth import model3_record
    rows = [ln.split(",") for ln in model3_record()[1:]]
    t_s, depth, vel, force = (np.array([float(r[i]) for r in rows]) for i in range(4))
    runs = []
    for kw in ({}, dict(direction_memory=False, relaxation=False, relax_branches=1,
                        presliding_mm=7.0, tau_fast_s=0.01, tau_slow_s=100.0)):
        cfg = replace(default_config(model), beta0=PRESETS["paper-10mms"].params.beta, **kw)
        bank = FilterBank(F64, cfg, [PRESETS["paper-10mms"].params.as_list()])
        t = time_us(t_s)
        out = [bank.step(t[k:k + 1], F64.arr(depth[k:k + 1]), F64.arr(vel[k:k + 1]),
                         F64.arr(force[k:k + 1])) for k in range(0, len(t))]
        runs.append(np.array([[o.force_hat[0], o.innovation[0]] for o in out]))
    assert np.array_equal(runs[0], runs[1])


def test_model3_holds_the_dwell_on_its_own_truth():
    """On a Model III truth (model3_truth.py) started at the true values, Model III's one-step
    prediction holds the dwell (Model II's drops the friction term there) and its innovations
    stay near the noise in every phase."""
    from model3_truth import model3_record
    rows = [ln.split(",") for ln in model3_record()[1:]]
    t, l, v, f = (np.array([float(r[i]) for r in rows]) for i in range(4))
    res = {}
    for model in (2, 3):
        cfg = replace(default_config(model), r_n2=4e-6)
        bank = FilterBank(F64, cfg, [get_preset("paper-10mms").params.as_list()])
        tu = time_us(t)
        inn = np.array([bank.step(tu[k:k + 1], F64.arr(l[k:k + 1]), F64.arr(v[k:k + 1]),
                                  F64.arr(f[k:k + 1])).innovation[0] for k in range(len(t))])
        dwell = (l >= l.max() - 1e-9)
        pred = f - inn
        res[model] = (float(np.mean(pred[dwell]) / np.mean(f[dwell])),
                      {ph: float(np.sqrt(np.mean(inn[m] ** 2)) / 2e-3)
                       for ph, m in (("insertion", (v > 0) & (l > 0)), ("dwell", dwell),
                                     ("retraction", (v < 0) & (l > 0)))})
    print(f"\nModel II dwell prediction / force {res[2][0]:.3f}, innovation RMS / noise "
          f"{res[2][1]}\nModel III dwell prediction / force {res[3][0]:.3f}, innovation RMS / "
          f"noise {res[3][1]}")
    assert res[3][0] > 0.97 and res[2][0] < 0.9
    assert all(x < 3.0 for x in res[3][1].values())


def test_model3_on_a_phantom_record(tmp_path):
    """A measured-like record with relaxation and pre-sliding (`nte-ref phantom`, held-out seed
    101 of the default tissue; the air cut and the tare removed with its truth JSON): Model
    III's one-step innovations are below Model II's in the insertion and well below in the
    dwell and the retraction, and its prediction holds the dwell (Model II's collapses towards
    sigma0 z l)."""
    import json
    import subprocess
    import sys
    from pathlib import Path
    root = Path(__file__).resolve().parents[2]
    csv = tmp_path / "ph.csv"
    subprocess.run([sys.executable, "-m", "reference_py", "phantom", "--seed", "101", "--out",
                    str(csv)], cwd=root, check=True, capture_output=True)
    d = np.genfromtxt(csv, delimiter=",", names=True)
    truth = json.loads(csv.with_suffix(".truth.json").read_text())
    sensor, cycle = truth["spec"]["sensor"], truth["cycles"][0]
    t = d["t_s"]
    l = d["depth_mm"] * sensor["depth_sign"] - truth["surface_mm"]
    f = d["force_n"] * sensor["force_sign"] - sensor["offset_n"]
    v = d["velocity_mm_s"] * sensor["depth_sign"]
    k0 = max(0, int(np.argmax(l > 0)) - 20)
    t, l, f, v = t[k0:], l[k0:], f[k0:], v[k0:]
    phases = {"insertion": (l > 0) & (t <= cycle["insertion_end_s"]),
              "dwell": (t > cycle["insertion_end_s"]) & (t <= cycle["retraction_start_s"]),
              "retraction": (t > cycle["retraction_start_s"]) & (l > 0)}
    res = {}
    for model in (2, 3):
        bank = FilterBank(F64, default_config(model),
                          [get_preset("paper-10mms").params.as_list()])
        tu = time_us(t)
        inn = np.array([bank.step(tu[k:k + 1], F64.arr(l[k:k + 1]), F64.arr(v[k:k + 1]),
                                  F64.arr(f[k:k + 1])).innovation[0] for k in range(len(t))])
        rms = {ph: float(np.sqrt(np.mean(inn[m] ** 2)) / sensor["noise_n"])
               for ph, m in phases.items()}
        dw = phases["dwell"]
        res[model] = (rms, float(np.mean(f[dw] - inn[dw]) / np.mean(f[dw])))
    print(f"\nphantom seed 101, innovation RMS / noise: Model II {res[2][0]}, dwell prediction "
          f"{res[2][1]:.3f}; Model III {res[3][0]}, dwell prediction {res[3][1]:.3f}")
    # the insertion is dominated by the layers' ruptures, which Model III does not model
    assert res[3][0]["insertion"] < res[2][0]["insertion"]
    assert res[3][0]["dwell"] < 0.1 * res[2][0]["dwell"] and res[3][0]["dwell"] < 5.0
    assert res[3][0]["retraction"] < 0.6 * res[2][0]["retraction"]
    assert res[3][1] > 0.97
