"""What to do next, read off the analysis (report.json's ``what_next``, report.md's "What next").

Two lists of items ``{"suggest", "because", "candidates", "source"}``, computed from the report's
own fields only (so report.md, report.json and this advice cannot disagree, and a test can check
each item against the numbers it cites in ``source``):

``data``: records that would separate the remaining candidates.  What the record lacks for a
    candidate that could not be judged -- one insertion speed (velocity friction is not even a
    candidate), no dwell, no retraction, no air after the exit, one trial, a record too short for
    a periodicity test -- what two candidates acting in the same phases need to be told apart (a
    second cycle: a re-insertion shows pre-sliding again but no asymmetry, a second hold restarts
    relaxation but not a drift), and what a flagged parameter of a named effect needs (a slow
    time constant at its bound or with a standard error above it: a longer dwell; a fast one at
    its bound: a higher sample rate; the pre-sliding length: a longer retraction).
``effects``: which effect to try next.  From the shape of the largest unexplained stretches
    (shape.py) and where they are -- a drop while inserting is a rupture the detector did not
    count; a rise or slope change after a rupture is a cutting force that builds up; a step on
    the way out is a layer letting go; an oscillation is tissue motion (0.1-0.6 Hz) or stick-slip;
    a trend in the air is a drift -- and from flagged base values (a surface correction at its
    bound: the surface moves with the needle, tenting) and from a named effect whose refit made a
    phase the model explained worse (report.json effects[].worsens).  An item names a vocabulary
    effect when one fits and is not named yet, else the pattern, marked "not in the vocabulary".
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from .effects import EFFECT_NL
from .evidence import REVERSAL_WINDOW_MM

#: two insertion speeds count as distinct above this relative difference (evidence.distinct_speeds)
SPEED_REL = 0.15
#: a hold asked for where the record has none (s): three times the slow relaxation time constant
#: measured on tissue (2-5 s, MODEL.md §8), so its decay is seen against a line
HOLD_S = 15.0
#: a dwell shorter than this many slow time constants leaves the slow branch unresolved
DWELL_TAUS = 3.0
#: the shortest slow relaxation time constant the fit searches (s)
TAU_SLOW_LO = min(p.lo for p in EFFECT_NL["dwell_relaxation"] if p.name == "tau_slow_s")
#: samples wanted within the fast relaxation time constant
SAMPLES_PER_TAU = 3.0
#: a retraction is asked to cover this many pre-sliding lengths
PRESLIDE_DELTAS = 3.0
#: air after the exit asked for (s), for the air-level (drift) evidence
AIR_S = 2.0
#: the slowest tissue-motion line tested (Hz; tissue_motion's frequency bound) and the periods of
#: it a record needs in the tissue
MOTION_F_LO = min(p.lo for p in EFFECT_NL["tissue_motion"] if p.name == "motion_freq_hz")
MOTION_F_HI = max(p.hi for p in EFFECT_NL["tissue_motion"] if p.name == "motion_freq_hz")
MOTION_PERIODS = 2.0
#: the largest this many described unexplained stretches are read for effects to try
STRETCHES = 5
#: a candidate counts as "in play" when some round scored it at least this delta BIC
#: (workflow.BIC_MIN) or named it
IN_PLAY_BIC = 10.0

_INSERT = ("loading", "insertion")
_BACK = ("reversal", "retraction")
_AIR = ("out_of_tissue", "after_exit")


def _item(suggest: str, because: str, candidates: list[str], source: str) -> dict[str, Any]:
    return {"suggest": suggest, "because": because, "candidates": candidates, "source": source}


def _num(x: Any) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return math.nan
    return v


def _param(rep: dict[str, Any], effect: str, name: str) -> float:
    """A named effect's reported parameter (report.json effects[].parameters), NaN if absent."""
    for e in rep.get("effects") or []:
        if e.get("name") == effect:
            for k, v in (e.get("parameters") or {}).items():
                if k.split(" [")[0] == name and "standard error" not in k:
                    return _num(v)
    return math.nan


