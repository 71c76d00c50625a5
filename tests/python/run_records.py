"""Shared by the tests of nte-run's reader, verdict and starting flags (test_run_units.py,
test_run_verdict.py, test_run_start.py): the two correct records of issue 23, runners of the
C programs and of the reference, and a refusal's message.

    ph  the phantom `nte-ref phantom skin --seed 3` (velocity column given; rests 104 samples)
    ml  a measured-like record (discrepancy_measured_like.make_trial(5), written without a
        velocity column by config_loop_figures.write_record)
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Callable

import pytest

from c_twin import EXE, ROOT

PROGS = {"nte-run-double": EXE["float64"], "nte-run": EXE["float32"]}
#: the tests' pytestmark: they need both C programs
NEEDS_C = pytest.mark.skipif(
    not all(p.exists() for p in EXE.values()),
    reason="build/host/bin/nte-run{,-double} missing: build the firmware first (make build)")


def write_records(d: Path) -> dict[str, Path]:
    """The phantom and the measured-like record, written into `d`."""
    subprocess.run([sys.executable, "-m", "reference_py", "phantom", "skin", "--seed", "3",
                    "--out", str(d / "ph.csv")], check=True, capture_output=True, cwd=ROOT)
    from config_loop_figures import write_record
    from discrepancy_measured_like import make_trial
    tr = make_trial(5)[0]
    write_record(d / "ml.csv", tr.t_s, tr.depth_mm, tr.force_n)
    return {"ph": d / "ph.csv", "ml": d / "ml.csv"}


def records_fixture(extra: Callable[[Path, dict[str, Path]], dict[str, Path]]):
    """A module fixture: write_records's records in a temporary folder, with what
    extra(folder, records) writes beside them."""
    @pytest.fixture(scope="module")
    def records(tmp_path_factory) -> dict[str, Path]:
        d = tmp_path_factory.mktemp("records")
        out = write_records(d)
        return {**out, **extra(d, out)}
    return records


def c_run(prog: str, csv: Path, out: Path, *flags: str) -> subprocess.CompletedProcess:
    """nte-run or nte-run-double on `csv`, writing `out`.  Its output decoded as it is written:
    text=True would turn a CR inside a quoted name the message repeats into a line break."""
    r = subprocess.run([str(PROGS[prog]), str(csv), "--out", str(out), *flags],
                       capture_output=True, timeout=120)
    return subprocess.CompletedProcess(r.args, r.returncode, r.stdout.decode(), r.stderr.decode())


def reference(csv: Path, out: Path, *flags: str) -> subprocess.CompletedProcess:
    """`nte-ref estimate` on `csv`, writing `out` (its output decoded as c_run's)."""
    r = subprocess.run([sys.executable, "-m", "reference_py", "estimate", str(csv),
                        "--out", str(out), *flags], capture_output=True, cwd=ROOT)
    return subprocess.CompletedProcess(r.args, r.returncode, r.stdout.decode(), r.stderr.decode())


def body(stderr: str, prog: str) -> str:
    """The one line of a refusal without its "PROG: error: " prefix (and the argument
    parser's " (see PROG --help)" suffix)."""
    lines = stderr.splitlines()
    assert len(lines) == 1, stderr
    prefix, suffix = f"{prog}: error: ", f" (see {prog} --help)"
    assert lines[0].startswith(prefix), lines[0]
    text = lines[0][len(prefix):]
    return text[:-len(suffix)] if text.endswith(suffix) else text
