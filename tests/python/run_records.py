"""Shared by the tests of nte-run's reader and verdict (test_run_units.py, test_run_verdict.py):
the two correct records of issue 23 and a runner of the C programs.

    ph  the phantom `nte-ref phantom skin --seed 3` (velocity column given; rests 104 samples)
    ml  a measured-like record (discrepancy_measured_like.make_trial(5), written without a
        velocity column by config_loop_figures.write_record)
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from c_twin import EXE, ROOT

PROGS = {"nte-run-double": EXE["float64"], "nte-run": EXE["float32"]}


def write_records(d: Path) -> dict[str, Path]:
    """The phantom and the measured-like record, written into `d`."""
    subprocess.run([sys.executable, "-m", "reference_py", "phantom", "skin", "--seed", "3",
                    "--out", str(d / "ph.csv")], check=True, capture_output=True, cwd=ROOT)
    from config_loop_figures import write_record
    from discrepancy_measured_like import make_trial
    tr = make_trial(5)[0]
    write_record(d / "ml.csv", tr.t_s, tr.depth_mm, tr.force_n)
    return {"ph": d / "ph.csv", "ml": d / "ml.csv"}


def c_run(prog: str, csv: Path, out: Path, *flags: str) -> subprocess.CompletedProcess:
    """nte-run or nte-run-double on `csv`, writing `out`."""
    return subprocess.run([str(PROGS[prog]), str(csv), "--out", str(out), *flags],
                          capture_output=True, text=True, timeout=120)


def reference(csv: Path, out: Path, *flags: str) -> subprocess.CompletedProcess:
    """`nte-ref estimate` on `csv`, writing `out`."""
    return subprocess.run([sys.executable, "-m", "reference_py", "estimate", str(csv),
                           "--out", str(out), *flags], capture_output=True, text=True, cwd=ROOT)
