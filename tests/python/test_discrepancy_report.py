"""report.md, report.json and estimator_config.json tell one story (issue 22, items 3 and 7):
the gap table has one column per model, each effect's gap starts where the previous one ended,
every number the three files share is the same, and values at a bound of their fit or with a
standard error above them are flagged."""
import dataclasses
import json
import os
import pickle
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from reference_py.discrepancy.effects import EFFECT_NL
from reference_py.discrepancy.report import AT_BOUND_FRAC, build, check_parameter, render_md
from test_config_loop import loop_records


_RUN = """
import pickle, sys
from reference_py.discrepancy.io import read_trial
from reference_py.discrepancy.report import write
from reference_py.discrepancy.workflow import run
out, files = sys.argv[1], sys.argv[2:]
res = run([read_trial(f) for f in files])
write(res, files, __import__("pathlib").Path(out), with_figures=False)
with open(out + ".pickle", "wb") as fh:
    pickle.dump(res, fh)
"""


@pytest.fixture(scope="module")
def phantom(tmp_path_factory):
    """Three phantom insertions (skin on muscle: two layers, dwell, reversal), one report.  The
    workflow runs in a child with one BLAS thread, as the command does (many small solves)."""
    d = tmp_path_factory.mktemp("report")
    files = [str(f) for f in loop_records(d, (1, 2, 3)).values()]
    out = d / "out"
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    subprocess.run([sys.executable, "-c", _RUN, str(out)] + files, check=True, env=env,
                   cwd=str(Path(__file__).resolve().parents[2]), capture_output=True)
    with open(str(out) + ".pickle", "rb") as fh:
        res = pickle.load(fh)
    return {"res": res, "files": files, "out": out,
            "rep": json.loads((out / "report.json").read_text()),
            "md": (out / "report.md").read_text(),
            "cfg": json.loads((out / "estimator_config.json").read_text())}


def _section(md: str, head: str) -> list[str]:
    lines = md.splitlines()
    i = next(j for j, l in enumerate(lines) if l.startswith(head))
    out = []
    for l in lines[i + 1:]:
        if l.startswith("#"):
            break
        out.append(l)
    return out


def _table(lines: list[str]) -> list[list[str]]:
    rows = [[c.strip() for c in l.strip().strip("|").split("|")] for l in lines
            if l.startswith("|")]
    return [r for r in rows if not all(set(c) <= {"-"} and c for c in r)]


def _close(md_text: str, value: float) -> bool:
    """A number printed with 4 significant digits against the full value."""
    return float(md_text) == pytest.approx(value, rel=6e-4, abs=1e-12)


def test_gap_table_one_header_per_column(phantom):
    rows = _table(_section(phantom["md"], "## 5."))
    head, body = rows[0], rows[1:]
    assert head[0] == "phase" and len(head) - 1 == len(phantom["rep"]["errors"])
    assert head[1:] == phantom["rep"]["gap_models"]
    assert body and all(len(r) == len(head) for r in body), (head, body)
    # one model per named effect after the base, in the order of discovery
    assert head[1] == "base" and head[2:] == [f"+{n}" for n in phantom["rep"]["named"]]
    # every cell is the report.json value of its column
    for r in body:
        for cell, err in zip(r[1:], phantom["rep"]["errors"]):
            rmse, mae = cell.split(" / ")
            assert _close(rmse, err[r[0]]["rmse_n"]) and _close(mae, err[r[0]]["mae_n"])


