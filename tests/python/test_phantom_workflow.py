"""The discrepancy workflow on realistic phantom records (multi-layer tissue, relaxation,
pre-sliding, sensor noise 8-50 mN), each trial on its own, against the phantom's ground truth.

Targets: relaxation named in >= 95 % of the trials with a dwell; the layer count right in >= 90 %;
the RMSE to the noise-free record shrinks >= 50 % from the base fit to the final model (median);
the final residual is <= 3x the sensor noise (median).  Where the workflow falls short, the test is
a strict xfail whose reason carries the measured figure.  Measured (this file, --runxfail):
relaxation named in 6/6, median shrink 0.81 (0.68 to 0.90), layers right 5/6, median final
residual 3.4x the noise (3.8x before the first band carried its own friction: lab-2006 29x -> 5.0x;
3.6x before the tears were placed between their samples: lab-2006 5.0x -> 4.7x; lab-2007
12x -> 7.6x with the relaxation's memory after a dwell, the median unchanged).

Trials: lab tissues of five seeds in 2001-2007 (drawn from the measured statistics; not used to
tune the phantom) and the four-layer preset at 30 mN; all have a 5.26 s dwell.  Six trials keep
the run within the CI budget.
"""
from __future__ import annotations

import numpy as np
import pytest

from reference_py.discrepancy import workflow
from reference_py.discrepancy.io import Trial
from reference_py.sim.calibration import LAB
from reference_py.sim.phantom import simulate_phantom

# lab seeds: noise 18, 19, 53, 15 and 8 mN; 2, 1, 1, 3 and 0 ruptures; 1-3 mm/s
CASES = [(LAB, s, {}) for s in (2001, 2002, 2004, 2006, 2007)] + [
    ("artery-filled", 4, {"noise_n": 0.03}),
]


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x * x)))


@pytest.fixture(scope="module")
def rows() -> list[dict[str, float]]:
    out = []
    for name, seed, kw in CASES:
        rec = simulate_phantom(name, seed=seed, **kw)
        assert rec.truth["cycles"][0]["retraction_start_s"] > rec.truth["cycles"][0][
            "insertion_end_s"] + 5.0                                   # the trial has a dwell
        trial = Trial(f"{name}-{seed}", rec.t_s, rec.depth_mm, rec.force_n, rec.velocity_mm_s)
        res = workflow.run([trial])
        prep = res.preps[0]
        assert np.array_equal(prep.t_s, rec.t_s)
        # the noise-free record: tissue force plus the sensor's offset and drift
        clean = rec.force_true_n + rec.spec.sensor.offset_n + rec.truth["samples"]["drift_n"]
        base, final = res.predictions[0][0], res.predictions[-1][0]
        out.append({"case": f"{name}-{seed}",
                    "relaxation": float("dwell_relaxation" in res.named),
                    "layers_found": float(res.layers[0]),     # ruptures the base switched at
                    "layers_true": float(rec.truth["ruptures_per_cycle"][0]),
                    "shrink": 1.0 - _rms(final - clean) / _rms(base - clean),
                    "resid_x_noise": _rms(rec.force_n - final) / rec.spec.sensor.noise_n})
    return out


def _summary(rows: list[dict[str, float]], key: str) -> str:
    return ", ".join(f"{r['case']}: {r[key]:.2f}" for r in rows)


def test_every_trial_ran_and_the_figures_are_finite(rows):
    assert len(rows) == len(CASES)
    for r in rows:
        assert all(np.isfinite(v) for k, v in r.items() if k != "case"), r


def test_relaxation_is_named_in_trials_with_a_dwell(rows):
    share = np.mean([r["relaxation"] for r in rows])
    assert share >= 0.95, f"relaxation named in {share:.0%}"


@pytest.mark.xfail(strict=True,
                   reason="measured: layer count right in 5/6 trials (target >= 90 %; "
                          "lab-2004 at 53 mN noise: 0 of 1 found)")
def test_layer_count_is_right(rows):
    share = np.mean([r["layers_found"] == r["layers_true"] for r in rows])
    found = ", ".join(f"{r['case']}: {r['layers_found']:.0f}/{r['layers_true']:.0f}" for r in rows)
    assert share >= 0.90, f"layer count right in {share:.0%} (found/true): {found}"


def test_rmse_to_the_noise_free_record_shrinks_by_half(rows):
    med = float(np.median([r["shrink"] for r in rows]))
    assert med >= 0.5, f"median shrink {med:.0%}: " + _summary(rows, "shrink")


@pytest.mark.xfail(strict=True,
                   reason="measured: median final residual 3.4x the noise (target <= 3x; "
                          "lab-2007 7.6x, 12x before the relaxation's memory after a dwell; "
                          "lab-2006 4.7x)")
def test_final_residual_is_within_three_times_the_noise(rows):
    med = float(np.median([r["resid_x_noise"] for r in rows]))
    assert med <= 3.0, f"median final residual {med:.1f}x noise: " + _summary(rows, "resid_x_noise")
