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


def _first_error(make) -> str | None:
    try:
        make()
    except ValueError as e:
        return str(e)
    return None


def test_configuration_ranges_have_one_source():
    """config.py's range tables drive the Python validation, and the C validation is built
    from the same tables (generated macros, which tests/c/test_robust.c checks at every bound)."""
    from dataclasses import replace

    from reference_py import config, robust

    header = (ROOT / "firmware" / "src" / "nte_constants.h").read_text()
    source = (ROOT / "firmware" / "src" / "nte_config.c").read_text()
    for prefix, table in (("NTE_RANGE_", config.INT_RANGES),
                          ("NTE_RANGE_ROB_", config.ROBUST_INT_RANGES)):
        for name, (lo, hi) in table.items():
            for tag, v in (("MIN", lo), ("MAX", hi)):
                macro = f"{prefix}{name.upper()}_{tag}"
                assert f"#define {macro} {v}\n" in header, macro
                assert macro in source, f"nte_config.c does not check {macro}"
    for macro in ("NTE_CONFIG_POSITIVE_FIELDS", "NTE_CONFIG_NONNEGATIVE_FIELDS",
                  "NTE_ROBUST_POSITIVE_FIELDS"):
        assert macro + "(" in source, macro
    base = config.EstimatorConfig()
    for name, (lo, hi) in config.INT_RANGES.items():
        assert _first_error(lambda: replace(base, **{name: lo}).validate()) is None
        assert _first_error(lambda: replace(base, **{name: hi}).validate()) is None
        assert name in _first_error(lambda: replace(base, **{name: lo - 1}).validate())
        assert name in _first_error(lambda: replace(base, **{name: hi + 1}).validate())
    for name in config.POSITIVE_FIELDS:
        assert name in _first_error(lambda: replace(base, **{name: 0.0}).validate())
    for name in config.NONNEGATIVE_FIELDS:
        assert name in _first_error(lambda: replace(base, **{name: -1.0}).validate())
    rb = robust.RobustConfig(min_entries=2)
    for name, (lo, hi) in config.ROBUST_INT_RANGES.items():
        step = 2 if name == "buffer_len" else 1
        extra = {"buffer_len": hi} if name == "min_entries" else {}
        assert _first_error(lambda: replace(rb, **{name: lo}).validate()) is None
        assert _first_error(lambda: replace(rb, **extra, **{name: hi}).validate()) is None
        assert name in _first_error(lambda: replace(rb, **{name: lo - step}).validate())
        assert name in _first_error(lambda: replace(rb, **extra, **{name: hi + step}).validate())
    for name in config.ROBUST_POSITIVE_FIELDS:
        assert name in _first_error(lambda: replace(rb, **{name: 0.0}).validate())