def test_each_effect_starts_where_the_previous_ended(phantom):
    rep = phantom["rep"]
    effects = rep["effects"]
    assert [e["name"] for e in effects] == rep["named"]
    assert effects[0]["name"] == "layer_puncture"
    # the one-layer base is before the layers: not the same model
    assert effects[0]["errors_before"] == rep["errors"][0]
    assert effects[0]["errors_before"] != effects[0]["errors_after"]
    for j, e in enumerate(effects):
        assert e["errors_before"] == rep["errors"][j] and e["errors_after"] == rep["errors"][j + 1]
        if j:
            assert e["errors_before"] == effects[j - 1]["errors_after"], e["name"]
    # the dwell effect's own phase falls in its own column (not under another effect's name)
    k = rep["named"].index("dwell_relaxation")
    d = effects[k]
    assert d["errors_after"]["dwell"]["rmse_n"] < 0.5 * d["errors_before"]["dwell"]["rmse_n"]


def test_json_md_and_config_agree(phantom):
    rep, md, cfg = phantom["rep"], phantom["md"], phantom["cfg"]
    # the config is the report's export, number for number
    assert rep["export"] == cfg
    assert rep["base_model"]["params"] == cfg["params"]
    assert [t["surface_fitted_mm"] for t in rep["trials"]] == cfg["surface_mm"]
    assert [t["tare_n"] for t in rep["trials"]] == cfg["tare_n"]
    for t, s in zip(rep["trials"], cfg["surface_mm"]):
        assert t["surface_offset_mm"] + t["surface_correction_mm"] == pytest.approx(s, abs=1e-12)
    for e in rep["effects"]:
        if e["name"] == "layer_puncture":
            continue
        exported = cfg["effects"][e["name"]]
        assert exported, e["name"]
        for par, v in exported.items():
            key = next(k for k in e["parameters"] if k == par or k.startswith(par + " ["))
            assert e["parameters"][key] == v, (e["name"], par)
        # every shared nonlinear parameter of the effect is exported
        for p in EFFECT_NL[e["name"]]:
            assert p.per_trial or p.name in exported
    # report.md: base parameters as written to the config
    base = {}
    for l in _section(md, "## 1. Base model"):
        m = re.match(r"- (\w+) = (\S+)", l)
        if m and m.group(1) in cfg["params"]:
            base[m.group(1)] = m.group(2)
    assert set(base) == set(cfg["params"])
    for k, v in base.items():
        assert _close(v, cfg["params"][k]), k
    # report.md: the fitted surfaces and tares are the config's
    rows = _table(_section(md, "## Trials"))
    head = rows[0]
    i_s, i_t = head.index("surface fitted mm"), head.index("tare N")
    for r, s, tare in zip(rows[1:], cfg["surface_mm"], cfg["tare_n"]):
        assert _close(r[i_s], s) and _close(r[i_t], tare)
    # report.md: each effect's parameters are the config's
    for name, pars in cfg["effects"].items():
        sec = _section(md, f"### Effect {rep['named'].index(name) + 1}: `{name}`")
        for par, v in pars.items():
            line = next(l for l in sec if re.match(rf"- {re.escape(par)}( \[[^]]*\])? = ", l))
            assert _close(line.rsplit(" = ", 1)[1], v), (name, par, line)
    # and report.md is report.json rendered
    assert md == render_md(rep, rep["figures"])


@pytest.mark.parametrize("args,kinds", [
    (("tau_fast_s", 0.050, 0.05, 1.0), {"at_bound"}),
    (("tau_slow_s", 1.017, 1.0, 30.0), {"at_bound"}),
    (("presliding_mm", 10.0, 0.05, 10.0), {"at_bound"}),
    (("tau_slow_s", 3.54, 1.0, 30.0, 9.19), {"se_above_value"}),
    (("tau_slow_s", 1.0, 1.0, 30.0, 9.19), {"at_bound", "se_above_value"}),
    (("tau_slow_s", 3.54, 1.0, 30.0, 0.3), set()),
    (("surface", 1.5, -1.5, 1.5, 0.01, False), {"at_bound"}),
    (("surface", -1.5, -1.5, 1.5, None, False), {"at_bound"}),
    (("surface", 0.02, -1.5, 1.5, 0.5, False), set()),      # a signed correction: no se test
    (("sigma2", 0.0, 0.0, np.inf, None, False), {"at_bound"}),
    (("sigma2", 0.004, 0.0, np.inf, None, False), set()),
])
def test_flagging_function(args, kinds):
    flags = check_parameter(*args)
    assert {f["kind"] for f in flags} == kinds
    for f in flags:
        assert f["parameter"] == args[0] and f["value"] == args[1]
        assert ("bound" in f) == (f["kind"] == "at_bound")
        assert ("se" in f) == (f["kind"] == "se_above_value")


