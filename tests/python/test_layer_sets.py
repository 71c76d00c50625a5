"""Model III's layer sets (nte.h THE LAYER SETS; reference_py/layers.py LayerSets.enter): in
predict-only mode each layer below the first runs with its own sigma0, f1, beta, sigma2 from its
start depth on; --export-config writes them at the depths of the tears it found, fitted to the
record's replay with the starts moved by -1, 0 and +1 mm (export_replay.LAYER_SHIFTS_MM).

* the switch: where it happens, what is published (layer, the set's values), what is left
  alone (the samples before the first start, everything outside predict-only mode, Model II);
* C = reference at 0 ULP in float32 and float64 with sets;
* the export: starts at the run's tears, the replay block's RMSE is that of the three shifted
  replays (recomputed here from the readers' predictions), the file read back by both readers.

Bad layer sets in a file are in test_config_loop.py's table; nte_config_check's refusals in
tests/c/test_api.c.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from test_config_loop import VENV_BIN, crun, ref

PRESET = {"sigma0": 7.9e-3, "sigma1": 2.46, "sigma2": 4.14e-3, "f1": 5.59e-2,
          "f2": -2.11e-2, "alpha": 5.25e-2, "beta": 2.55e-2}
SETS = [{"start_mm": 4.0, "sigma0": 3.2e-3, "f1": 7.0e-2, "beta": 1.9e-2, "sigma2": 9.0e-3},
        {"start_mm": 8.5, "sigma0": 1.3e-2, "f1": 4.0e-2, "beta": 3.1e-2, "sigma2": 2.0e-3}]
SET_NAMES = ("sigma0", "f1", "beta", "sigma2")


def _config(path: Path, sets: list[dict[str, float]] | None, model: int = 3) -> Path:
    doc: dict[str, object] = {"schema": "nte-estimator-config/1", "model": model,
                              "params": PRESET}
    if sets is not None:
        doc["model3"] = {"layer_sets": sets}
    path.write_text(json.dumps(doc))
    return path


@pytest.fixture(scope="module")
def record(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """In to 12 mm at 10 mm/s, a dwell, back out: the tip crosses both starts both ways."""
    rec = tmp_path_factory.mktemp("sets") / "rec.csv"
    subprocess.run([str(VENV_BIN / "nte-ref"), "simulate", "--preset", "paper-10mms", "--depth",
                    "12", "--dwell", "0.5", "--out", str(rec)], check=True, capture_output=True)
    return rec


def _rows(path: Path) -> np.ndarray:
    return np.genfromtxt(path, delimiter=",", names=True)


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_predict_only_runs_each_layer_with_its_set(tmp_path, record, precision):
    """Below each start the model runs with that set's values (published as the estimates,
    u = 0), the layer published is the set's; nothing changes before the first start; the
    configured values return when the tip is out; C writes the reference's bytes."""
    with_sets = _config(tmp_path / "sets.json", SETS)
    plain = _config(tmp_path / "plain.json", None)
    outs = {}
    for name, cfg in (("sets", with_sets), ("plain", plain)):
        out = tmp_path / f"{name}.csv"
        r = ref(str(record), "--config", str(cfg), "--predict-only", "--precision", precision,
                "--out", str(out))
        assert r.returncode == 0, r.stderr
        outs[name] = out
    c_out = tmp_path / "c.csv"
    c = crun(str(record), "--config", str(with_sets), "--predict-only", "--out", str(c_out),
             precision=precision)
    assert c.returncode == 0, c.stderr
    assert c_out.read_bytes() == outs["sets"].read_bytes()

    depth = _rows(record)["depth_mm"]
    est, base = _rows(outs["sets"]), _rows(outs["plain"])
    deepest = np.maximum.accumulate(depth)
    want = np.where(depth > 0.0, (deepest >= 4.0).astype(int) + (deepest >= 8.5), 0)
    assert np.array_equal(est["layer"].astype(int), want)
    assert set(want.tolist()) == {0, 1, 2} and want[-1] == 0
    as_real = np.float32 if precision == "float32" else np.float64
    for k, s in enumerate(SETS):
        inside = want == k + 1
        for nm in ("sigma0", "beta", "sigma2"):
            # u restarts at 0: the published estimate is the set's value, rounded once
            assert np.all(as_real(est[nm][inside]) == as_real(s[nm])), (k, nm)
        assert np.allclose(est["f1"][inside], s["f1"], rtol=1e-6)
    before = want == 0
    first = int(np.argmax(want > 0))
    assert first > 10
    assert np.array_equal(est["force_hat_n"][:first], base["force_hat_n"][:first])
    assert est["force_hat_n"][first] != base["force_hat_n"][first]
    # out of the tissue again: the configured values
    out_again = before & (np.arange(len(depth)) > first)
    assert np.any(out_again)
    for nm in ("sigma0", "beta", "sigma2"):
        assert np.all(as_real(est[nm][out_again]) == as_real(PRESET[nm])), nm


