"""--export-config from both twins, byte for byte (issue 21, "the loop"): nte-ref estimate and
nte-run-double write the same export, but for "source", on a phantom record in four
configurations, and both run a poor fit again from the first strengths.

The only tests that run the reference's export: it fits the replay in numpy (export_refine.py),
minutes per export on a slow machine, so the records here are sampled at 50 and 30 Hz (half the
samples of the 100 Hz phantom records and the 50 Hz measured-like one they replaced; the export's
operations are the same at any rate).  Every other
test of the export (test_config_loop.py, test_layer_sets.py) runs it with the C twin, which these
tests hold to the reference's bytes.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from test_config_loop import _c, crun, loop_records, ref

#: the records' sample rate, Hz (the skin-on-muscle preset records at 100 Hz)
RATE_HZ = "50"


@pytest.fixture(scope="module")
def records(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The loop's phantom records (skin-on-muscle, seeds 1 and 3, files as recorded: air gap
    and tare; seed 3 tears twice) at 50 Hz."""
    d = tmp_path_factory.mktemp("twins")
    return {"dir": d, **loop_records(d, (1, 3), "--rate", RATE_HZ)}


@pytest.mark.parametrize("args", [["--model", "2", "--contact", "on"],
                                  ["--model", "3", "--contact", "on", "--tau-slow", "4"],
                                  ["--model", "3", "--no-relaxation", "--no-layer-sets"],
                                  ["--model", "1", "--init-seed", "3"]],
                         ids=["m2-contact", "m3-contact", "m3-norelax", "m1-seed3"])
def test_export_same_bytes_from_both_twins(records, args):
    """--export-config from nte-ref estimate and nte-run-double on the same run: the same
    bytes but for "source" (floats in Python's shortest round-trip form from both); the
    export is accepted by both readers."""
    d = records["dir"]
    tag = "_".join(args).replace("-", "")
    rx, cx = d / f"rx{tag}.json", d / f"cx{tag}.json"
    r = ref(str(records["p3"]), *args, "--out", str(d / "rx.csv"), "--export-config", str(rx))
    assert r.returncode == 0, r.stderr
    c = crun(str(records["p3"]), *args, "--out", str(d / "cx.csv"), "--export-config", str(cx))
    assert c.returncode == 0, c.stderr
    assert json.loads(cx.read_text())["source"] == "nte-run"
    assert rx.read_text().replace('"source": "nte-ref estimate"', '"source": "nte-run"') == \
        cx.read_text()
    for exe in (ref, crun):
        assert exe(str(records["p1"]), "--config", str(cx), "--out",
                   str(d / "re.csv")).returncode == 0


def test_a_poor_fit_runs_again_from_the_first_strengths_in_both_twins(tmp_path):
    """A fit that still misses its record by more than RESTART_FRACTION of the peak runs again
    from the same snapshot with the relaxation strengths the record began with (the fit moves
    them in log form, and one pushed towards 0 stays there); the closer result is exported.
    On the measured-like generator's seed 83 at 30 Hz (measured: a first fit at 11.6 % of the
    peak, 0.730 N, and 0.721 N after the second) both twins do it, say so on stdout with the
    first fit's RMSE, and write the same bytes; the exported fit is no worse than the first."""
    _c()
    sys.path.insert(0, str(Path(__file__).parent))
    import config_loop_figures as figures
    from discrepancy_measured_like import make_trial
    from reference_py.tools.export_select import RESTART_FRACTION
    tr, _, _, _ = make_trial(83, rate_hz=30.0)
    rec = tmp_path / "ml83.csv"
    figures.write_record(rec, tr.t_s, tr.depth_mm, tr.force_n)
    args = ("--model", "3", "--contact", "on")
    r = ref(str(rec), *args, "--out", str(tmp_path / "r.csv"), "--export-config",
            str(tmp_path / "r.json"))
    assert r.returncode == 0, r.stderr
    c = crun(str(rec), *args, "--out", str(tmp_path / "c.csv"), "--export-config",
             str(tmp_path / "c.json"))
    assert c.returncode == 0, c.stderr
    assert (tmp_path / "r.json").read_text().replace('"source": "nte-ref estimate"',
                                                     '"source": "nte-run"') == \
        (tmp_path / "c.json").read_text()
    said = [ln for ln in r.stdout.splitlines() if ln.startswith("exported the estimates")]
    assert len(said) == 1 and said[0] in c.stdout.splitlines()
    rep = json.loads((tmp_path / "c.json").read_text())["replay"]
    first = float(said[0].split("after a first fit at ")[1].split(" N")[0])
    assert first > RESTART_FRACTION * rep["peak_n"]
    assert rep["fit_rmse_n"] <= first * (1 + 1e-3)     # the printed figure has 4 digits