def test_report_flags_every_value_at_a_bound(phantom):
    """Each reported nonlinear value in the at-bound zone is in ``flags`` and in report.md."""
    rep, res = phantom["rep"], phantom["res"]
    flagged = {(f["parameter"], f["trial"], f["fit"]) for f in rep["flags"]
               if f["kind"] == "at_bound"}
    names = [p.name for p in res.preps]
    from reference_py.discrepancy.effects import BASE_NL
    specs = [(p, res.fits[0], "base") for p in BASE_NL] + \
        [(p, res.fits[-1], "final") for s in res.steps for p in EFFECT_NL[s.effect]
         if p.flag_bounds]      # a share at 0 or 1 is a finding, not a fit held back
    for par, f, fit_name in specs:
        for i, v in enumerate(np.atleast_1d(f.nl[par.name])):
            lo, hi, v = (np.log(par.lo), np.log(par.hi), np.log(v)) if par.log else \
                (par.lo, par.hi, v)
            if min(v - lo, hi - v) <= AT_BOUND_FRAC * (hi - lo):
                key = (par.name, names[i] if par.per_trial else None, fit_name)
                assert key in flagged, key
    md_flags = [l for l in phantom["md"].splitlines() if l.startswith("- FLAG ")]
    for f in rep["flags"]:
        assert any(l.startswith(f"- FLAG {f['parameter']} ") for l in md_flags), f


def test_constructed_fit_at_bound_is_flagged_and_exported_as_reported(phantom):
    """A relaxation whose slow time constant ended at its upper bound, with a standard error
    larger than it: flagged in report.json and report.md; the config writes the same value."""
    res = phantom["res"]
    assert "dwell_relaxation" in [s.effect for s in res.steps]
    final = res.fits[-1]
    nl = dict(final.nl, tau_slow_s=np.array(30.0), tau_fast_s=np.array(0.5))
    se = dict(final.nl_se or {}, tau_fast_s=np.array(0.9))
    res2 = dataclasses.replace(res, fits=res.fits[:-1] + [dataclasses.replace(final, nl=nl,
                                                                               nl_se=se)])
    rep = json.loads(json.dumps(build(res2, phantom["files"])))
    got = {(f["parameter"], f["kind"]) for f in rep["flags"] if f["fit"] == "final"}
    assert ("tau_slow_s", "at_bound") in got
    assert ("tau_fast_s", "se_above_value") in got and ("tau_fast_s", "at_bound") not in got
    at = next(f for f in rep["flags"] if f["parameter"] == "tau_slow_s")
    assert at["value"] == 30.0 and at["bound"] == 30.0 and at["side"] == "upper"
    sef = next(f for f in rep["flags"] if f["parameter"] == "tau_fast_s")
    assert sef["se"] == 0.9 and sef["value"] == 0.5
    md = render_md(rep, [])
    assert "- FLAG tau_slow_s = 30 at its upper bound 30 (final fit)" in md
    assert "- FLAG tau_fast_s = 0.5 with standard error 0.9 above it (final fit)" in md
    assert rep["export"]["effects"]["dwell_relaxation"]["tau_slow_s"] == 30.0
    k = rep["named"].index("dwell_relaxation")
    assert rep["effects"][k]["parameters"]["tau_slow_s [s]"] == 30.0


def test_no_flags_said_plainly(phantom):
    rep = dict(phantom["rep"], flags=[])
    assert "No fitted value is at a bound or has a standard error above it." in \
        render_md(rep, [])


