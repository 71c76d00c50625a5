"""The report's "What next" (issue 22, item 7): which data would separate the remaining candidates
and which effect to try next, read off the analysis -- each rule on a report that triggers it and
only it (a complete record with nothing left asks for nothing), so a rule that fires on the wrong
evidence, or advice that does not follow the numbers, fails here."""
import copy

import pytest

from reference_py.discrepancy.nextsteps import render, what_next

PHASES = ("out_of_tissue", "loading", "insertion", "dwell", "reversal", "retraction", "after_exit")


def _trial(name: str, speed: float) -> dict:
    return {"name": name, "speed_mm_s": speed, "rate_hz": 100.0, "cycles": 1,
            "phase_samples": {ph: 200 for ph in PHASES}}


def _complete() -> dict:
    """Three trials at two speeds, 10 s dwells, a retraction and air after the exit; relaxation
    (tau_slow 2 s) and pre-sliding named, nothing unexplained, nothing flagged."""
    return {
        "named": ["layer_puncture", "dwell_relaxation", "reversal_presliding"],
        "effects": [
            {"name": "layer_puncture", "parameters": {"layers_per_trial": [1, 1, 1]}},
            {"name": "dwell_relaxation", "parameters": {"tau_fast_s [s]": 0.3,
                                                        "tau_slow_s [s]": 2.0},
             "candidates": [{"name": "dwell_relaxation", "delta_bic": 900.0}]},
            {"name": "reversal_presliding", "parameters": {"presliding_mm [mm]": 1.5},
             "candidates": [{"name": "reversal_presliding", "delta_bic": 300.0},
                            {"name": "direction_asymmetry", "delta_bic": 2.0}]}],
        "trials": [_trial("a", 1.0), _trial("b", 2.0), _trial("c", 3.0)],
        "local_evidence": {"distinct_speeds": 3, "per_trial": [
            {"dwells": [{"duration_s": 10.0}], "air_drift": {"available": 1.0}}
            for _ in range(3)]},
        "final_round": [{"name": "sensor_drift", "delta_bic": -3.0}],
        "flags": [], "verdict": {"unexplained": False, "where": []},
        "validation": {"scheme": "first half of the trials fitted, second half held out"},
        "heldout_scheme": "whole trials (leave one out)"}


def _stretch(phase: str, shape: str, **kw: float) -> dict:
    w = {"trial": "b", "phase": phase, "t_from_s": 10.0, "t_to_s": 11.0, "over_noise": 12.0,
         "looks_like": shape, "at_s": 10.4, "at_depth_mm": 12.0, "size_n": -0.5,
         "frequency_hz": 0.0, "description": f"a {shape}"}
    w.update(kw)
    return w


def _flag(parameter: str, value: float, kind: str = "at_bound", side: str = "upper",
          **kw: object) -> dict:
    f = {"parameter": parameter, "trial": None, "value": value, "fit": "final", "kind": kind}
    if kind == "at_bound":
        f.update(side=side, bound=value)
    f.update(kw)
    return f


def _set_param(rep: dict, effect: str, key: str, value: float) -> None:
    next(e for e in rep["effects"] if e["name"] == effect)["parameters"][key] = value


def _one_speed(rep: dict) -> None:
    rep["local_evidence"]["distinct_speeds"] = 1
    for t in rep["trials"]:
        t["speed_mm_s"] = 2.0


def _no_dwell(rep: dict) -> None:
    rep["named"].remove("dwell_relaxation")
    rep["effects"] = [e for e in rep["effects"] if e["name"] != "dwell_relaxation"]
    for t in rep["trials"]:
        t["phase_samples"]["dwell"] = 0
    for t in rep["local_evidence"]["per_trial"]:
        t["dwells"] = []


def _tau_slow_at_bound(rep: dict) -> None:
    _set_param(rep, "dwell_relaxation", "tau_slow_s [s]", 30.0)
    rep["flags"].append(_flag("tau_slow_s", 30.0))


def _short_dwell(rep: dict) -> None:
    _set_param(rep, "dwell_relaxation", "tau_slow_s [s]", 4.0)
    for t in rep["local_evidence"]["per_trial"]:
        t["dwells"][0]["duration_s"] = 5.26


def _ends_in_hold(rep: dict) -> None:
    rep["named"].remove("reversal_presliding")
    rep["effects"] = [e for e in rep["effects"] if e["name"] != "reversal_presliding"]
    for t in rep["trials"]:
        t["cycles"] = 0
        for ph in ("reversal", "retraction", "after_exit"):
            t["phase_samples"][ph] = 0
    for t in rep["local_evidence"]["per_trial"]:
        t["air_drift"]["available"] = 0.0


