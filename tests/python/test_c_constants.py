"""The C constants headers are exactly what the reference generates today.

firmware/src/nte_constants.h and firmware/host/nte_presets.h hold every rounded constant of the
reference (exp/tanh coefficients, tuning profiles, presets) as exact hex literals; this test
regenerates them in memory and fails when the committed files are stale.
"""
from __future__ import annotations

import subprocess
import sys

from c_twin import ROOT


def test_constants_headers_up_to_date():
    res = subprocess.run([sys.executable, str(ROOT / "firmware" / "tools" / "gen_constants.py"),
                          "--check"], capture_output=True, text=True, cwd=ROOT)
    assert res.returncode == 0, res.stdout + res.stderr
