"""The fixed-point range report (nte-ref fixedpoint): Q-format rule, recording, a small fixed set."""
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from reference_py.bank import FilterBank
from reference_py.config import profile_config
from reference_py.fmath import F64
from reference_py.params import PRESETS
from reference_py.tools import fixedpoint as fp
from reference_py.sim.trajectory import TrajectorySpec

SHORT = TrajectorySpec(depth_mm=10.0, dwell_s=0.2)


def _range(values):
    r = fp.Range()
    r.add(np.asarray(values, dtype=float))
    return r


@pytest.mark.parametrize("values,I", [
    ([0.75, -0.5], 0),          # |x| < 1: Q0.31
    ([1.0], 1),                 # 1 needs an integer bit
    ([-50.0, 3.0], 6),          # |x| < 64
    ([0.03, 0.01], -5),         # |x| < 1/32
    ([3e-5], -15),
])
def test_q_format_integer_bits(values, I):
    got_I, F, fits = fp.q_format(_range(values), 12)
    assert (got_I, F) == (I, 31 - I)
    assert max(abs(v) for v in values) < 2.0 ** got_I
    assert max(abs(v) for v in values) >= 2.0 ** (got_I - 1)
    assert fits


def test_q_format_fits_by_significant_bits():
    # max 1 needs I = 1 (F = 30); p1 = 2^-18 keeps 30 - 18 = 12 significant bits: fits at 12,
    # not at 13
    r = _range([1.0] + [2.0 ** -18] * 10 + [0.5] * 89)
    assert r.small() == 2.0 ** -18
    assert fp.q_format(r, 12)[2]
    assert not fp.q_format(r, 13)[2]
    # exact zeros do not count, and a value below the 1st percentile does not either
    r = _range([1.0] + [0.0] * 1000 + [1e-30] + [0.5] * 200)
    assert r.small() == 0.5 and r.zeros == 1000
    assert fp.q_format(r, 12)[2]


def test_range_rejects_non_finite():
    with pytest.raises(ValueError, match="non-finite"):
        fp.Range().add(np.array([1.0, np.nan]))


def test_recording_does_not_change_the_bank():
    p = PRESETS["paper-10mms"]
    sc = fp.paper_scenarios(2, 2, SHORT)[0]
    cfg = replace(profile_config("default", 2), beta0=p.params.beta)
    plain = FilterBank(F64, cfg, sc.starts)
    rec = fp.RecordingBank(F64, cfg, sc.starts, ranges={})
    from reference_py.sim.trajectory import lspb_profile
    t, l, v, _ = lspb_profile(sc.spec)
    rng = np.random.default_rng(3)
    for k in range(0, len(t)):
        y = np.full(3, 0.01 * l[k]) + rng.normal(0.0, 2e-3, 3)
        a = plain.step(np.full(3, int(t[k] * 1e6)), np.full(3, l[k]), np.full(3, v[k]), y)
        b = rec.step(np.full(3, int(t[k] * 1e6)), np.full(3, l[k]), np.full(3, v[k]), y)
        assert np.array_equal(a.force_hat, b.force_hat) and np.array_equal(a.params, b.params)
    assert rec.ranges["z"].count > 0


@pytest.fixture(scope="module")
def small_set():
    """Model II over a fixed small set: one paper preset and one random tissue, short moves."""
    paper = fp.paper_scenarios(2, 2, SHORT)[:1]
    rand = [replace(s, spec=replace(SHORT, speed_mm_s=3.0))
            for s in fp.random_scenarios(2, 1, 2, seed=4)]
    return fp.collect(2, paper + rand)


def test_small_set_covers_every_variable(small_set):
    names = set(small_set)
    for want in ("z", "u.sigma0", "u.beta", "theta.sigma1", "g", "1/g", "h (force)",
                 "rk3 dz/dz0", "rk3 dz/du.beta", "H[z]", "H[u.f1]", "P1 predicted [z,z]",
                 "P2 updated [f1,sigma1]", "P3 updated [sigma2,sigma2]", "K1[sigma0]", "K3[z]",
                 "innovation2", "S3 = H P H' + R", "gate2 y^2", "gate3 gate^2 S", "NIS1",
                 "input force_n"):
        assert want in names, want
    assert all(r.count > 0 for r in small_set.values())


