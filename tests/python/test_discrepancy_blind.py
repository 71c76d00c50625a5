"""Blind tests (issue 8): data with a hidden effect, generated in tests only, graded on what the
workflow names first and on how much of the gap to the noise-free truth it closes.

All 180 cases (20 per effect, 20 with none, 20 with relaxation + pre-sliding) run once, in two
processes, for the whole module.
"""
import pytest

from discrepancy_generator import CASES_PER_KIND, EFFECTS, PAIR, run_all


@pytest.fixture(scope="module")
def results() -> list[dict]:
    return run_all(workers=2, per_kind=CASES_PER_KIND)


@pytest.mark.parametrize("effect", EFFECTS)
def test_hidden_effect_named_first_and_gap_shrinks(results: list[dict], effect: str) -> None:
    rows = [r for r in results if r["kind"] == (effect,)]
    assert len(rows) >= 20
    hits = [r for r in rows if r["named"][0] == effect]
    assert len(hits) >= 0.9 * len(rows), [r["named"] for r in rows]
    for r in hits:
        assert r["support_after"] <= 0.5 * r["support_before"], r
        assert r["overall_after"] <= 0.7 * r["overall_before"], r


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
