"""Stable numerics on plausible input: the 25 Hz insertion that once diverged, reference and C.

* The reproducer (nte-ref simulate --preset needleB-tissueB-10mms --depth 120 --dwell 1
  --speed 40 --rate 25 --accel 10000 --seed 12, then estimate --model 1): every output finite,
  |force_hat| within 10x the input's largest force (it once reached 6.6e4 N), reference and C
  at 0 ULP in float and double.
* The range bound on the same input with the exponential step switched off (Kutta's RK3 on every
  sub-step, the integrator that diverged): the divergence is caught, flagged DIVERGED, and
  nothing out of +-force_max_n is published.
"""
from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))

from c_twin import EXE, ulp_distance  # noqa: E402

from reference_py import bank as B  # noqa: E402
from reference_py import rk3  # noqa: E402
from reference_py.bank import STATUS_DIVERGED  # noqa: E402
from reference_py.config import default_config  # noqa: E402
from reference_py.params import get_preset  # noqa: E402
from reference_py.tools.csvio import read_trial  # noqa: E402
from reference_py.tools.estimate import estimate_csv_lines, run_estimate  # noqa: E402

REPRO = ["--preset", "needleB-tissueB-10mms", "--depth", "120", "--dwell", "1", "--speed", "40",
         "--rate", "25", "--accel", "10000", "--seed", "12"]
FORCE_MAX_N = default_config(1).force_max_n


@pytest.fixture(scope="module")
def repro_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("repro") / "x.csv"
    subprocess.run([sys.executable, "-m", "reference_py", "simulate", *REPRO, "--out", str(out)],
                   check=True, capture_output=True, cwd=ROOT)
    return out


@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_reproducer_finite_in_range_and_c_identical(repro_csv: Path, tmp_path: Path,
                                                    precision: str) -> None:
    trial = read_trial(repro_csv)
    peak_in = float(np.max(np.abs(trial.force_n)))
    run = run_estimate(trial, get_preset("paper-10mms"), 1, precision=precision)
    f = np.asarray(run.force_hat_n, dtype=np.float64)
    assert np.all(np.isfinite(f)) and np.all(np.isfinite(np.asarray(run.z, dtype=np.float64)))
    assert np.all(np.isfinite(np.asarray(run.innovation_n, dtype=np.float64)))
    # the input peaks at 0.24 N; the estimate once reached 6.6e4 N
    assert float(np.max(np.abs(f))) <= 10.0 * peak_in
    assert float(np.max(np.abs(f))) <= 2.0 * peak_in
    if not EXE[precision].exists():
        pytest.skip(f"{EXE[precision]} not built (make build)")
    out = tmp_path / "c.csv"
    subprocess.run([str(EXE[precision]), str(repro_csv), "--model", "1", "--out", str(out)],
                   check=True, capture_output=True)
    c_lines = out.read_text().split("\n")[:-1]
    assert ulp_distance(estimate_csv_lines(run), c_lines, precision) == 0