def _flags(rep: dict[str, Any], parameter: str, kind: str | None = None,
           side: str | None = None) -> list[dict[str, Any]]:
    return [f for f in rep.get("flags") or [] if f.get("parameter") == parameter
            and (kind is None or f.get("kind") == kind) and (side is None or f.get("side") == side)]


def _rounds(rep: dict[str, Any]) -> list[dict[str, Any]]:
    """Every candidate row of every round (each named effect's round, then the last)."""
    rows = [c for e in rep.get("effects") or [] for c in e.get("candidates") or []]
    return rows + list(rep.get("final_round") or [])


def _in_play(rep: dict[str, Any], name: str) -> bool:
    """Named, or scored by some round as worth its parameters (delta BIC >= IN_PLAY_BIC)."""
    if name in (rep.get("named") or []):
        return True
    return any(c.get("name") == name and _num(c.get("delta_bic")) >= IN_PLAY_BIC
               for c in _rounds(rep))


def _phase_samples(rep: dict[str, Any], phase: str) -> int:
    return int(sum(int((t.get("phase_samples") or {}).get(phase, 0))
                   for t in rep.get("trials") or []))


def _dwells(rep: dict[str, Any]) -> list[dict[str, Any]]:
    ev = rep.get("local_evidence") or {}
    return [d for t in ev.get("per_trial") or [] for d in t.get("dwells") or []]


def _fmt(x: float) -> str:
    return f"{x:.3g}"