def test_every_refused_candidate_says_why(phantom):
    """Each round's candidate table has a last column with the reason of a refusal, the last
    round's candidates included (why nothing more was named)."""
    refused = {"name": "sensor_drift", "delta_bic": 12.5, "heldout_gain": -0.25,
               "rejected": "does not improve its own phases"}
    rep = dict(phantom["rep"], final_round=[*phantom["rep"]["final_round"], refused])
    md = render_md(rep, [])
    rounds = [e.get("candidates", []) for e in rep["effects"]] + [rep["final_round"]]
    heads = [f"### Effect {k + 1}:" for k in range(len(rep["effects"]))]
    for head, cands in zip(heads + ["### The last round's candidates"], rounds):
        table = _table(_section(md, head))
        assert table[0] == ["candidate", "delta BIC", "held-out gain", "refused because"], head
        assert [row[3] for row in table[1:]] == [c.get("rejected", "") for c in cands], head
    assert _table(_section(md, "### The last round's candidates"))[-1] == [
        "sensor_drift", "12.5", "-0.25", "does not improve its own phases"]


def test_unexplained_stretches_say_what_they_look_like(phantom):
    # this record set leaves structure (the verdict is "unexplained"): the largest stretches are
    # described, the verdict line quotes the first, report.md tables them from report.json
    v = phantom["rep"]["verdict"]
    assert v["unexplained"] is True
    described = [w for w in v["where"] if "looks_like" in w]
    assert described and described[0] == v["where"][0]
    assert {w["looks_like"] for w in described} <= {"drop", "rise", "slope change", "oscillation",
                                                     "trend", "no simple shape"}
    assert v["text"].endswith(f"it looks like {described[0]['description']})")
    sec = _section(phantom["md"], "Where the residual stays above the threshold")
    block = sec[1:sec.index("", 1)]                     # the table, up to its blank line
    header, *rows = _table(block)
    assert header[-1] == "looks like"
    assert len(rows) == min(len(described), 5)
    for row, w in zip(rows, described):
        assert row[0] == w["trial"] and row[1] == w["phase"] and row[5] == w["description"]


def test_what_next_is_read_off_the_report(phantom):
    """report.json's "what_next" is the advice of the report's own numbers (recomputed from the
    other fields it is the same), report.md renders it, and it follows the record: one speed
    here, so another speed is asked for -- and not once the evidence has two."""
    import copy

    from reference_py.discrepancy.nextsteps import render, what_next
    rep, md = phantom["rep"], phantom["md"]
    src = {k: v for k, v in rep.items() if k not in ("what_next", "figures", "estimator_config")}
    assert rep["what_next"] == what_next(src)
    sec = "\n".join(["## What next"] + _section(md, "## What next")).strip()
    assert sec == "\n".join(render(rep["what_next"])).strip()
    speeds = {t["speed_mm_s"] for t in rep["trials"]}
    assert rep["local_evidence"]["distinct_speeds"] == 1 and len(speeds) == 1
    ask = [d for d in rep["what_next"]["data"] if d["source"] == "local_evidence.distinct_speeds"]
    assert len(ask) == 1 and f"{speeds.pop():.3g} mm/s" in ask[0]["suggest"]
    assert ask[0]["candidates"] == ["velocity_friction"]
    # the verdict is "unexplained": each effect to try that cites a stretch quotes it
    assert rep["verdict"]["unexplained"] and rep["what_next"]["effects"]
    for d in rep["what_next"]["effects"]:
        if d["source"].startswith("verdict.where["):
            w = rep["verdict"]["where"][int(d["source"][len("verdict.where["):-1])]
            assert w["description"] in d["because"] and w["looks_like"] != "no simple shape"
    two = copy.deepcopy(src)
    two["local_evidence"]["distinct_speeds"] = 2
    assert all(d["source"] != "local_evidence.distinct_speeds" for d in what_next(two)["data"])