def _no_air_after(rep: dict) -> None:
    for t in rep["trials"]:
        t["phase_samples"]["after_exit"] = 0
    for t in rep["local_evidence"]["per_trial"]:
        t["air_drift"]["available"] = 0.0


def _asymmetry_in_play(rep: dict) -> None:
    rep["final_round"].append({"name": "direction_asymmetry", "delta_bic": 40.0,
                               "rejected": "does not improve its own phases"})


def _asymmetry_in_play_two_cycles(rep: dict) -> None:
    _asymmetry_in_play(rep)
    for t in rep["trials"]:
        t["cycles"] = 2


def _one_trial(rep: dict) -> None:
    rep["trials"] = rep["trials"][:1]
    rep["local_evidence"]["per_trial"] = rep["local_evidence"]["per_trial"][:1]
    rep["local_evidence"]["distinct_speeds"] = 1
    rep["validation"] = {"scheme": "needs >= 2 trials"}
    rep["heldout_scheme"] = "time blocks (0.5 s, 3 folds)"


def _too_short_for_motion(rep: dict) -> None:
    rep["final_round"].append({"name": "tissue_motion", "delta_bic": -8.0,
                               "local": "records too short for a periodicity test"})


def _tau_fast_at_floor(rep: dict) -> None:
    _set_param(rep, "dwell_relaxation", "tau_fast_s [s]", 0.05)
    rep["flags"].append(_flag("tau_fast_s", 0.05, side="lower"))


def _presliding_at_bound(rep: dict) -> None:
    _set_param(rep, "reversal_presliding", "presliding_mm [mm]", 10.0)
    rep["flags"].append(_flag("presliding_mm", 10.0))


# (case, change, data items as (source, words in the suggestion), effect items likewise)
DATA_CASES = [
    ("complete record", lambda r: None, [], []),
    ("one speed", _one_speed,
     [("local_evidence.distinct_speeds", ["2 mm/s", "1 or 4 mm/s"])], []),
    ("no dwell", _no_dwell, [("trials.phase_samples.dwell", ["15 s"])], []),
    ("tau_slow at its bound", _tau_slow_at_bound,
     [("flags.tau_slow_s, local_evidence.dwells", ["at least 90 s", "now is 10 s"])],
     [("flags.tau_slow_s", ["sensor_drift"])]),
    ("dwell shorter than 3 tau_slow", _short_dwell,
     [("flags.tau_slow_s, local_evidence.dwells", ["at least 12 s", "now is 5.26 s"])], []),
    ("ends in its hold", _ends_in_hold, [("trials.phase_samples", ["6 mm"])], []),
    ("no air after the exit", _no_air_after,
     [("local_evidence.per_trial.air_drift", ["2 s"])], []),
    ("asymmetry and pre-sliding, one cycle", _asymmetry_in_play,
     [("trials.cycles, candidates", ["second"])], []),
    ("asymmetry and pre-sliding, two cycles", _asymmetry_in_play_two_cycles, [], []),
    ("one trial", _one_trial,
     [("local_evidence.distinct_speeds", ["1 mm/s"]),
      ("validation.scheme, heldout_scheme", ["3 trials"])], []),
    ("too short for a periodicity test", _too_short_for_motion,
     [("final_round.tissue_motion.local", ["20 s", "0.1 Hz"])], []),
    ("tau_fast at its floor", _tau_fast_at_floor,
     [("flags.tau_fast_s", ["60 Hz", "100 Hz"])], []),
    ("pre-sliding length at its bound", _presliding_at_bound,
     [("flags.presliding_mm", ["at least 30 mm"])],
     [("flags.presliding_mm", ["direction_asymmetry"])]),
]


@pytest.mark.parametrize("case, change, data, effects", DATA_CASES,
                         ids=[c[0] for c in DATA_CASES])
def test_each_rule_fires_on_its_evidence_only(case, change, data, effects):
    rep = _complete()
    change(rep)
    wn = what_next(rep)
    assert [d["source"] for d in wn["data"]] == [s for s, _ in data], (case, wn["data"])
    assert [d["source"] for d in wn["effects"]] == [s for s, _ in effects], (case, wn["effects"])
    for got, (_, words) in zip(wn["data"] + wn["effects"], data + effects):
        for w in words:
            assert w in got["suggest"] + " " + got["because"], (case, w, got)


