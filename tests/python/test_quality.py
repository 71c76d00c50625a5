"""Estimation quality of the paper's bank over 100 seeds (reference issue, "How it is checked").

Scenario: Model II, 10 mm/s to 50 mm, 1 s dwell, back out, 200 Hz, white noise 2 mN; every seed
has its own noise and its own start.  The table of every case is printed and written to
build/quality.md (the README's table comes from `nte-ref evaluate --matrix`).
"""
from pathlib import Path

import numpy as np
import pytest

from reference_py.tools.quality import STANDARD_MATRIX, QualityCase, format_summary, run_quality

ROOT = Path(__file__).resolve().parents[2]
RESULTS: dict[QualityCase, object] = {}


@pytest.fixture(scope="module", autouse=True)
def table():
    yield
    text = format_summary([RESULTS[c] for c in STANDARD_MATRIX if c in RESULTS])
    print("\n" + text)
    out = ROOT / "build" / "quality.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text + "\n")


def _run(case):
    if case not in RESULTS:
        RESULTS[case] = run_quality(case)
    return RESULTS[case]


@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_bank_from_near_starts_meets_table_ii(precision):
    r = _run(QualityCase(factor=1.25, precision=precision))
    n_pass = int(r.passes["all"].sum())
    print(f"{precision}: {n_pass}/100 meet every bound")
    assert n_pass >= 95
    assert r.metrics["finite"].all()


@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_bank_from_factor5_starts_stays_finite(precision):
    r = _run(QualityCase(factor=5.0, precision=precision))
    assert r.metrics["finite"].all()
    for key, v in r.metrics.items():
        if key != "finite":
            assert np.all(np.isfinite(v)), key
            q = np.percentile(v, [10, 50, 90])
            print(f"factor 5 {precision} {key}: p10 {q[0]:.4g} median {q[1]:.4g} p90 {q[2]:.4g}")


@pytest.mark.parametrize("case", [c for c in STANDARD_MATRIX if c.factor == 1.25 and (
    c.schedule != "all" or c.profile != "default" or c.model != 2 or c.preset != "paper-10mms")],
    ids=lambda c: c.label().replace(" ", "_"))
def test_reported_cases_run_finite(case):
    """Rotation, the paper's tuning, Model I and 6 mm/s: reported; finite everywhere."""
    r = _run(case)
    assert r.metrics["finite"].all()
    if case.preset == "paper-6mms" and case.model == 2 and case.profile == "default":
        assert int(r.passes["all"].sum()) >= 90   # the 6 mm/s preset converges like 10 mm/s
