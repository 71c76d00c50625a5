"""Replay regression of the float build (PX4-ECL change indication).

The float build's estimate files on the paper scenarios are committed: two as plain CSV
(tests/data/c_replay/*.csv, readable diffs) and all 24 by SHA-256 (tests/data/c_replay/
SHA256SUMS).  Any change of the library's output bits fails this test; when a change is
intended, regenerate with ``python tests/python/c_twin.py replay`` and commit the new files
together with the change.
"""
from __future__ import annotations

import pytest

from c_twin import ALL_RUNS, EXE, REPLAY, REPLAY_CSV, run_c, sha256_lines

pytestmark = pytest.mark.skipif(not EXE["float32"].exists(),
                                reason="build/host/bin/nte-run missing: run make build first")


def test_replay_matches_committed_outputs(tmp_path):
    expected = dict(reversed(line.split("  ", 1)) for line in
                    (REPLAY / "SHA256SUMS").read_text().splitlines() if line)
    assert set(expected) == {r.name for r in ALL_RUNS}
    changed = []
    for r in ALL_RUNS:
        lines = run_c("float32", r, tmp_path / f"{r.name}.csv")
        if r.name in REPLAY_CSV:
            committed = (REPLAY / f"{r.name}.csv").read_text().split("\n")[:-1]
            for k, (a, b) in enumerate(zip(lines, committed)):
                if a != b:
                    changed.append(f"{r.name} line {k + 1}:\n  now       {a}\n  committed {b}")
                    break
        if sha256_lines(lines) != expected[r.name]:
            changed.append(f"{r.name}: SHA-256 differs from the committed replay")
    assert not changed, "\n".join(changed)