# (case, stretch, flags of the base fit, named, what the effect item must say, its candidates)
STRETCH_CASES = [
    ("a step on the way out", _stretch("retraction", "drop"), "layer letting go",
     ["0.5 N", "12 mm", "not in the vocabulary"], []),
    ("a drop while inserting", _stretch("insertion", "drop", at_depth_mm=8.0), "extra layer",
     ["8 mm", "layer_puncture"], ["layer_puncture"]),
    ("a drop that comes back", _stretch("insertion", "drop", until_s=10.8), "another depth",
     ["rupture"], ["layer_puncture"]),
    ("a slope change after ruptures", _stretch("insertion", "slope change"), "cutting force",
     ["post-rupture"], ["layer_puncture"]),
    ("a breathing line", _stretch("insertion", "oscillation", frequency_hz=0.25),
     "tissue_motion", ["0.25 Hz"], ["tissue_motion"]),
    ("a fast oscillation", _stretch("retraction", "oscillation", frequency_hz=1.5),
     "stick-slip", ["1.5 Hz", "not in the vocabulary"], []),
    ("a trend in the air", _stretch("after_exit", "trend"), "sensor_drift", ["sensor_drift"],
     ["sensor_drift"]),
    ("a turn-over without pre-sliding named", _stretch("reversal", "slope change"),
     "direction_asymmetry", ["direction_asymmetry"], ["direction_asymmetry"]),
]


@pytest.mark.parametrize("case, stretch, key, words, candidates", STRETCH_CASES,
                         ids=[c[0] for c in STRETCH_CASES])
def test_effect_to_try_follows_the_largest_stretch(case, stretch, key, words, candidates):
    rep = _complete()
    rep["verdict"] = {"unexplained": True, "where": [
        {k: v for k, v in stretch.items() if k not in ("looks_like",)},   # not described
        stretch]}
    wn = what_next(rep)
    assert len(wn["effects"]) == 1 and wn["effects"][0]["source"] == "verdict.where[1]", wn
    item = wn["effects"][0]
    assert key in item["suggest"], (case, item)
    for w in words:
        assert w in item["suggest"] + " " + item["because"], (case, w, item)
    assert item["candidates"] == candidates
    assert item["because"].startswith(f"{stretch['phase']} of b, 10-11 s, 12x the noise")
    assert not wn["explained"]


def test_stretches_alike_are_one_item_and_shapeless_ones_none():
    rep = _complete()
    rep["verdict"] = {"unexplained": True, "where": [
        _stretch("retraction", "drop", trial=t) for t in ("a", "b", "c")] + [
        _stretch("dwell", "no simple shape")]}
    wn = what_next(rep)
    assert len(wn["effects"]) == 1
    assert wn["effects"][0]["because"].endswith("(and 2 more stretches like it)")
    rep["verdict"]["where"] = [_stretch("dwell", "no simple shape")]
    wn = what_next(rep)
    assert wn["effects"] == []
    assert "none read off the residual" in "\n".join(render(wn))


def test_a_surface_at_its_bound_points_to_tenting():
    rep = _complete()
    rep["flags"] = [dict(_flag("surface", 1.5), fit="base", trial=t) for t in ("a", "c")]
    wn = what_next(rep)
    assert [d["source"] for d in wn["effects"]] == ["flags.surface"]
    assert "tenting" in wn["effects"][0]["suggest"]
    assert "1.5 mm" in wn["effects"][0]["because"] and "a, c" in wn["effects"][0]["because"]


def test_a_named_effect_is_not_suggested_again():
    rep = _complete()
    rep["named"].append("tissue_motion")
    rep["verdict"] = {"unexplained": True, "where": [
        _stretch("insertion", "oscillation", frequency_hz=0.25)]}
    item = what_next(rep)["effects"][0]
    assert not item["suggest"].startswith("tissue_motion") and "stick-slip" in item["suggest"]


def test_rendered_section_lists_every_item():
    rep = _complete()
    _one_speed(rep)
    _ends_in_hold(rep)
    rep["verdict"] = {"unexplained": True, "where": [_stretch("insertion", "drop")]}
    wn = what_next(rep)
    md = render(copy.deepcopy(wn))
    assert md[0] == "## What next"
    for d in wn["data"] + wn["effects"]:
        assert f"- {d['suggest']} -- because {d['because']} (from {d['source']})" in md
    explained = what_next(_complete())
    text = "\n".join(render(explained))
    assert "nothing the record lacks" in text and "no structure above the threshold" in text


def test_an_effect_that_spoils_an_explained_phase_is_questioned():
    rep = _complete()
    rep["effects"][2]["worsens"] = {"phase": "after_exit", "rmse_before_n": 0.026,
                                    "rmse_after_n": 0.264, "allowance_x_noise": 3.0}
    wn = what_next(rep)
    assert [d["source"] for d in wn["effects"]] == ["effects[2].worsens"]
    item = wn["effects"][0]
    assert item["suggest"].startswith("reversal_presliding in another form, or without it")
    assert "after_exit" in item["suggest"] and "0.026 -> 0.264 N" in item["because"]
    assert item["candidates"] == ["reversal_presliding"]