def data_items(rep: dict[str, Any]) -> list[dict[str, Any]]:
    """Records that would separate the remaining candidates (see the module's doc)."""
    out: list[dict[str, Any]] = []
    named = list(rep.get("named") or [])
    trials = rep.get("trials") or []
    ev = rep.get("local_evidence") or {}
    speeds = [_num(t.get("speed_mm_s")) for t in trials if _num(t.get("speed_mm_s")) > 0]
    n_speeds = int(_num(ev.get("distinct_speeds", len(set(speeds)))) or 0)
    if n_speeds < 2 and speeds:
        v = float(np.median(speeds))
        out.append(_item(
            f"trials at another insertion speed, more than {100 * SPEED_REL:.0f} % from "
            f"{_fmt(v)} mm/s (e.g. {_fmt(0.5 * v)} or {_fmt(2.0 * v)} mm/s)",
            f"velocity_friction cannot be a candidate with {n_speeds} distinct insertion speed: "
            "a friction that grows with speed is taken up by the base model's sigma2",
            ["velocity_friction"], "local_evidence.distinct_speeds"))
    dwells = _dwells(rep)
    if not dwells and _phase_samples(rep, "dwell") == 0:
        out.append(_item(
            f"a hold at full depth of at least {HOLD_S:.0f} s before the retraction",
            "dwell_relaxation cannot be a candidate: the record has no dwell",
            ["dwell_relaxation"], "trials.phase_samples.dwell"))
    elif dwells:
        longest = max(_num(d.get("duration_s")) for d in dwells)
        tau_s = _param(rep, "dwell_relaxation", "tau_slow_s")
        why = []
        for f in _flags(rep, "tau_slow_s"):
            why.append(f"tau_slow_s = {_fmt(_num(f.get('value')))} s " + (
                f"at its {f.get('side')} bound" if f.get("kind") == "at_bound" else
                f"with a standard error of {_fmt(_num(f.get('se')))} s"))
        if math.isfinite(tau_s) and longest < DWELL_TAUS * tau_s:
            why.append(f"the longest dwell ({_fmt(longest)} s) is shorter than "
                       f"{DWELL_TAUS:.0f} tau_slow")
        refused = [c for c in _rounds(rep) if c.get("name") == "dwell_relaxation"
                   and c.get("rejected") == "no local evidence"]
        if refused and "dwell_relaxation" not in named and \
                longest < DWELL_TAUS * TAU_SLOW_LO:
            why.append(f"no exponential decay was told from a line over {_fmt(longest)} s")
        if why:
            want = DWELL_TAUS * (tau_s if math.isfinite(tau_s) else HOLD_S / DWELL_TAUS)
            out.append(_item(
                f"a longer dwell: at least {_fmt(max(want, longest))} s "
                f"({DWELL_TAUS:.0f} tau_slow; the longest now is {_fmt(longest)} s)",
                "; ".join(why) + ": a slow relaxation and a drift look alike over it",
                ["dwell_relaxation", "sensor_drift"], "flags.tau_slow_s, local_evidence.dwells"))
    back = _phase_samples(rep, "reversal") + _phase_samples(rep, "retraction")
    if trials and back == 0:
        out.append(_item(
            f"a retraction of at least {REVERSAL_WINDOW_MM:.0f} mm after the hold",
            "reversal_presliding and direction_asymmetry live in the reversal and the "
            "retraction: the record ends before the needle moves back",
            ["reversal_presliding", "direction_asymmetry"], "trials.phase_samples"))
    delta = _param(rep, "reversal_presliding", "presliding_mm")
    pre_flags = _flags(rep, "presliding_mm")
    if pre_flags and math.isfinite(delta):
        f = pre_flags[0]
        out.append(_item(
            f"a retraction of at least {_fmt(PRESLIDE_DELTAS * delta)} mm "
            f"({PRESLIDE_DELTAS:.0f} presliding lengths)",
            f"presliding_mm = {_fmt(delta)} mm " + (
                f"at its {f.get('side')} bound" if f.get("kind") == "at_bound" else
                f"with a standard error of {_fmt(_num(f.get('se')))} mm") +
            ": the turn-over is not resolved within the retraction",
            ["reversal_presliding", "direction_asymmetry"], "flags.presliding_mm"))
    air = [t.get("air_drift") or {} for t in ev.get("per_trial") or []]
    if trials and back and _phase_samples(rep, "after_exit") < 5 and \
            not any(_num(a.get("available")) > 0 for a in air):
        out.append(_item(
            f"at least {AIR_S:.0f} s of record in the air after the needle leaves the tissue",
            "a sensor drift is told from the tissue's slow terms by the level in the air after "
            "the exit against the tare before contact: no trial has one",
            ["sensor_drift"], "local_evidence.per_trial.air_drift"))
    cycles = [int(_num(t.get("cycles"))) for t in trials if math.isfinite(_num(t.get("cycles")))]
    if cycles and max(cycles) <= 1:
        pairs = []
        if _in_play(rep, "reversal_presliding") and _in_play(rep, "direction_asymmetry"):
            pairs.append("reversal_presliding (a transient after every change of direction) and "
                         "direction_asymmetry (a retraction friction) act in the same phases: a "
                         "re-insertion shows pre-sliding again and no asymmetry")
        if _in_play(rep, "dwell_relaxation") and _in_play(rep, "sensor_drift"):
            pairs.append("dwell_relaxation restarts at each hold and a sensor drift does not")
        if pairs:
            both = sorted({n for n in ("reversal_presliding", "direction_asymmetry",
                                       "dwell_relaxation", "sensor_drift")
                           if any(n in p for p in pairs)})
            out.append(_item(
                "a second insertion-hold-retraction cycle in the same trial",
                "; ".join(pairs) + f" (at most {max(cycles)} reversal per trial)", both,
                "trials.cycles, candidates"))
    val = rep.get("validation") or {}
    if len(trials) < 3:
        out.append(_item(
            "at least 3 trials of the same needle and tissue",
            f"held-out validation: {val.get('scheme', '-')}; each candidate was checked on "
            f"{rep.get('heldout_scheme', '-')} (whole trials are left out with 3 or more)",
            [], "validation.scheme, heldout_scheme"))
    short = [c for c in _rounds(rep) if c.get("name") == "tissue_motion"
             and "too short" in str(c.get("local", ""))]
    if short and "tissue_motion" not in named:
        out.append(_item(
            f"records with at least {MOTION_PERIODS / MOTION_F_LO:.0f} s in the tissue "
            f"({MOTION_PERIODS:.0f} periods of the slowest motion line tested, "
            f"{MOTION_F_LO:g} Hz)",
            "tissue_motion's periodicity test: " + str(short[-1].get("local")),
            ["tissue_motion"], "final_round.tissue_motion.local"))
    fast = _flags(rep, "tau_fast_s", "at_bound", "lower")
    if fast:
        tau_f = _num(fast[0].get("value"))
        rates = [_num(t.get("rate_hz")) for t in trials if _num(t.get("rate_hz")) > 0]
        have = f"; the record has {_fmt(float(np.median(rates)))} Hz" if rates else ""
        out.append(_item(
            f"a higher sample rate: at least {_fmt(SAMPLES_PER_TAU / tau_f)} Hz "
            f"({SAMPLES_PER_TAU:.0f} samples within tau_fast{have})",
            f"tau_fast_s = {_fmt(tau_f)} s at its lower bound: the fast relaxation is faster "
            "than the fit can resolve", ["dwell_relaxation"], "flags.tau_fast_s"))
    return out