def test_small_set_ranges_are_physical(small_set):
    r = small_set
    cfg = profile_config("default", 2)
    assert 0.0 < r["e = exp(-alpha l)"].lo and r["e = exp(-alpha l)"].hi <= 1.0
    assert r["g"].lo > 0.0 and r["1/g"].lo > 0.0
    for name, rg in r.items():
        if name.startswith("u."):
            assert rg.max_abs() <= cfg.u_max, name
        if name.startswith("P") and "[z,z]" in name:
            assert rg.lo >= cfg.var_floor_z * (1 - 1e-12), name
        if name.startswith("S"):
            assert rg.lo >= cfg.r_n2 * (1 - 1e-12), name
        if name.startswith("NIS"):
            assert rg.lo >= 0.0, name


def test_small_set_table(small_set):
    lines, misfits, published = fp.format_table(small_set, 12)
    rows = {ln.split(" | ")[0][2:]: ln for ln in lines[2:]}
    assert set(rows) == set(small_set)
    # the log-parameters are O(1) by construction (|u| <= u_max = 3.9): at most Q2.29
    for name in ("u.sigma0", "u.sigma1", "u.sigma2", "u.f1", "u.beta"):
        I, F = (int(x) for x in rows[name].split(" | ")[4][1:].split("."))
        assert I <= 2 and I + F == 31, rows[name]
        assert name not in misfits
    # misfits are exactly the rows marked no; the NIS is published only, never a misfit
    assert misfits == [n for n, ln in rows.items() if ln.endswith("**no** |")]
    assert published == [n for n, ln in rows.items() if ln.endswith("no (published only) |")]
    assert not any(n.startswith("NIS") for n in misfits)
    # the gate's comparison fits where y^2 alone would not (its values near 0 need no bits)
    for i in (1, 2, 3):
        assert rows[f"gate{i} y^2"].endswith("yes (as the gate's comparison) |")
        assert not fp.q_format(small_set[f"gate{i} y^2"], 12)[2]
    # asking for more significant bits can only add misfits
    more = fp.format_table(small_set, 24)[1]
    assert set(misfits) <= set(more) and len(more) > len(misfits)


def test_gate_comparison_is_judged_on_its_threshold():
    """y^2 <= gate2 S in one format: it fits when the threshold keeps its significant bits,
    however small y^2 gets; a threshold too small for the larger side's format does not."""
    y2 = _range([1e-14, 1e-9, 0.06] * 40)
    thr = _range([5e-4, 9.0] * 60)
    I, F, fits = fp.gate_format(y2, thr, 12)
    assert (I, F) == (4, 27) and fits
    tiny = _range([1e-7, 9.0] * 60)   # 1e-7 is 13 steps of Q4.27: 4 bits, not 12
    assert not fp.gate_format(y2, tiny, 12)[2]


def test_cli_rejects_bad_flags():
    res = subprocess.run([sys.executable, "-m", "reference_py", "fixedpoint", "--seeds", "0"],
                         capture_output=True, text=True)
    assert res.returncode == 2
    assert res.stderr.strip() == "nte-ref: error: --seeds must be >= 1 (got 0)"
    assert "Traceback" not in res.stderr


