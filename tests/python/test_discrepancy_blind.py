"""Blind tests: data with a hidden effect in a form the workflow may not have been written for,
generated in tests only (discrepancy_generator.py), graded on what the workflow names first, on
how much of the gap to the noise-free truth it closes, on the bounds of what it reports and on its
"unexplained" verdict.

The CI subset is the first CI_CASES cases of every kind (each effect form, none, the relaxation +
pre-sliding pair, stick-slip): 4 x 23 = 92 cases, run once for the module in two processes. The
full run (20 cases per kind) is ``tests/python/discrepancy_confusion.py --full``; it prints
the confusion matrix per form and restricted to the held-out forms.  Targets are the issue's;
a shortfall is a strict xfail carrying the figure measured on the CI subset, so the mark must go
once it passes.

DISCREPANCY_BLIND_CASES=N runs N cases per kind instead (20 = the full run);
DISCREPANCY_RESULTS=FILE writes the per-case rows as JSON; DISCREPANCY_REGRADE=FILE grades such a
file instead of running the cases (the cases and the workflow are deterministic).
"""
import json
import os

import pytest

from discrepancy_generator import EFFECTS, FORMS, OOV, jobs_for, run_all, verdict_against_truth

CI_CASES = 4

#: measured shortfalls (CI subset); strict: the mark must go once the target is met
NAMING_XFAIL: dict[str, str] = {
    "dwell_relaxation": "named first 10/12 (prony_dwell 3/4: tissue_motion 1x; power_law 3/4: "
                        "layer_puncture 1x), target >= 90 %",
    "direction_asymmetry": "named first 4/8 (constant 2/4, depth 2/4; 'none' 3x, layer_puncture "
                           "1x), target >= 90 %",
}
HELD_OUT_XFAIL: dict[str, str] = {
    "direction_asymmetry": "held-out form (depth) named first 2/4, target >= 85 %",
}
_SHRINK = "cases named first with RMSE vs truth -50 % in its phases and -30 % overall: "
SHRINK_XFAIL: dict[str, str] = {
    "dwell_relaxation": _SHRINK + "4/10 (prony_dwell 3/3; maxwell_total and power_law: -3..-30 %, "
                                  "the library's dwell-only form on a relaxation acting all along)"
                                  ", target all",
    "velocity_friction": _SHRINK + "10/11 (stribeck k=0: phases -28 %), target all",
    "layer_puncture": _SHRINK + "0/12 (ruptures are detected and fitted in the base model, so "
                                "the effect step adds nothing: 0..-4 %), target all",
    "sensor_drift": _SHRINK + "5/8 (linear k=0 -7 %, random_walk k=0 -21 %, warmup k=3 -23 %), "
                              "target all",
    "tissue_motion": _SHRINK + "4/12 (sinusoid k=0..3 -11..-50 %, respiratory k=1, 3 -42 %, "
                               "-46 %, irregular k=1, 3 -40 %, -29 %), target all",
}
NONE_XFAIL = ""
PAIR_XFAIL = "relaxation + pre-sliding both named in 3/4 (k=3, maxwell_total + elastoplastic: " \
             "pre-sliding not named), target >= 85 %"
BOUNDS_XFAIL = ""
UNEXPLAINED_FIRES_XFAIL = "stick-slip flagged 'unexplained' in 2/4 (k=0, k=2 explained by a " \
                          "detected layer), target >= 90 %"


def _params(xfails: dict[str, str]) -> list:
    return [pytest.param(e, marks=pytest.mark.xfail(strict=True, reason=xfails[e]))
            if e in xfails else e for e in EFFECTS]


def _mark(reason: str):  # type: ignore[no-untyped-def]
    return pytest.mark.xfail(strict=True, reason=reason) if reason else (lambda f: f)


@pytest.fixture(scope="module")
def results() -> list[dict]:
    cached = os.environ.get("DISCREPANCY_REGRADE")
    if cached:
        with open(cached) as fh:
            return json.load(fh)
    cases = int(os.environ.get("DISCREPANCY_BLIND_CASES", CI_CASES))
    res = run_all(jobs_for(cases), workers=2)
    out = os.environ.get("DISCREPANCY_RESULTS")
    if out:
        with open(out, "w") as fh:
            json.dump(res, fh)
    return res


def _rows(results: list[dict], effect: str, held_out_only: bool = False) -> list[dict]:
    rows = [r for r in results if r["kind"].split("/")[0] == effect and "/" in r["kind"]
            and (r["held_out"][effect] or not held_out_only)]
    assert rows, effect
    return rows


def _summary(rows: list[dict]) -> list[str]:
    return [f"{r['kind']}#{r['k']}: {','.join(r['named'])}" for r in rows]


