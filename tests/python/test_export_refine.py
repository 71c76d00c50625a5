"""The export's fit (reference_py/tools/export_refine.py; C twin firmware/host/export_refine.c).

* its linear algebra against numpy's (the fit writes its own so that C and numpy add in the
  same order; numpy is the judge of the result);
* the rules that keep a fitted file readable;
* on a record the model can describe exactly (tests/python/model3_truth.py: Model III's own
  equations with known values, not the phantom the export was developed on) the fit started
  from values 30-40 % off brings the replay down to the noise.

C ≡ reference for the whole export (fit included) is test_export_twins.py; the export's choice
and figures are test_config_loop.py::test_export_keeps_the_snapshot_that_replays_best_and_fits_it.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from reference_py.config import default_config
from reference_py.params import PARAM_NAMES, get_preset
from reference_py.tools.csvio import Trial
from reference_py.tools.export_refine import (STRENGTH_MAX, cholesky, cholesky_solve, readable,
                                              refine)
from reference_py.tools.export_replay import replay


@pytest.mark.parametrize("n", [1, 2, 5, 9])
def test_cholesky_solve_matches_numpy(n):
    rng = np.random.default_rng(n)
    B = rng.normal(size=(n, n))
    M = B @ B.T + 0.1 * np.eye(n)
    b = rng.normal(size=n)
    L = cholesky(M.tolist())
    assert L is not None
    assert np.allclose(np.array(L) @ np.array(L).T, M, rtol=1e-12, atol=1e-12)
    x = cholesky_solve(L, b.tolist())
    assert np.allclose(x, np.linalg.solve(M, b), rtol=1e-9, atol=1e-12)


def test_cholesky_refuses_what_is_not_positive_definite():
    assert cholesky([[1.0, 2.0], [2.0, 1.0]]) is None
    assert cholesky([[0.0]]) is None
    assert cholesky([[float("nan")]]) is None


def test_readable_keeps_what_a_reader_accepts():
    p = get_preset("paper-10mms").params.as_list()          # f2 < 0
    f1, f2 = PARAM_NAMES.index("f1"), PARAM_NAMES.index("f2")
    row = list(p) + [0.8, 0.5]
    row[PARAM_NAMES.index("sigma1")] = 5000.0
    row[f1] = 0.5 * -row[f2]                                 # g(0) = f1 + f2 < 0
    out = readable(row)
    assert out[PARAM_NAMES.index("sigma1")] == 1000.0
    assert out[f1] + out[f2] > 0
    assert sum(out[7:]) <= STRENGTH_MAX and out[7] / out[8] == pytest.approx(0.8 / 0.5)
    assert readable(out) == out                              # a readable row stays as it is


def _truth_trial() -> tuple[Trial, np.ndarray]:
    from model3_truth import model3_record
    rows = [ln.split(",") for ln in model3_record(noise=2e-3, seed=5)[1:]]
    t, l, v, f, ft = (np.array([float(r[i]) for r in rows]) for i in range(5))
    return Trial("m3truth.csv", t, l, f, v, True, {}), ft


def test_fit_brings_the_replay_to_the_noise_on_the_models_own_record():
    """Model III's truth (paper-10mms values, strengths 0.15/0.2, tau 0.3/3 s, delta 1.5 mm,
    noise 2 mN): from every identified value 30-40 % off, the replay misses by many times the
    noise; the fit ends within 1.5x the noise, its sd is finite and positive for every fitted
    value, and never makes the replay worse than its start."""
    trial, truth = _truth_trial()
    cfg = replace(default_config(3), r_n2=4e-6, tau_fast_s=0.3, tau_slow_s=3.0,
                  presliding_mm=1.5)
    names = ("sigma0", "sigma1", "sigma2", "f1", "beta", "g_fast", "g_slow")
    true_row = get_preset("paper-10mms").params.as_list() + [0.15, 0.2]
    start = list(true_row)
    for k, j in enumerate([0, 1, 2, 3, 6, 7, 8]):
        start[j] = true_row[j] * (1.4 if k % 2 == 0 else 0.7)
    before = replay(cfg, "float64", trial, [start], math.nan, 0.0)
    rmse0 = float(np.sqrt(np.mean(before.residuals[0] ** 2)))
    fit = refine(cfg, "float64", trial, start, names, math.nan, 0.0)
    assert rmse0 > 10 * 2e-3
    assert fit.rmse_n <= 1.5 * 2e-3 and fit.rmse_n <= rmse0
    assert 2 <= fit.passes <= 20
    assert sorted(fit.sd) == [0, 1, 2, 3, 6, 7, 8]
    assert all(math.isfinite(s) and s > 0 for s in fit.sd.values())
    # the fitted row replays to the reported RMSE exactly
    after = replay(cfg, "float64", trial, [fit.row], math.nan, 0.0)
    assert math.sqrt(float(np.add.accumulate(after.residuals[0] ** 2)[-1]) /
                     after.residuals.shape[1]) == fit.rmse_n
