"""reference_py/discrepancy/shape.py: what a stretch of residual looks like, and the "unexplained"
verdict that says it.  The forms below are not the classifier's own (a drop through a tanh over
0.2 s, a triangle wave, a curved slope change, a Gaussian bump), each under noise."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from reference_py.discrepancy.prep import prepare
from reference_py.discrepancy.shape import classify, describe
from reference_py.discrepancy.unexplained import unexplained

sys.path.insert(0, str(Path(__file__).parent))
from discrepancy_measured_like import make_trial  # noqa: E402

T = np.arange(0.0, 4.0, 0.01)
NOISE = 0.02


def _with_noise(y: np.ndarray, seed: int) -> np.ndarray:
    return y + np.random.default_rng(seed).normal(0.0, NOISE, len(y))


@pytest.mark.parametrize("seed", range(4))
def test_a_smooth_drop_is_a_drop_where_it_happens(seed: int) -> None:
    sh = classify(T, _with_noise(-0.15 * (1 + np.tanh((T - 1.7) / 0.05)), seed))
    assert sh["shape"] == "drop"
    assert abs(float(sh["at_s"]) - 1.7) < 0.15
    assert abs(float(sh["size_n"]) + 0.30) < 0.04


@pytest.mark.parametrize("seed", range(4))
def test_a_step_up_is_a_rise(seed: int) -> None:
    sh = classify(T, _with_noise(np.where(T > 2.6, 0.12, 0.0), seed))
    assert sh["shape"] == "rise" and abs(float(sh["at_s"]) - 2.6) < 0.1


@pytest.mark.parametrize("seed", range(4))
def test_a_triangle_wave_is_an_oscillation_at_its_frequency(seed: int) -> None:
    tri = 0.2 * (2.0 * np.abs((T * 1.3) % 1.0 - 0.5) - 0.5)
    sh = classify(T, _with_noise(tri, seed))
    assert sh["shape"] == "oscillation"
    assert abs(float(sh["frequency_hz"]) - 1.3) < 0.1
    assert "Hz" in describe(sh, 5.0)


@pytest.mark.parametrize("seed", range(4))
def test_a_bending_residual_is_a_slope_change(seed: int) -> None:
    y = 0.25 * np.maximum(T - 1.2, 0.0) ** 1.2
    sh = classify(T, _with_noise(y, seed))
    assert sh["shape"] == "slope change"
    assert abs(float(sh["at_s"]) - 1.2) < 0.35 and float(sh["size_n"]) > 0


@pytest.mark.parametrize("seed", range(4))
def test_a_passing_dip_is_a_drop_that_comes_back(seed: int) -> None:
    sh = classify(T, _with_noise(-0.3 * np.exp(-((T - 2.0) / 0.25) ** 2), seed))
    assert sh["shape"] == "drop"
    assert float(sh["at_s"]) < 2.0 < float(sh["until_s"])
    assert ", back at " in describe(sh, 5.0)


def test_noise_alone_has_no_simple_shape() -> None:
    for seed in range(6):
        assert classify(T, _with_noise(np.zeros_like(T), 100 + seed))["shape"] == "no simple shape"


def test_the_verdict_says_the_largest_stretch_is_a_drop_and_where() -> None:
    # a model that knows every layer but one: the prediction keeps the deepest membrane's force
    # after it tore, so the data drop away from it there
    tr, truth, sigma, n_layers = make_trial(1203, n_layers=2, speed=1.5)
    p = prepare(tr)
    l = p.stage_mm - p.surface_mm
    k_tear = int(np.argmax(np.where(l > 0, truth - p.tare_n, -np.inf)[: int(np.argmax(l))]))
    missed = 1.0
    pred = truth.copy()
    after = (np.arange(len(pred)) > k_tear) & (p.v_mm_s > 0)
    pred[after] += missed
    where = unexplained([p], [pred])
    assert where, "a 1 N miss must be unexplained"
    w = where[0]
    assert w["looks_like"] == "drop"
    assert abs(float(w["size_n"]) + missed) < 0.25
    assert abs(float(w["at_s"]) - float(p.t_s[k_tear])) < 0.3
    assert abs(float(w["at_depth_mm"]) - float(l[k_tear])) < 0.5
    assert str(w["description"]).startswith("a drop of")
    # the miss lasts while the needle advances: the data come back to the model at the stop
    assert float(w["until_s"]) > float(w["at_s"])