def test_every_form_is_drawn(results: list[dict]) -> None:
    kinds = {r["kind"] for r in results}
    for e in EFFECTS:
        for f in FORMS[e]:
            assert f"{e}/{f.name}" in kinds
    assert {"none", "pair", OOV} <= kinds
    pair_forms = {tuple(sorted(r["forms"].values())) for r in results if r["kind"] == "pair"}
    assert len(pair_forms) >= 2


@pytest.mark.parametrize("effect", _params(NAMING_XFAIL))
def test_hidden_effect_named_first(results: list[dict], effect: str) -> None:
    """>= 90 % of the cases of an effect, over all its forms, name it first."""
    rows = _rows(results, effect)
    hits = [r for r in rows if r["first"] == effect]
    assert len(hits) >= 0.9 * len(rows), _summary(rows)


@pytest.mark.parametrize("effect", _params(HELD_OUT_XFAIL))
def test_held_out_forms_named_first(results: list[dict], effect: str) -> None:
    """>= 85 % of the cases in forms the library does not contain name the effect first."""
    rows = _rows(results, effect, held_out_only=True)
    hits = [r for r in rows if r["first"] == effect]
    assert len(hits) >= 0.85 * len(rows), _summary(rows)


@pytest.mark.parametrize("effect", _params(SHRINK_XFAIL))
def test_gap_shrinks_when_named_first(results: list[dict], effect: str) -> None:
    """Every case where the hidden effect is named first: RMSE vs the noise-free truth falls by
    >= 50 % where the effect acts and by >= 30 % overall."""
    hits = [r for r in _rows(results, effect) if r["first"] == effect]
    assert hits
    bad = [r for r in hits if not (r["support_after"] <= 0.5 * r["support_before"]
                                   and r["overall_after"] <= 0.7 * r["overall_before"])]
    assert not bad, [(r["kind"], r["k"], round(1 - r["support_after"] / r["support_before"], 2),
                      round(1 - r["overall_after"] / r["overall_before"], 2)) for r in bad]


@_mark(NONE_XFAIL)
def test_no_hidden_effect_reports_none(results: list[dict]) -> None:
    rows = [r for r in results if r["kind"] == "none"]
    ok = sum(1 for r in rows if r["named"] == ["none"])
    assert rows and ok >= 0.9 * len(rows), _summary(rows)


@_mark(PAIR_XFAIL)
def test_two_hidden_effects_both_named(results: list[dict]) -> None:
    rows = [r for r in results if r["kind"] == "pair"]
    ok = sum(1 for r in rows if set(r["effects"]) <= set(r["named"]))
    assert rows and ok >= 0.85 * len(rows), _summary(rows)


@_mark(BOUNDS_XFAIL)
def test_no_parameter_outside_its_bounds(results: list[dict]) -> None:
    """Over the whole blind set: no named effect's and no base parameter outside the bounds the
    report documents, no layer outside the inserted depth, no drop above the peak."""
    bad = [(r["kind"], r["k"], r["violations"][:3]) for r in results if r["violations"]]
    assert not bad, (len(bad), bad[:8])


@_mark(UNEXPLAINED_FIRES_XFAIL)
def test_unexplained_fires_on_stick_slip(results: list[dict]) -> None:
    """A stick-slip oscillation is outside the vocabulary: the verdict says 'unexplained'."""
    rows = [r for r in results if r["kind"] == OOV]
    fired = [r for r in rows if r["unexplained"] is True]
    assert rows and len(fired) >= 0.9 * len(rows), [(r["k"], r["unexplained"]) for r in rows]


def test_unexplained_follows_the_truth(results: list[dict]) -> None:
    """On the vocabulary's own cases (one effect, none, the pair) the verdict fires where the
    final model leaves structure and stays silent where it does not, in >= 90 % of each.  What
    is left is judged on the noise-free truth with the verdict's own rule
    (discrepancy_generator.left_structure): a form outside the library, or a fit that stopped
    short, leaves a stretch the verdict must report; a model that follows the truth leaves none
    and must not be called unexplained."""
    left, fits = verdict_against_truth([r for r in results if r["kind"] != OOV])
    fired = [r for r in left if r["unexplained"]]
    silent = [r for r in fits if not r["unexplained"]]
    # both kinds occur in the CI subset (47 and 41 of 88 when this was written): a subset
    # without one of them would not test that side
    assert len(left) >= 10 and len(fits) >= 10, (len(left), len(fits))
    assert len(fired) >= 0.9 * len(left), [(r["kind"], r["k"]) for r in left
                                           if not r["unexplained"]]
    assert len(silent) >= 0.9 * len(fits), [(r["kind"], r["k"]) for r in fits
                                            if r["unexplained"]]