def _stretch_effect(w: dict[str, Any], named: list[str], layers: bool
                    ) -> tuple[str, list[str]] | None:
    """The effect (or pattern) one described unexplained stretch points to, and the vocabulary
    effects involved; None for "no simple shape"."""
    ph, shape = str(w.get("phase")), str(w.get("looks_like"))
    freq = _num(w.get("frequency_hz"))
    if shape == "periodic drops":
        return (f"stick-slip: drops of one size every {_fmt(_num(w.get('period_mm')))} mm, which "
                "the base model counts as layers (not in the vocabulary)", [])
    if shape == "oscillation":
        if MOTION_F_LO <= freq <= MOTION_F_HI and "tissue_motion" not in named:
            return f"tissue_motion (a line at {_fmt(freq)} Hz)", ["tissue_motion"]
        return (f"stick-slip or a resonance at {_fmt(freq)} Hz (not in the vocabulary)", [])
    if shape == "no simple shape":
        return None
    if ph in _AIR:
        if "sensor_drift" not in named:
            return "sensor_drift (the force in the air departs from the tare)", ["sensor_drift"]
        return ("a drift that is not linear in time: a warm-up or a random walk (not in the "
                "vocabulary)", ["sensor_drift"])
    if ph == "dwell":
        if "dwell_relaxation" not in named:
            return "dwell_relaxation", ["dwell_relaxation"]
        if shape in ("drop", "rise") and "until_s" in w:
            return ("a transient at the dwell's start faster than tau_fast: a third, faster "
                    "relaxation branch or the stage's own deceleration (not in the vocabulary)",
                    ["dwell_relaxation"])
        return ("a relaxation beyond two exponentials in the dwell: a power-law kernel or a "
                "Maxwell element on the whole tissue force (not in the vocabulary)",
                ["dwell_relaxation"])
    if ph in _INSERT:
        if shape in ("drop", "rise") and "until_s" in w:
            return ("a rupture the model places at another depth: a tear that runs on over "
                    "travel, or layers moved with the fitted surface -- rupture depths fitted "
                    "layer by layer (not in the vocabulary: the multi-layer base keeps the "
                    "detected ones)", ["layer_puncture"])
        if shape == "drop":
            return (f"an extra layer: a rupture the detector did not count near "
                    f"{_fmt(_num(w.get('at_depth_mm')))} mm (layer_puncture)", ["layer_puncture"])
        if shape == "trend":
            return ("a shaft friction density that changes with depth (not in the vocabulary)",
                    [])
        if layers:
            return ("a cutting force that builds up over the first millimetres after a rupture "
                    "(post-rupture cutting onset; not in the vocabulary)", ["layer_puncture"])
        return ("layer_puncture: a loading ramp the base model's tenting does not follow",
                ["layer_puncture"])
    if ph in _BACK:
        if shape in ("drop", "rise"):
            return (f"a layer letting go during the retraction: a step of "
                    f"{_fmt(abs(_num(w.get('size_n'))))} N near "
                    f"{_fmt(_num(w.get('at_depth_mm')))} mm (not in the vocabulary)", [])
        for e in ("reversal_presliding", "direction_asymmetry"):
            if e not in named:
                return e, [e]
        return ("a retraction friction that changes with depth (not in the vocabulary)",
                ["direction_asymmetry"])
    return None


