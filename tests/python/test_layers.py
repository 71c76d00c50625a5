"""Model III's layer index (reference_py/layers.py, firmware/src/nte_layers.c).

* the detector's rules on hand-made samples: a drop fires, the hold-off and the direction
  silence it, the index saturates and returns to 0 out of the tissue;
* on phantom records drawn otherwise than the three it was tuned on (skin-on-muscle seeds
  101-103): `lab` tissues (random layers, 0-3 ruptures) and the other presets, the published
  index equals the number of ruptures so far 0.3 s after >= 90 % of the ruptures, with at most
  one false alarm per five records;
* C = reference at 0 ULP with the layer column, float32 and float64; --no-layers drops the
  column and changes nothing else (the detector watches, it does not steer).
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from reference_py.fmath import F32, F64  # noqa: E402
from reference_py import layers  # noqa: E402
from reference_py.layers import (HOLDOFF_MM, LAYER_MAX, THRESHOLD_SIGMA,  # noqa: E402
                                 RuptureDetector)

VENV_BIN = Path(sys.executable).parent
C64 = ROOT / "build" / "host" / "bin" / "nte-run-double"
C32 = ROOT / "build" / "host" / "bin" / "nte-run"
#: records the constants were not chosen on
HELD_OUT = [("lab", s) for s in range(201, 211)] + [
    (p, s) for p in ("skin", "muscle", "artery-filled", "skin-incision", "skin-on-muscle")
    for s in (111, 112)]


def _one(det: RuptureDetector, R, depth: float, v: float, sigmas: float, valid: bool = True,
         run: bool = True) -> tuple[int, bool, bool]:
    """One sample with an innovation of `sigmas` noise standard deviations (noise 1 mN): the
    layer index, a rupture, a drop inside the hold-off."""
    arr = lambda x: R.arr([x])  # noqa: E731
    layer, rupture, drop = det.step(np.array([valid]), np.array([run]), arr(depth), arr(v),
                                    arr(sigmas * 1e-3), arr(1e-3))
    return int(layer[0]), bool(rupture[0]), bool(drop[0])


@pytest.mark.parametrize("R", [F32, F64], ids=["float32", "float64"])
def test_the_detector_rules(R):
    det = RuptureDetector(R, 1, 1e-3)
    # a drop of threshold + drift + 1 sigma in one sample, inserting below the hold-off: fires
    assert _one(det, R, 3.0, 2.0, -(THRESHOLD_SIGMA + 2.0)) == (1, True, False)
    # within the hold-off below that rupture: no new layer however large; a drop past the
    # alarm in one sample is a tear of the same layer, one short of it nothing, nor does
    # either accumulate or move the hold-off's origin
    assert _one(det, R, 3.5, 2.0, -(THRESHOLD_SIGMA + 0.5)) == (1, False, False)
    assert _one(det, R, 3.6, 2.0, -(THRESHOLD_SIGMA + 0.5)) == (1, False, False)
    assert _one(det, R, 3.0 + HOLDOFF_MM - 0.1, 2.0, -1000.0) == (1, False, True)
    assert _one(det, R, 3.0 + HOLDOFF_MM + 0.1, 2.0, -(THRESHOLD_SIGMA + 2.0)) == (2, True, False)
    # a slow drop accumulates: 5 sigma per sample for ceil(20 / 4) + 1 samples
    fired = [_one(det, R, 7.0 + 0.01 * k, 2.0, -5.0)[1] for k in range(6)]
    assert fired == [False] * 5 + [True]
    # moving out, or standing: silent, in the hold-off too
    assert _one(det, R, 10.0, -2.0, -1000.0) == (3, False, False)
    assert _one(det, R, 10.0, 0.0, -1000.0) == (3, False, False)
    assert _one(det, R, 7.1, 0.0, -1000.0) == (3, False, False)
    # a rejected sample changes nothing; the first sample after init is not judged
    assert _one(det, R, 12.0, 2.0, -1000.0, valid=False) == (3, False, False)
    assert _one(det, R, 12.0, 2.0, -1000.0, run=False) == (3, False, False)
    # positive innovations only drain the CUSUM
    assert _one(det, R, 12.0, 2.0, 1000.0) == (3, False, False)
    # saturates at LAYER_MAX - 1
    for k in range(LAYER_MAX + 2):
        _one(det, R, 20.0 + 2.0 * k, 2.0, -1000.0)
    assert _one(det, R, 40.0, 2.0, 0.0)[0] == LAYER_MAX - 1
    # out of the tissue: back to layer 0, the surface is the next hold-off's origin
    assert _one(det, R, 0.0, -2.0, 0.0) == (0, False, False)
    assert _one(det, R, HOLDOFF_MM - 0.1, 2.0, -1000.0) == (0, False, True)
    assert _one(det, R, HOLDOFF_MM + 0.1, 2.0, -1000.0) == (1, True, False)


def _phantom(d: Path, preset: str, seed: int) -> tuple[Path, dict]:
    f = d / f"{preset}_{seed}.csv"
    subprocess.run([str(VENV_BIN / "nte-ref"), "phantom", preset, "--seed", str(seed),
                    "--out", str(f)], check=True, capture_output=True, cwd=ROOT)
    return f, json.loads(f.with_suffix(".truth.json").read_text())


def _run(exe: Path, *args: str) -> None:
    r = subprocess.run([str(exe), *args], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


@pytest.fixture(scope="module")
def held_out(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """Over HELD_OUT, records as recorded (air gap, tare: the contact front end finds the
    surface): ruptures, those with an alarm within 0.3 s after them (found), alarms not within
    0.3 s after a rupture (false), and the ruptures 0.3 s after which the published index
    equals the ruptures so far in that insertion, capped at LAYER_MAX - 1 (right: a miss or
    a false alarm also makes the later ones of the insertion wrong)."""
    if not C64.exists():
        pytest.skip("build/host missing: make build")
    d = tmp_path_factory.mktemp("layers")
    res = {"total": 0, "found": 0, "false": 0, "right": 0, "lines": []}
    for preset, seed in HELD_OUT:
        rec, truth = _phantom(d, preset, seed)
        est = d / "est.csv"
        _run(C64, str(rec), "--model", "3", "--out", str(est))
        e = np.genfromtxt(est, delimiter=",", names=True)
        t, layer, status = e["t_s"], e["layer"].astype(int), e["status"].astype(int)
        alarms = t[(status & (1 << 12)) != 0]
        times = [r["time_s"] for r in truth["ruptures"]]
        per_cycle: dict[int, int] = {}
        for r in truth["ruptures"]:
            per_cycle[r["cycle"]] = per_cycle.get(r["cycle"], 0) + 1
            k = min(int(np.searchsorted(t, r["time_s"] + 0.3)), len(t) - 1)
            res["right"] += int(layer[k] == min(per_cycle[r["cycle"]], LAYER_MAX - 1))
        res["total"] += len(times)
        res["found"] += sum(1 for x in times if any(0.0 <= a - x <= 0.3 for a in alarms))
        res["false"] += sum(1 for a in alarms if not any(0.0 <= a - x <= 0.3 for x in times))
        res["lines"].append(f"{preset}:{seed} ruptures {len(times)} alarms {len(alarms)}")
    print(f"\nheld-out phantom records ({len(HELD_OUT)}): {res['found']} of {res['total']} "
          f"ruptures found within 0.3 s, {res['false']} false alarms, layer index right after "
          f"{res['right']}\n" + "\n".join(res["lines"]))
    return res


def test_ruptures_found_on_held_out_phantom_records(held_out):
    """At least 85 % of the ruptures found within 0.3 s, at most one false alarm per five
    records (measured: 30 of 31, 1 in 20, on skin-incision 111, which has no membrane; 31 of 31
    before a drop inside the hold-off was a tear of the same layer (artery-filled 112's fourth
    tore 1.48 mm below the third's alarm), 30 of 31 before the tear's rescale, 0 false alarms
    while the step bound left z's change whole, 2 before the step bound)."""
    assert held_out["total"] >= 20
    assert held_out["found"] >= 0.85 * held_out["total"]
    assert held_out["false"] <= len(HELD_OUT) / 5


def test_layer_index_right_after_90_percent_of_ruptures(held_out):
    """Measured: 31 of 31 (27 of 31 while Model III's gate held out for ten samples: the
    filter stayed at the old force through a tear, and the next tear looked small)."""
    assert held_out["right"] >= 0.9 * held_out["total"]


#: the identified parameters' columns of a Model III file (their _sd columns aside)
PARAM_COLUMNS = ("sigma0", "sigma1", "sigma2", "f1", "beta", "g_fast", "g_slow", "delta")


@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_c_equals_reference_and_a_tear_rescales_the_model(tmp_path, precision):
    """C is the reference bit for bit through the tears (ruptures, and drops inside the
    hold-off: a tear's second sample); without the layers the file is the same up to the
    first rupture.  At a tear's sample no parameter moves along the gain (the
    tear updates z alone, its gate open); a drop rescales beta and sigma2 by one ratio below 1
    (layers.tear_rescale), so that the published force is the measured one after the drop,
    and the estimates differ after it (the covariances restarted)."""
    rec, _ = _phantom(tmp_path, "lab", 204)          # three ruptures
    if not C64.exists():
        pytest.skip("build/host missing: make build")
    r_out, c_out = tmp_path / "r.csv", tmp_path / "c.csv"
    r = subprocess.run([str(VENV_BIN / "nte-ref"), "estimate", str(rec), "--model", "3",
                        "--precision", precision, "--out", str(r_out)], capture_output=True,
                       text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    _run(C64 if precision == "float64" else C32, str(rec), "--model", "3", "--out", str(c_out))
    assert r_out.read_bytes() == c_out.read_bytes()
    e = np.genfromtxt(c_out, delimiter=",", names=True)
    status = e["status"].astype(int)
    ruptures = np.flatnonzero(status & (1 << 12))
    drops = np.flatnonzero(status & (1 << 16))      # a tear's second sample, in the hold-off
    assert e["layer"].max() == 3 and len(ruptures) == 3 and len(drops) >= 2
    assert np.all(e["layer"][drops] == e["layer"][drops - 1]), "a drop is not a new layer"
    tears = np.union1d(ruptures, drops)
    assert not np.any(status[tears] & (1 << 2)), "a tear's sample is never gated"
    n_out = tmp_path / "n.csv"
    _run(C64 if precision == "float64" else C32, str(rec), "--model", "3", "--no-layers",
         "--out", str(n_out))
    without = np.genfromtxt(n_out, delimiter=",", names=True)
    assert "layer" not in without.dtype.names
    k = tears[0]
    params = [n for n in without.dtype.names if n in PARAM_COLUMNS]
    assert len(params) == 8
    for name in without.dtype.names:
        a, b = e[name][:k], without[name][:k]
        assert np.array_equal(a, b, equal_nan=True), name
    rel = 1e-12 if precision == "float64" else 2e-6
    for k in tears:
        for name in params:
            if name not in ("beta", "sigma2"):
                assert e[name][k] == e[name][k - 1], f"{name} moved at the tear {k}"
        ratio = e["beta"][k] / e["beta"][k - 1]
        assert layers.TEAR_RATIO_MIN <= ratio <= 1.0
        assert e["sigma2"][k] / e["sigma2"][k - 1] == pytest.approx(ratio, rel=rel * 10)
    # the lab tissue's tears drop the force: the rupture's sample and the drop after it are
    # each rescaled, onto the measured force
    force = np.genfromtxt(rec, delimiter=",", names=True)["force_n"]
    for k in (ruptures[0], drops[0]):
        assert e["beta"][k] < 0.9 * e["beta"][k - 1]
        measured = force[k] - e["tare_n"][k]
        assert e["force_hat_n"][k] == pytest.approx(measured, rel=100 * rel, abs=1e-6)
    assert not np.array_equal(e["force_hat_n"][k + 1:], without["force_hat_n"][k + 1:])


def test_held_parameters_are_not_rescaled_at_a_tear(tmp_path):
    """With the parameters held (set_frozen) a tear still restarts nothing the user froze:
    beta and sigma2 keep their values (and their nominal) through the tear, which the same
    record without the freeze rescales."""
    from dataclasses import replace

    from reference_py.bank import STATUS_RUPTURE, FilterBank
    from reference_py.config import ContactConfig, default_config
    from reference_py.params import IDX, PRESETS
    from reference_py.tools.csvio import read_trial, time_us

    rec, _ = _phantom(tmp_path, "lab", 204)          # three ruptures
    tr = read_trial(str(rec))
    t_us = time_us(tr.t_s)
    cfg = replace(default_config(3), contact=ContactConfig(enabled=True))

    def run(freeze_at: int | None) -> tuple[list[int], list[tuple[float, float, float]]]:
        bank = FilterBank(F64, cfg, [PRESETS["paper-10mms"].params.as_list()])
        tears, values = [], []
        for k in range(len(t_us)):
            if freeze_at is not None and k == freeze_at:
                bank.set_frozen(True)
            o = bank.step(t_us[k:k + 1], F64.arr(tr.depth_mm[k:k + 1]),
                          F64.arr(tr.velocity_mm_s[k:k + 1]), F64.arr(tr.force_n[k:k + 1]))
            if int(o.status[0]) & STATUS_RUPTURE:
                tears.append(k)
            values.append((float(bank.th.beta[0]), float(bank.th.sigma2[0]),
                           float(bank.scaled.nominal[IDX["beta"]][0])))
        return tears, values

    tears, adapting = run(None)
    k = tears[0]
    assert adapting[k][0] < 0.9 * adapting[k - 1][0], "the free run rescales at its tear"
    held_tears, held = run(k - 5)
    assert any(k - 5 <= j <= k + 5 for j in held_tears), "the held run tears there too"
    assert all(v == held[k - 6] for v in held[k - 5:]), "a held beta or sigma2 moved"