def test_the_sets_act_in_predict_only_mode_and_model_3_only(tmp_path, record):
    """Outside predict-only mode the filters identify from the configured values: the sets
    change no byte; with --model 2 they are not read (as the file's other Model III fields)."""
    with_sets = _config(tmp_path / "sets.json", SETS)
    plain = _config(tmp_path / "plain.json", None)
    for args in (["--model", "3", "--contact", "off"], ["--model", "2"]):
        a, b = tmp_path / "a.csv", tmp_path / "b.csv"
        for cfg, out in ((with_sets, a), (plain, b)):
            r = ref(str(record), "--config", str(cfg), *args, "--out", str(out))
            assert r.returncode == 0, r.stderr
            c = crun(str(record), "--config", str(cfg), *args, "--out", str(tmp_path / "c.csv"))
            assert c.returncode == 0, c.stderr
            assert (tmp_path / "c.csv").read_bytes() == out.read_bytes()
        assert a.read_bytes() == b.read_bytes(), args


def test_the_configuration_refuses_sets_it_cannot_run():
    from dataclasses import replace

    from reference_py.config import LayerSet, default_config
    ok = LayerSet(4.0, (7.9e-3, 5.59e-2, 2.55e-2, 4.14e-3))
    replace(default_config(3), layer_sets=(ok,)).validate()
    for cfg, why in (
            (replace(default_config(2), layer_sets=(ok,)), "Model III only"),
            (replace(default_config(3), layer_sets=(ok,) * 4), "at most 3"),
            (replace(default_config(3), layer_sets=(ok, ok)), "layer_sets[1].start_mm"),
            (replace(default_config(3), layer_sets=(LayerSet(4.0, (1.0, 1.0, -1.0, 1.0)),)),
             "layer_sets[0].beta"),
            (replace(default_config(3), layer_sets=(LayerSet(600.0, ok.values),)),
             "layer_sets[0].start_mm")):
        with pytest.raises(ValueError, match=why.replace("[", r"\[").replace("]", r"\]")):
            cfg.validate()


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A short skin-on-muscle phantom insertion (two tears) identified by nte-run-double (the
    reference's bytes: test_export_twins.py) with --export-config."""
    d = tmp_path_factory.mktemp("export")
    rec = d / "som.csv"
    subprocess.run([str(VENV_BIN / "nte-ref"), "phantom", "skin-on-muscle", "--seed", "207",
                    "--stroke", "14", "--dwell", "1", "--rate", "50", "--out", str(rec)],
                   check=True, capture_output=True)
    r = crun(str(rec), "--model", "3", "--out", str(d / "id.csv"), "--export-config",
             str(d / "x.json"))
    assert r.returncode == 0, r.stderr
    return {"dir": d, "rec": rec, "id": d / "id.csv", "cfg": d / "x.json"}


def test_export_writes_a_set_at_each_tear_of_the_first_insertion(exported):
    doc = json.loads(exported["cfg"].read_text())
    sets = doc["model3"]["layer_sets"]
    run = _rows(exported["id"])
    depth = _rows(exported["rec"])["depth_mm"]
    torn = [k for k in range(1, len(run)) if run["layer"][k] > run["layer"][k - 1]]
    assert len(torn) == len(sets) == 2
    for k, s in zip(torn, sets):
        assert s["start_mm"] == float(depth[k]) - float(run["surface_mm"][k])
        assert set(s) == set(SET_NAMES) | {"start_mm", "sd"}
        assert all(0.0 < s[nm] <= 1000.0 for nm in SET_NAMES)


def test_the_replay_block_is_the_three_shifted_replays(exported):
    """fit_rmse_n is the RMSE of the readers' predictions of the record with the exported
    file, its starts as written and moved by -1 and +1 mm, the residuals one after the
    other (summed in sample order, as both exporters sum)."""
    from reference_py.tools.export_replay import LAYER_SHIFTS_MM, sum_in_order
    d = exported["dir"]
    doc = json.loads(exported["cfg"].read_text())
    force = _rows(exported["rec"])["force_n"] - doc["tare_n"]
    parts = []
    for shift in LAYER_SHIFTS_MM:
        moved = json.loads(exported["cfg"].read_text())
        for s in moved["model3"]["layer_sets"]:
            # the exporter adds the shift in the working precision (float64 here)
            s["start_mm"] = s["start_mm"] + shift
        f = d / "moved.json"
        f.write_text(json.dumps(moved))
        out = d / "pred.csv"
        r = ref(str(exported["rec"]), "--config", str(f), "--predict-only", "--out", str(out))
        assert r.returncode == 0, r.stderr
        c = crun(str(exported["rec"]), "--config", str(f), "--predict-only", "--out",
                 str(d / "cpred.csv"))
        assert c.returncode == 0 and (d / "cpred.csv").read_bytes() == out.read_bytes()
        parts.append(_rows(out)["force_hat_n"] - force)
    res = np.concatenate(parts)
    assert float(np.sqrt(sum_in_order(res * res) / len(res))) == doc["replay"]["fit_rmse_n"]
    assert doc["replay"]["fit_rmse_n"] < 0.1 * doc["replay"]["peak_n"]


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q"]))
