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


def test_real_upper_bounds_have_one_source():
    """The upper bounds that keep every published estimate and standard deviation finite
    (a fuzzer found nominal alpha = -5.7e303 with p0_u = 2e78 publishing an infinite sd): one
    table in config.py, generated into the C constants, applied on both sides at the bound."""
    from dataclasses import replace

    from reference_py import config, robust
    from reference_py.bank import FilterBank
    from reference_py.fmath import F64
    from reference_py.params import get_preset

    header = (ROOT / "firmware" / "src" / "nte_constants.h").read_text()
    source = (ROOT / "firmware" / "src" / "nte_config.c").read_text()
    bounds = {**config.UPPER_BOUNDS, **config.ROBUST_UPPER_BOUNDS,
              "nominal_abs": config.NOMINAL_ABS_MAX}
    for name, hi in bounds.items():
        macro = f"NTE_K_RANGE_{name.upper()}_MAX"
        assert f"#define {macro} ({float(hi).hex()})" in header, macro
        assert macro in source, f"nte_config.c does not check {macro}"
    base = config.EstimatorConfig()
    for name, hi in config.UPPER_BOUNDS.items():
        assert _first_error(lambda: replace(base, **{name: hi}).validate()) is None
        assert name in _first_error(lambda: replace(base, **{name: hi * 1.01}).validate())
    rb = robust.RobustConfig()
    for name, hi in config.ROBUST_UPPER_BOUNDS.items():
        assert _first_error(lambda: replace(rb, **{name: hi}).validate()) is None
        assert name in _first_error(lambda: replace(rb, **{name: hi * 1.01}).validate())
    nominal = get_preset("paper-10mms").params.as_list()
    FilterBank(F64, base, [nominal])                    # the preset is accepted
    big = nominal[:5] + [-1.01 * config.NOMINAL_ABS_MAX] + nominal[6:]
    assert "alpha" in _first_error(lambda: FilterBank(F64, base, [big]))
