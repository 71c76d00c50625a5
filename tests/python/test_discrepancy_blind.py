"""Blind tests (issue 8): data with a hidden effect, generated in tests only, graded on what the
workflow names first and on how much of the gap to the noise-free truth it closes.

All 180 cases (20 per effect, 20 with none, 20 with relaxation + pre-sliding) run once, in two
processes, for the whole module.  Naming and gap shrink are separate tests so that a shortfall in
one is visible (a strict xfail carrying the measured figure) without hiding the other.

DISCREPANCY_SUMMARY=FILE writes the closing-note figures of this run (confusion matrix, median
shrink, run time per trial; the same as ``python -m reference_py.discrepancy.confusion``);
DISCREPANCY_RESULTS=FILE writes the per-case results as JSON; DISCREPANCY_REGRADE=FILE grades such
a file instead of running the cases (seconds instead of ~6 CPU-minutes; same figures, the cases
and the workflow are deterministic).
"""
import json
import os

import pytest

from discrepancy_generator import CASES_PER_KIND, EFFECTS, PAIR, run_all

#: measured shortfalls (full run, 20 cases per row); strict: the mark must go once it passes
NAMING_XFAIL: dict[str, str] = {
    "direction_asymmetry": "named first 17/20 (3 'none': the base fit absorbs the asymmetry to "
                           "2-3 mN RMS vs the truth under 6 mN noise, screen dBIC 7 / -1 / 2), "
                           "target >= 18/20",
}
_SHRINK = "cases named first with RMSE vs truth -50 % in its phases and -30 % overall: "
SHRINK_XFAIL: dict[str, str] = {
    "velocity_friction": _SHRINK + "18/20 (k=12: phase RMSE +35 %; k=17: overall only -20 %), "
                                   "target 20/20",
    "direction_asymmetry": _SHRINK + "16/17 (k=6: phase RMSE doubles after a 2nd effect), "
                                     "target all",
    "layer_puncture": _SHRINK + "15/20 (median 0.65 phases / 0.46 overall), target 20/20",
    "sensor_drift": _SHRINK + "15/20 (median 0.73; k=5 0.01, k=17 0.12), target 20/20",
    "tissue_motion": _SHRINK + "13/19 (median 0.59; partial fits 0.29-0.48), target all",
}


def _params(xfails: dict[str, str]) -> list:
    return [pytest.param(e, marks=pytest.mark.xfail(strict=True, reason=xfails[e]))
            if e in xfails else e for e in EFFECTS]


@pytest.fixture(scope="module")
def results() -> list[dict]:
    cached = os.environ.get("DISCREPANCY_REGRADE")
    if cached:   # re-grade a DISCREPANCY_RESULTS file of a full run (the workflow is deterministic)
        with open(cached) as fh:
            return [{**r, "kind": tuple(r["kind"])} for r in json.load(fh)]
    res = run_all(workers=2, per_kind=CASES_PER_KIND)
    out = os.environ.get("DISCREPANCY_SUMMARY")
    if out:
        from reference_py.discrepancy.confusion import summarise
        with open(out, "w") as fh:
            fh.write(summarise(res) + "\n")
    out = os.environ.get("DISCREPANCY_RESULTS")
    if out:
        with open(out, "w") as fh:
            json.dump([{**r, "kind": list(r["kind"])} for r in res], fh)
    return res


@pytest.mark.parametrize("effect", _params(NAMING_XFAIL))
def test_hidden_effect_named_first(results: list[dict], effect: str) -> None:
    rows = [r for r in results if r["kind"] == (effect,)]
    assert len(rows) >= 20
    hits = [r for r in rows if r["named"][0] == effect]
    assert len(hits) >= 0.9 * len(rows), [r["named"] for r in rows]


@pytest.mark.parametrize("effect", _params(SHRINK_XFAIL))
def test_gap_shrinks_when_named_first(results: list[dict], effect: str) -> None:
    """Every case where the hidden effect is named first: RMSE vs the noise-free truth falls by
    >= 50 % where the effect acts and by >= 30 % overall."""
    hits = [r for r in results if r["kind"] == (effect,) and r["named"][0] == effect]
    assert hits
    bad = [r for r in hits if not (r["support_after"] <= 0.5 * r["support_before"]
                                   and r["overall_after"] <= 0.7 * r["overall_before"])]
    assert not bad, bad


@pytest.mark.xfail(strict=True, reason="'none' returned on 17/20 cases without a hidden effect "
                                       "(full run of this module), target >= 18/20")
def test_no_hidden_effect_reports_none(results: list[dict]) -> None:
    rows = [r for r in results if r["kind"] == ()]
    assert len(rows) >= 20
    ok = sum(1 for r in rows if r["named"] == ["none"])
    assert ok >= 0.9 * len(rows), [r["named"] for r in rows]


def test_two_hidden_effects_both_named(results: list[dict]) -> None:
    rows = [r for r in results if r["kind"] == PAIR]
    assert len(rows) >= 20
    ok = sum(1 for r in rows if set(PAIR) <= set(r["named"]))
    assert ok >= 0.8 * len(rows), [r["named"] for r in rows]
