"""nte-ref estimate run in-process for the tests of its flags and lines (test_column_map,
test_verdict, test_start_noise, test_engine_c): exit status, stdout and stderr lines."""
from __future__ import annotations

from pathlib import Path

import pytest

from reference_py.tools.cli import main


def estimate(capsys: pytest.CaptureFixture[str], src: Path, out: Path, *flags: str
             ) -> tuple[int, list[str], list[str]]:
    """``nte-ref estimate SRC --out OUT FLAGS``: (exit status, stdout lines, stderr lines); a
    refusal by the argument parser (SystemExit) is its exit status too."""
    capsys.readouterr()
    try:
        rc = main(["estimate", str(src), "--out", str(out), *flags])
    except SystemExit as e:
        rc = int(e.code)  # type: ignore[arg-type]
    got = capsys.readouterr()
    return rc, got.out.strip().splitlines(), got.err.strip().splitlines()


def refused(capsys: pytest.CaptureFixture[str], src: Path, out: Path, *flags: str) -> list[str]:
    """The stderr lines of an estimate that must be refused: exit 2, nothing on stdout, no
    output file."""
    rc, so, se = estimate(capsys, src, out, *flags)
    assert rc == 2 and so == [], (rc, so, se)
    assert not out.exists()
    return se