def effect_items(rep: dict[str, Any]) -> list[dict[str, Any]]:
    """Which effect to try next (see the module's doc)."""
    out: list[dict[str, Any]] = []
    named = list(rep.get("named") or [])
    layers = "layer_puncture" in named
    verdict = rep.get("verdict") or {}
    where = [(j, w) for j, w in enumerate(verdict.get("where") or [])
             if "looks_like" in w][:STRETCHES]
    seen: dict[str, dict[str, Any]] = {}
    for j, w in where:
        got = _stretch_effect(w, named, layers)
        if got is None:
            continue
        text, cands = got
        why = (f"{w.get('phase')} of {w.get('trial')}, {_fmt(_num(w.get('t_from_s')))}-"
               f"{_fmt(_num(w.get('t_to_s')))} s, {_fmt(_num(w.get('over_noise')))}x the noise: "
               f"{w.get('description')}")
        if text in seen:
            seen[text]["more"] += 1
            continue
        seen[text] = dict(_item(text, why, cands, f"verdict.where[{j}]"), more=0)
        out.append(seen[text])
    for d in out:
        more = d.pop("more")
        if more:
            d["because"] += f" (and {more} more stretch{'es' if more > 1 else ''} like it)"
    for k, e in enumerate(rep.get("effects") or []):
        w = e.get("worsens")
        if w:
            out.append(_item(
                f"{e.get('name')} in another form, or without it: its refit makes the "
                f"{w.get('phase')} phase worse",
                f"RMSE {_fmt(_num(w.get('rmse_before_n')))} -> {_fmt(_num(w.get('rmse_after_n')))}"
                f" N in a phase the model explained (more than "
                f"{_fmt(_num(w.get('allowance_x_noise')))}x the noise)", [str(e.get("name"))],
                f"effects[{k}].worsens"))
    surf = _flags(rep, "surface", "at_bound")
    if surf:
        trials = ", ".join(str(f.get("trial")) for f in surf)
        out.append(_item(
            "tenting before puncture: the surface moves with the needle, so the force's features "
            "appear deeper than the stage says (not in the vocabulary)",
            f"the surface correction is at its bound ({_fmt(_num(surf[0].get('bound')))} mm) in "
            f"{trials}", [], "flags.surface"))
    slow = _flags(rep, "tau_slow_s", "at_bound", "upper")
    if slow and "sensor_drift" not in named:
        out.append(_item(
            "sensor_drift, or a third, slower relaxation branch",
            f"tau_slow_s = {_fmt(_num(slow[0].get('value')))} s at its upper bound: something "
            "slower than the slow branch goes on in the dwell", ["sensor_drift",
                                                                 "dwell_relaxation"],
            "flags.tau_slow_s"))
    pre = _flags(rep, "presliding_mm", "at_bound", "upper")
    if pre and "direction_asymmetry" not in named:
        out.append(_item(
            "direction_asymmetry: a retraction friction that stays different, rather than a "
            "turn-over", f"presliding_mm = {_fmt(_num(pre[0].get('value')))} mm at its upper "
            "bound", ["direction_asymmetry", "reversal_presliding"], "flags.presliding_mm"))
    return out


def what_next(rep: dict[str, Any]) -> dict[str, Any]:
    """The "What next" advice of a report (report.json without ``what_next``)."""
    effects = effect_items(rep)
    verdict = rep.get("verdict") or {}
    return {"data": data_items(rep), "effects": effects,
            "explained": not bool(verdict.get("unexplained"))}


def render(wn: dict[str, Any]) -> list[str]:
    """The report.md section, from report.json's ``what_next`` alone."""
    L = ["## What next", "", "Data that would separate the remaining candidates:", ""]
    L += [f"- {d['suggest']} -- because {d['because']} (from {d['source']})"
          for d in wn.get("data") or []] or ["- nothing the record lacks for the candidates "
                                            "judged"]
    L += ["", "Effects to try next:", ""]
    if wn.get("effects"):
        L += [f"- {d['suggest']} -- because {d['because']} (from {d['source']})"
              for d in wn["effects"]]
    elif wn.get("explained"):
        L += ["- none: no structure above the threshold remains and no value is at a bound "
              "that points to one"]
    else:
        L += ["- none read off the residual: the largest stretches have no simple shape "
              "(see the figures)"]
    return L + [""]


__all__ = ["what_next", "render", "data_items", "effect_items"]
