"""Writing the report directory: report.json (the numbers), report.md (rendered from report.json
only, so the text can be recomputed from the JSON) and figures."""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from .effects import EFFECT_MEANING, EFFECT_NL, EFFECT_PHASES, NONE
from .prep import PHASES
from .workflow import Result, base_paramset


def _clean(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, np.ndarray):
        return _clean(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(float(x)) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    return x


def _effect_params(res: Result, k: int) -> dict[str, Any]:
    step = res.steps[k]
    f = step.fit
    out: dict[str, Any] = {}
    for par in EFFECT_NL[step.effect]:
        out[f"{par.name} [{par.unit}]"] = f.nl[par.name]
    lab = {"velocity_friction": ["b_visc"], "direction_asymmetry": ["dC_out", "dsigma2_out"],
           "layer_puncture": ["layer_drop"], "sensor_drift": ["drift"],
           "dwell_relaxation": [c for c in f.coef if c.startswith("relax_")]}
    units = {"b_visc": "N s/mm^2", "dC_out": "N/mm", "dsigma2_out": "N/mm", "layer_drop": "N",
             "drift": "N/s"}
    for c in lab.get(step.effect, []):
        out[f"{c} [{units.get(c, 'N')}]"] = f.coef[c]
    if step.effect == "direction_asymmetry":
        out["retraction/insertion sigma2 ratio"] = (f.coef["sigma2"] + f.coef["dsigma2_out"]) / \
            f.coef["sigma2"] if f.coef["sigma2"] else None
    return out


def build(res: Result, inputs: list[str]) -> dict[str, Any]:
    """The whole report as a JSON-ready dict."""
    effects = []
    for k, step in enumerate(res.steps):
        effects.append({
            "name": step.effect, "meaning": EFFECT_MEANING[step.effect],
            "parameters": _effect_params(res, k),
            "score": {"delta_bic": step.delta_bic, "heldout_gain": step.heldout_gain},
            "acts_on_phases": list(EFFECT_PHASES[step.effect]),
            "errors_before": res.errors[k], "errors_after": res.errors[k + 1],
            "candidates": step.candidates})
    if not effects:
        effects_named = [NONE]
    else:
        effects_named = [e["name"] for e in effects]
    base = base_paramset(res.fits[0])
    trials = [{"name": p.name, "samples": int(len(p.t_s)), "surface_offset_mm": p.surface_mm,
               "tare_n": p.tare_n, "noise_n": p.noise_n, "puncture_depth_mm": p.puncture_mm,
               "speed_mm_s": p.speed_mm_s,
               "phase_samples": {ph: int(np.count_nonzero(p.phase == j))
                                 for j, ph in enumerate(PHASES)}} for p in res.preps]
    return _clean({
        "inputs": inputs, "named": effects_named, "effects": effects,
        "base_model": {"model": "II (alpha, f2 from the joint Model I fit; see DISCREPANCY.md)",
                       "params": base.__dict__,
                       "offsets_n": [res.fits[0].coef[f"offset[{i}]"]
                                     for i in range(len(res.preps))]},
        "trials": trials, "skipped": [{"name": n, "reason": r} for n, r in res.skipped],
        "shared_fit": len(res.preps) > 1, "heldout_scheme": res.heldout_scheme,
        "errors": res.errors, "final_round": res.last_round,
        "residual_stats_before": res.stats_before, "residual_stats_after": res.stats_after,
        "speed_direction": res.speed_dir, "notes": res.notes, "runtime_s": res.runtime_s})


def _fmt(x: Any) -> str:
    if x is None:
        return "-"
    if isinstance(x, float):
        return f"{x:.4g}"
    if isinstance(x, list):
        return "[" + ", ".join(_fmt(v) for v in x) + "]"
    return str(x)


def render_md(rep: dict[str, Any], figures: list[str]) -> str:
    """report.md from report.json alone (every number here is in the JSON)."""
    L = ["# Discrepancy report", "", f"Inputs: {', '.join(rep['inputs'])}", "",
         f"**Named effects (in order of discovery): {', '.join(rep['named'])}**", ""]
    L += [f"- {n}" for n in rep["notes"]]
    if rep["skipped"]:
        L += [""] + [f"- skipped {s['name']}: {s['reason']}" for s in rep["skipped"]]
    L += ["", "## Trials", "", "| trial | samples | surface offset mm | tare N | noise N | "
          "puncture mm | speed mm/s |", "|---|---|---|---|---|---|---|"]
    for t in rep["trials"]:
        L.append(f"| {t['name']} | {t['samples']} | {_fmt(t['surface_offset_mm'])} | "
                 f"{_fmt(t['tare_n'])} | {_fmt(t['noise_n'])} | {_fmt(t['puncture_depth_mm'])} "
                 f"| {_fmt(t['speed_mm_s'])} |")
    L += ["", "## 1. Base model", ""]
    L += [f"- {k} = {_fmt(v)}" for k, v in rep["base_model"]["params"].items()]
    L += ["", "## 2. Residual of the base model per phase", "",
          "| phase | n | bias N | RMS N | trend N/s | decay N | period Hz | power share |",
          "|---|---|---|---|---|---|---|---|"]
    for ph, s in rep["residual_stats_before"].items():
        L.append(f"| {ph} | {s['n']} | {_fmt(s['bias_n'])} | {_fmt(s['rms_n'])} | "
                 f"{_fmt(s['trend_n_per_s'])} | {_fmt(s['decay_n'])} | {_fmt(s['period_hz'])} | "
                 f"{_fmt(s['period_power_share'])} |")
    L += ["", f"Speed/direction: friction-bias slope {_fmt(rep['speed_direction']['friction_bias_slope_n_per_mm_s'])} N per mm/s", ""]
    L += ["## 3-4. Candidate effects", "", f"Held-out data: {rep['heldout_scheme']}.", ""]
    for k, e in enumerate(rep["effects"]):
        L += [f"### Effect {k + 1}: `{e['name']}` — {e['meaning']}", "",
              f"delta BIC {_fmt(e['score']['delta_bic'])}, held-out gain "
              f"{_fmt(e['score']['heldout_gain'])}", "", "Parameters:"]
        L += [f"- {p} = {_fmt(v)}" for p, v in e["parameters"].items()]
        L += ["", "| candidate | delta BIC | held-out gain |", "|---|---|---|"]
        for c in e["candidates"]:
            L.append(f"| {c['name']} | {_fmt(c.get('delta_bic'))} | {_fmt(c.get('heldout_gain'))} |")
        L.append("")
    if not rep["effects"]:
        L += ["No candidate is significant: `none` (the base model explains the data).", ""]
    L += ["## 5. Gap before and after each added effect (RMSE / MAE, N)", ""]
    models = ["base"] + [f"+{n}" for n in rep["named"] if n != "none"]
    L += ["| phase | " + " | ".join(models) + " |", "|---" * (len(models) + 1) + "|"]
    for ph in list(PHASES) + ["overall"]:
        cells = []
        for err in rep["errors"]:
            if ph in err:
                cells.append(f"{err[ph]['rmse_n']:.4g} / {err[ph]['mae_n']:.4g}")
            else:
                cells.append("-")
        if any(c != "-" for c in cells):
            L.append(f"| {ph} | " + " | ".join(cells) + " |")
    L += ["", "## Figures", ""] + [f"![{Path(f).stem}]({f})" for f in figures]
    L += ["", f"Run time: {rep['runtime_s']:.2f} s", ""]
    return "\n".join(L)


def write(res: Result, inputs: list[str], out: Path, with_figures: bool = True) -> dict[str, Any]:
    """The report in ``out`` through the tools' safe writer: every file or none."""
    from ..tools.safe_write import Outputs
    with Outputs() as outs:
        outs.directory(out, "--out")
        rep = build(res, inputs)
        figs: list[str] = []
        if with_figures:
            from .figures import draw
            figs = draw(res, out, lambda p: outs.add(p, "--out"))
        rep["figures"] = figs
        outs.write_text(outs.add(out / "report.json", "--out"), json.dumps(rep, indent=1))
        outs.write_text(outs.add(out / "report.md", "--out"), render_md(rep, figs))
        outs.commit()
    return rep
