"""nte-run closes with the reference's verdict line (issue 23): the innovation RMS against the
sensor's noise, to the character (reference_py/tools/verdict.py is the contract).

Each run of nte-run and nte-run-double is judged again by verdict.verdict on what the C
program wrote (its estimate file: innovation, status, confidence) and the input as the
reference reads it: the last line on stdout and the start's warning on stderr must be the
reference's.  The forms: a record that rests before it moves (the phantom, the measured-like
record), the robust estimator's suffix, --predict-only, no sample in tissue, no rest before
the stage moves (noise unknown), a noise given by --noise.  End to end, `nte-ref estimate` and
nte-run-double print the same verdict line on the phantom (Model III) and the measured-like
record (Model II).

Requires build/host/bin/nte-run{,-double} (``make build``).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from run_records import NEEDS_C, PROGS, c_run, records_fixture, reference

pytestmark = NEEDS_C


def _air_and_moving(d: Path, _: dict[str, Path]) -> dict[str, Path]:
    from config_loop_figures import write_record
    # never in tissue: the stage holds still at 0 mm
    t = np.arange(400) * 0.01
    force = np.random.default_rng(1).normal(0.0, 2e-3, len(t))
    write_record(d / "air.csv", t, np.zeros_like(t), force)
    # no rest: the stage moves at 10 mm/s from the first sample
    write_record(d / "moving.csv", t, 10.0 * t, 0.02 * (10.0 * t) + force)
    return {"air": d / "air.csv", "moving": d / "moving.csv"}


records = records_fixture(_air_and_moving)


def _column(est: Path, name: str) -> np.ndarray:
    lines = est.read_text().split("\n")
    header = lines[0].split(",")
    i = header.index(name)
    return np.array([float(ln.split(",")[i]) for ln in lines[1:] if ln])


def expected(csv: Path, est: Path, *, predict_only: bool = False, noise: float | None = None,
             robust: bool = False):
    """verdict.verdict on what the C program wrote and the input as the reference reads it."""
    from reference_py.tools.csvio import Units, read_trial
    from reference_py.tools.verdict import verdict
    tr = read_trial(csv, units=Units(check=False))
    status = _column(est, "status").astype(np.uint32)
    return verdict(tr.t_s, tr.depth_mm, tr.force_n, _column(est, "innovation_n"), status,
                   predict_only=predict_only, noise_n=noise,
                   confidence=float(_column(est, "confidence")[-1]) if robust else None)


def check(prog: str, csv: Path, tmp: Path, *flags: str, predict_only: bool = False,
          noise: float | None = None) -> str:
    est = tmp / f"{prog}.csv"
    r = c_run(prog, csv, est, *flags)
    assert r.returncode == 0, r.stderr
    want = expected(csv, est, predict_only=predict_only, noise=noise,
                    robust="robust" in flags)
    assert r.stdout.splitlines()[-1] == want.line
    warnings = [ln for ln in r.stderr.splitlines() if ln.startswith("warning: the first")]
    assert warnings == ([] if want.warning is None else [want.warning])
    return want.line


@pytest.mark.parametrize("prog", list(PROGS))
@pytest.mark.parametrize("case", ["ph-m3", "ml-m2", "ml-robust", "air", "moving"])
def test_verdict_line_is_the_references(records, tmp_path, prog, case):
    csv, flags = {
        "ph-m3": (records["ph"], ["--model", "3", "--contact", "on"]),
        "ml-m2": (records["ml"], ["--model", "2"]),
        "ml-robust": (records["ml"], ["--model", "2", "--estimator", "robust"]),
        "air": (records["air"], ["--model", "2"]),
        "moving": (records["moving"], ["--model", "2"]),
    }[case]
    line = check(prog, csv, tmp_path, *flags)
    form = {"ph-m3": "measured in the first", "ml-m2": "see nte-discrepancy",
            "ml-robust": "; robust refinement: confidence ", "air": "no sample in tissue",
            "moving": "noise unknown (no rest before the stage moves): give --noise N"}[case]
    assert form in line
    print(f"\n{prog} {case}: {line}")


@pytest.mark.parametrize("prog", list(PROGS))
def test_predict_only_gives_no_verdict(records, tmp_path, prog):
    cfg = tmp_path / "cfg.json"
    r = c_run(prog, records["ml"], tmp_path / "id.csv", "--model", "2", "--export-config",
              str(cfg))
    assert r.returncode == 0, r.stderr
    line = check(prog, records["ml"], tmp_path, "--config", str(cfg), "--predict-only",
                 predict_only=True)
    assert line == "verdict: predict-only, the force was not read: no verdict"


@pytest.mark.parametrize("case", ["ph-m3", "ml-m2"])
def test_both_programs_print_the_same_verdict(records, tmp_path, case):
    csv, flags = {"ph-m3": (records["ph"], ["--model", "3", "--contact", "on"]),
                  "ml-m2": (records["ml"], ["--model", "2"])}[case]
    py = reference(csv, tmp_path / "py.csv", *flags)
    assert py.returncode == 0, py.stderr
    c = c_run("nte-run-double", csv, tmp_path / "c.csv", *flags)
    assert c.returncode == 0, c.stderr
    assert c.stdout.splitlines()[-1] == py.stdout.splitlines()[-1]
    assert c.stdout.splitlines()[-1].startswith("verdict: innovation RMS ")
    warn = [ln for ln in py.stderr.splitlines() if ln.startswith("warning: the first")]
    assert warn == [ln for ln in c.stderr.splitlines() if ln.startswith("warning: the first")]


def test_verdict_rules_have_one_source():
    """nte_verdict_rules.h holds verdict.py's thresholds and the status bits of its
    NOT_IN_TISSUE (gen_constants.py --check keeps it current; test_c_constants.py)."""
    from reference_py.tools import verdict
    from c_twin import ROOT
    header = (ROOT / "firmware" / "host" / "nte_verdict_rules.h").read_text()
    assert f"#define NTE_VERDICT_NOT_IN_TISSUE {verdict.NOT_IN_TISSUE}U\n" in header
    for name in ("REST_DEPTH_MM", "FOLLOWS_FACTOR", "START_WINDOW_S", "START_FACTOR"):
        assert f"#define NTE_VERDICT_{name} ({float(getattr(verdict, name)).hex()})" in header
    nte_h = (ROOT / "firmware" / "include" / "nte.h").read_text()
    for bit, name in ((0, "INIT"), (1, "REJECTED"), (5, "OUT_OF_TISSUE"), (13, "PREDICT_ONLY")):
        assert f"#define NTE_STATUS_{name} (1U << {bit}U)" in nte_h
        assert verdict.NOT_IN_TISSUE & (1 << bit)
    assert verdict.NOT_IN_TISSUE == 1 | 2 | 32 | 8192