def test_z_carrying_sensitivities_are_recorded_over_z():
    """The scaled forms are the raw sensitivities over the prior z, recorded from the same
    filter and sample: raw == z * scaled wherever z != 0, 0 where z is 0; sigma0's output
    sensitivity over z is H[z] itself."""
    seen = []

    class Capture(fp.RecordingBank):
        def _measure(self, names, d, zp, s, s_du, v, y, active):
            res = super()._measure(names, d, zp, s, s_du, v, y, active)
            seen.append({k: np.array(v) for k, v in self._pending.items()
                         if k in ("z prior", "H[z]") or k in fp.SCALED_FORMS
                         or k in fp.SCALED_FORMS.values()})
            return res

    p = PRESETS["paper-6mms"]
    sc = fp.paper_scenarios(2, 1, SHORT)[1]
    assert sc.label == "paper paper-6mms"
    cfg = replace(profile_config("default", 2), beta0=p.params.beta)
    rec = Capture(F64, cfg, sc.starts, ranges={})
    from reference_py.sim.trajectory import lspb_profile
    t, l, v, _ = lspb_profile(sc.spec)
    for k in range(0, len(t), 4):
        y = np.full(2, 0.01 * l[k])
        rec.step(np.full(2, int(t[k] * 1e6)), np.full(2, l[k]), np.full(2, v[k]), y)
    checked = dict.fromkeys(fp.SCALED_FORMS, 0)
    for got in seen:
        z = np.broadcast_to(got["z prior"], (2,))
        nz = z != 0.0
        for raw, scaled in fp.SCALED_FORMS.items():
            if raw not in got:
                continue          # another filter's sample
            a = np.broadcast_to(got[raw], (2,))
            b = np.broadcast_to(got[scaled], (2,))
            assert np.allclose(z[nz] * b[nz], a[nz], rtol=1e-12, atol=0.0), raw
            assert np.all(b[~nz] == 0.0)
            checked[raw] += int(nz.sum())
        if "H[u.sigma0] / z" in got:
            # sigma0's output sensitivity is z times z's own: both are
            # sigma0 (l - s l sigma1 e / g) (model.output_dz, output_du)
            b = np.broadcast_to(got["H[u.sigma0] / z"], (2,))
            hz = np.broadcast_to(got["H[z]"], (2,))
            assert np.allclose(b[nz], hz[nz], rtol=1e-12, atol=1e-15)
    # sigma0's (filter 1) and f1's (filter 2), each on many samples inside the tissue
    assert all(n > 20 for n in checked.values()), checked


def test_sensitivities_held_scaled_fit(small_set):
    """f1's raw sensitivities miss 12 significant bits near the surface; over z they keep them,
    and the table reports the raw ones as held in the scaled form, not as misfits."""
    lines, misfits, _ = fp.format_table(small_set, 12)
    rows = {ln.split(" | ")[0][2:]: ln for ln in lines[2:]}
    for raw in ("rk3 dz/du.f1", "H[u.f1]"):
        assert not fp.q_format(small_set[raw], 12)[2], raw
    for raw, scaled in fp.SCALED_FORMS.items():
        assert fp.q_format(small_set[scaled], 12)[2], scaled
        if fp.q_format(small_set[raw], 12)[2]:
            assert rows[raw].endswith(" | yes |"), raw
        else:
            assert rows[raw].endswith(f"as `{scaled}` (times z) |"), raw
        assert raw not in misfits and scaled not in misfits
    # a scaled form that does not fit either leaves the raw variable a misfit
    spoiled = dict(small_set)
    spoiled["H[u.f1] / z"] = _range([1e-9, 5.0] * 60)
    _, spoiled_misfits, _ = fp.format_table(spoiled, 12)
    assert "H[u.f1]" in spoiled_misfits and "H[u.f1] / z" in spoiled_misfits


def test_log_parameters_are_judged_by_their_step():
    """u's error is theta's relative error: a log-parameter fits when its format's step is at
    most 2^-sig_bits, however close to 0 it wanders; a format with fewer fraction bits does
    not."""
    wanders = _range([2.39, -1.3] + [3e-7] * 50 + list(np.linspace(-1.0, 1.0, 40)))
    assert not fp.q_format(wanders, 12)[2]          # judged by its small values it would not
    assert fp.log_parameter_format(wanders, 12) == (2, 29, True)
    assert fp.log_parameter_format(wanders, 29)[2] and not fp.log_parameter_format(wanders, 30)[2]
    lines, misfits, _ = fp.format_table({"u.f1": wanders}, 12)
    assert lines[2].endswith("yes (as θ's relative error) |") and misfits == []