@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_range_bound_catches_the_rk3_divergence(repro_csv: Path, precision: str,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """With Kutta's RK3 on every sub-step (the integrator that diverged) the bound resets the
    filters, flags DIVERGED, and publishes nothing outside +-force_max_n."""
    monkeypatch.setattr(rk3, "EXP_BOUND", math.inf)
    run = run_estimate(read_trial(repro_csv), get_preset("paper-10mms"), 1, precision=precision)
    f = np.asarray(run.force_hat_n, dtype=np.float64)
    flagged = (np.asarray(run.status) & np.uint32(STATUS_DIVERGED)) != 0
    assert np.all(np.isfinite(f)) and np.all(np.isfinite(np.asarray(run.z, dtype=np.float64)))
    assert np.all(np.abs(f) <= FORCE_MAX_N)
    assert int(flagged.sum()) >= 1
    # without the bound this run's force leaves the range (6.6e4 N once): the flags mark it
    assert float(np.max(np.abs(f[~flagged]))) <= FORCE_MAX_N


# --- the property on a fixed subset of random plausible scenarios, reference and C ---------
from reference_py.tools.estimate import EstimateRun  # noqa: E402
from reference_py.tools.plausible import BOUND, csv_lines, draw, outcome  # noqa: E402

#: seeds of nte-ref plausible's scenarios, drawn with at most CI_CAP samples (the long run
#: allows 6 000); together they cover both models, precisions and estimators, 20 Hz and
#: > 500 Hz, irregular time, a depth jump, saturation and an inverted force sign
SUBSET = (65, 1, 70, 112, 2, 3)
CI_CAP = 400


def _features(seed: int) -> set[str]:
    sc = draw(seed, CI_CAP)
    out = {f"model {sc.model}", sc.precision, sc.estimator}
    for name, present in (("irregular", sc.irregular), ("jump", sc.jump_mm != 0.0),
                          ("saturated", sc.saturation > 0.0), ("inverted", sc.inverted),
                          ("20 Hz", sc.rate_hz < 21.0), ("> 500 Hz", sc.rate_hz > 500.0)):
        if present:
            out.add(name)
    return out


def test_subset_covers_every_kind() -> None:
    seen = set().union(*(_features(s) for s in SUBSET))
    assert seen >= {"model 1", "model 2", "float32", "float64", "bank", "robust", "irregular",
                    "jump", "saturated", "inverted", "20 Hz", "> 500 Hz"}, seen


def _check(sc, force_in: np.ndarray, run: EstimateRun) -> None:
    o = outcome(sc, force_in, np.asarray(run.force_hat_n, np.float64),
                np.asarray(run.z, np.float64), np.asarray(run.innovation_n, np.float64),
                np.asarray(run.status))
    assert o.ok, (sc, o)


@pytest.mark.parametrize("seed", SUBSET)
def test_plausible_scenario_reference_and_c(seed: int, tmp_path: Path) -> None:
    sc = draw(seed, CI_CAP)
    src = tmp_path / "in.csv"
    src.write_text("\n".join(csv_lines(sc)) + "\n")
    trial = read_trial(src)
    assert len(trial.t_s) <= 2 * CI_CAP  # the cap leaves out the rests at the surface
    force_in = np.asarray(trial.force_n, dtype=np.float64)
    run = run_estimate(trial, get_preset(sc.preset), sc.model, estimator=sc.estimator,
                       precision=sc.precision, init_seed=sc.init_seed,
                       init_factor=sc.init_factor)
    _check(sc, force_in, run)
    exe = EXE[sc.precision]
    if not exe.exists():
        pytest.skip(f"{exe} not built (make build)")
    out = tmp_path / "c.csv"
    subprocess.run([str(exe), str(src), *sc.estimator_args(), "--out", str(out)], check=True,
                   capture_output=True)
    assert ulp_distance(estimate_csv_lines(run), out.read_text().split("\n")[:-1],
                        sc.precision) == 0


#: a scenario whose model cannot follow its data (Model II, float32, a start 4.2x off, the
#: force recorded with the opposite sign): before the data's bound (bank.DATA_BOUND) the bank
#: published 69.7x the largest force it was given
UNFOLLOWABLE = 101


def test_the_data_bound_holds_where_the_model_cannot_follow(tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch
                                                            ) -> None:
    sc = draw(UNFOLLOWABLE)
    assert sc.inverted and sc.model == 2 and sc.estimator == "bank", sc
    src = tmp_path / "in.csv"
    src.write_text("\n".join(csv_lines(sc)) + "\n")
    trial = read_trial(src)
    force_in = np.asarray(trial.force_n, dtype=np.float64)

    def estimate() -> EstimateRun:
        return run_estimate(trial, get_preset(sc.preset), sc.model, estimator=sc.estimator,
                            precision=sc.precision, init_seed=sc.init_seed,
                            init_factor=sc.init_factor)

    run = estimate()
    _check(sc, force_in, run)
    # every published force within DATA_BOUND x the largest |force| accepted so far in the
    # insertion (the record's depth never returns to 0 before its end), the noise sd at least
    seen = np.maximum.accumulate(np.abs(force_in))
    noise_sd = float(np.sqrt(np.float32(run.config.r_n2)))
    limit = B.DATA_BOUND * np.maximum(seen, noise_sd)
    hat = np.abs(np.asarray(run.force_hat_n, np.float64))
    assert np.all(hat <= limit * (1 + 1e-6)), float(np.max(hat / limit))
    limited = (np.asarray(run.status) & B.STATUS_DIVERGED) != 0
    assert 0 < np.count_nonzero(limited) < len(hat) // 10
    # without the bound the same run publishes far beyond it: the test needs the bound
    monkeypatch.setattr(B, "DATA_BOUND", 1.0e9)
    unbounded = estimate()
    o = outcome(sc, force_in, np.asarray(unbounded.force_hat_n, np.float64),
                np.asarray(unbounded.z, np.float64), np.asarray(unbounded.innovation_n,
                                                                np.float64),
                np.asarray(unbounded.status))
    assert o.ratio > 5 * BOUND, o
    monkeypatch.undo()
    exe = EXE[sc.precision]
    if not exe.exists():
        pytest.skip(f"{exe} not built (make build)")
    out = tmp_path / "c.csv"
    subprocess.run([str(exe), str(src), *sc.estimator_args(), "--out", str(out)], check=True,
                   capture_output=True)
    assert ulp_distance(estimate_csv_lines(run), out.read_text().split("\n")[:-1],
                        sc.precision) == 0


def test_command_runs_and_refuses_bad_counts() -> None:
    ok = subprocess.run([sys.executable, "-m", "reference_py", "plausible", "--scenarios", "3",
                         "--first-seed", "112"], capture_output=True, text=True, cwd=ROOT)
    if ok.returncode == 2 and "--c-bin" in ok.stderr:
        pytest.skip("C host programs not built (make build)")
    assert ok.returncode == 0, ok.stderr
    assert "scenarios 3 (seeds 112..114)" in ok.stdout
    assert "violations 0 (non-finite 0" in ok.stdout
    bad = subprocess.run([sys.executable, "-m", "reference_py", "plausible", "--scenarios", "0"],
                         capture_output=True, text=True, cwd=ROOT)
    assert bad.returncode == 2
    assert bad.stderr.strip() == "nte-ref: error: --scenarios must be in 1..1000000 (got 0)"
