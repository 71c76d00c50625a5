"""cppcheck + clang-tidy on firmware/ through tests/static/run.sh: no finding outside the
justified list tests/static/suppressions.txt, and no stale entry in that list."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def test_static_analysis_has_no_unjustified_finding() -> None:
    missing = [t for t in ("cppcheck", "clang-tidy", "clang", "cmake") if shutil.which(t) is None]
    if missing:
        pytest.skip(f"{missing} not installed (apt-get install -y cppcheck clang clang-tidy)")
    run = subprocess.run([str(ROOT / "tests" / "static" / "run.sh")], capture_output=True,
                         text=True, timeout=600)
    print(run.stdout, run.stderr)
    summary = [line for line in run.stdout.splitlines() if line.startswith("static: files=")]
    assert summary, run.stdout + run.stderr
    assert "unsuppressed=0" in summary[0] and "unused_suppressions=0" in summary[0], summary[0]
    assert run.returncode == 0, run.stdout + run.stderr
