"""Writing the report directory: report.json (the numbers), report.md (rendered from report.json
only, so the text can be recomputed from the JSON) and figures."""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from .effects import EFFECT_MEANING, EFFECT_NL, EFFECT_PHASES, LIN_BOUNDS, NONE, lin_bound
from .prep import PHASES
from .workflow import UNEXPLAINED_WINDOW_S, UNEXPLAINED_X, Result, base_paramset


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
    se = f.nl_se or {}
    for par in EFFECT_NL[step.effect]:
        out[f"{par.name} [{par.unit}]"] = f.nl[par.name]
        if par.name in se:
            out[f"{par.name} standard error [{par.unit}]"] = se[par.name]
    lab = {"velocity_friction": ["b_visc"], "direction_asymmetry": ["dC_out", "dsigma2_out"],
           "layer_puncture": ["layer_drop"], "sensor_drift": ["drift"],
           "dwell_relaxation": [c for c in f.coef if c.startswith("relax_")],
           "reversal_presliding": [c for c in f.coef if c.startswith("presliding_")]}
    units = {"b_visc": "N s/mm^2", "dC_out": "N/mm", "dsigma2_out": "N/mm", "layer_drop": "N",
             "drift": "N/s"}
    for c in lab.get(step.effect, []):
        out[f"{c} [{units.get(c, 'N')}]"] = f.coef[c]
    if step.effect == "direction_asymmetry":
        out["retraction/insertion sigma2 ratio"] = (f.coef["sigma2"] + f.coef["dsigma2_out"]) / \
            f.coef["sigma2"] if f.coef["sigma2"] else None
    return out


def bounds_table() -> dict[str, Any]:
    """Every documented bound (nonlinear parameters and linear coefficients), for checkers."""
    from .effects import BASE_NL
    nl = {p.name: [p.lo, p.hi, p.unit] for p in BASE_NL}
    for e, ps in EFFECT_NL.items():
        nl.update({p.name: [p.lo, p.hi, p.unit] for p in ps})
    lin = {k: [v[0] if np.isfinite(v[0]) else None, v[1] if np.isfinite(v[1]) else None]
           for k, v in LIN_BOUNDS.items()}
    return {"nonlinear": nl, "linear": lin,
            "layer_depth": "0 < rupture depth <= deepest inserted depth",
            "layer_drop": "0 < drop < insertion peak"}


def bound_violations(res: Result) -> list[str]:
    """Parameters of the final model outside their documented bounds (expected: none)."""
    from .effects import nl_specs
    f = res.fits[-1]
    out = []
    for par in nl_specs(f.effects):
        vals = np.atleast_1d(f.nl[par.name])
        if np.any(vals < par.lo - 1e-9) or np.any(vals > par.hi + 1e-9):
            out.append(f"{par.name}={vals.tolist()} outside [{par.lo}, {par.hi}]")
    for lab, c in f.coef.items():
        lo, hi = lin_bound(lab)
        if not (lo - 1e-9 <= c <= hi + 1e-9):
            out.append(f"{lab}={c} outside [{lo}, {hi}]")
    for p, t in zip(res.preps, res.evidence.get("per_trial", [])):  # type: ignore[union-attr]
        deepest = float(np.max(p.stage_mm - p.surface_mm))
        peak = float(np.max(p.force_n))
        for r in t["ruptures"]:
            if not (0 < r["depth_mm"] <= deepest + 1e-9):
                out.append(f"{p.name}: rupture at {r['depth_mm']} mm outside (0, {deepest}]")
            if not (0 < r["drop_n"] <= peak):
                out.append(f"{p.name}: drop {r['drop_n']} N not in (0, peak {peak} N]")
    return out


def _share(res: Result, k: int) -> float:
    gap = res.fits[0].sse - res.fits[-1].sse
    return (res.fits[k].sse - res.fits[k + 1].sse) / gap if gap > 0 else 0.0


def _magnitude(res: Result, k: int) -> dict[str, float]:
    """RMS (N) of the force the effect adds in its own phases, with a bootstrap-free standard
    error from the residual noise (sqrt of the chi-square's variance)."""
    e = res.errors
    ph = EFFECT_PHASES[res.steps[k].effect]
    before = [e[k][p]["rmse_n"] ** 2 * e[k][p]["n"] for p in ph if p in e[k]]
    after = [e[k + 1][p]["rmse_n"] ** 2 * e[k + 1][p]["n"] for p in ph if p in e[k + 1]]
    n = sum(e[k][p]["n"] for p in ph if p in e[k])
    d = max(sum(before) - sum(after), 0.0) / max(n, 1)
    sig = float(np.median([p.noise_n for p in res.preps]))
    mag = float(np.sqrt(d))
    se = float(sig * np.sqrt(2.0 / max(n, 1)) * (1.0 + sig / max(mag, 1e-12)))
    return {"rms_n": mag, "standard_error_n": min(se, mag) if mag > 0 else se}


def verdict(res: Result) -> dict[str, Any]:
    return {"unexplained": bool(res.unexplained), "threshold_x_noise": UNEXPLAINED_X,
            "window_s": UNEXPLAINED_WINDOW_S, "where": res.unexplained[:10],
            "text": ("unexplained: structure above {:.0f}x the noise remains (largest: {} phase "
                     "of {}, {:.1f}-{:.1f} s, depth {:.1f}-{:.1f} mm, {:.0f}x the noise)".format(
                         UNEXPLAINED_X, res.unexplained[0]["phase"], res.unexplained[0]["trial"],
                         res.unexplained[0]["t_from_s"], res.unexplained[0]["t_to_s"],
                         res.unexplained[0]["depth_from_mm"], res.unexplained[0]["depth_to_mm"],
                         res.unexplained[0]["over_noise"]) if res.unexplained else
                     f"explained: no structure above {UNEXPLAINED_X:.0f}x the noise remains")}


def build(res: Result, inputs: list[str]) -> dict[str, Any]:
    """The whole report as a JSON-ready dict."""
    effects = []
    if any(res.layers):
        effects.append({
            "name": "layer_puncture", "meaning": EFFECT_MEANING["layer_puncture"],
            "parameters": {"layers_per_trial": res.layers,
                           "ruptures": [t["ruptures"] for t in res.evidence["per_trial"]]},
            "score": {"local": "force drops seen in the first insertion; the multi-layer base "
                      "model switches to each layer's own parameters there"},
            "acts_on_phases": list(EFFECT_PHASES["layer_puncture"]),
            "errors_before": res.errors[0], "errors_after": res.errors[0]})
    for k, step in enumerate(res.steps):
        effects.append({
            "name": step.effect, "meaning": EFFECT_MEANING[step.effect],
            "parameters": _effect_params(res, k),
            "magnitude": _magnitude(res, k), "share_of_explained_gap": _share(res, k),
            "score": {"delta_bic_local": step.delta_bic, "heldout_gain": step.heldout_gain,
                      "own_phase_gain": step.own_phase_gain, "local_evidence": step.local},
            "acts_on_phases": list(EFFECT_PHASES[step.effect]),
            "errors_before": res.errors[k], "errors_after": res.errors[k + 1],
            "candidates": step.candidates})
    effects_named = res.named
    base = base_paramset(res.fits[0])
    trials = [{"name": p.name, "samples": int(len(p.t_s)), "surface_offset_mm": p.surface_mm,
               "tare_n": p.tare_n, "noise_n": p.noise_n, "puncture_depth_mm": p.puncture_mm,
               "speed_mm_s": p.speed_mm_s,
               "phase_samples": {ph: int(np.count_nonzero(p.phase == j))
                                 for j, ph in enumerate(PHASES)}} for p in res.preps]
    return _clean({
        "inputs": inputs, "named": effects_named, "effects": effects,
        "verdict": verdict(res), "bounds": bounds_table(),
        "bound_violations": bound_violations(res), "local_evidence": res.evidence,
        "validation": res.validation,
        "base_model": {"model": "II (alpha, f2 from the joint Model I fit; see DISCREPANCY.md), "
                                "plus one parameter set per detected layer",
                       "params": base.__dict__,
                       "layer_coefficients": {k: v for k, v in res.fits[0].coef.items()
                                              if k.startswith("layer")},
                       "zero_in_air": True},
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
         f"**Named effects (in order of discovery): {', '.join(rep['named'])}**", "",
         f"**Verdict: {rep['verdict']['text']}**", ""]
    val = rep["validation"]
    if "shrink" in val:
        L += [f"Held-out validation ({val['scheme']}): RMSE base {_fmt(val['rmse_base_n'])} N, "
              f"final {_fmt(val['rmse_final_n'])} N, shrink {_fmt(val['shrink'])}", ""]
    if rep["bound_violations"]:
        L += ["Parameters outside their bounds: " + "; ".join(rep["bound_violations"]), ""]
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
        L += [f"### Effect {k + 1}: `{e['name']}` — {e['meaning']}", ""]
        L += [f"- score {s}: {_fmt(v)}" for s, v in e["score"].items()]
        if "magnitude" in e:
            L += [f"- magnitude {_fmt(e['magnitude']['rms_n'])} ± "
                  f"{_fmt(e['magnitude']['standard_error_n'])} N RMS, share of the explained gap "
                  f"{_fmt(e['share_of_explained_gap'])}"]
        L += ["", "Parameters:"]
        L += [f"- {p} = {_fmt(v)}" for p, v in e["parameters"].items()]
        L += ["", "| candidate | delta BIC | held-out gain |", "|---|---|---|"]
        for c in e.get("candidates", []):
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


CONFIG_SCHEMA = "nte-estimator-config/1"


def readable_params(params: dict[str, float], noise_n: float, depth_max_mm: float
                    ) -> tuple[dict[str, float], dict[str, dict[str, float]]]:
    """The base fit's values as the estimator can start from them.  The fit bounds the
    friction coefficients at 0 (lsq_linear); the estimator identifies log-ratios to its
    nominal values, so it needs them positive (its readers refuse 0).  A coefficient the fit
    put at 0 is written as the smallest value the data could tell from 0 -- its term at the
    deepest point equal to the noise: sigma2 = noise / depth, sigma1 = noise / (beta depth)
    (the sigma1 term is at most sigma1 beta l) -- from which the filters can grow it by their
    clip factor if the tissue wants it.  Returns the values and what was floored (fitted and
    written values, for the report's reader)."""
    out = dict(params)
    floored: dict[str, dict[str, float]] = {}
    depth = max(depth_max_mm, 1.0)
    floors = {"sigma2": noise_n / depth, "sigma1": noise_n / (params["beta"] * depth)}
    for name, floor in floors.items():
        if not out[name] > 0.0:
            floored[name] = {"fitted": float(out[name]), "written": float(floor)}
            out[name] = float(floor)
    return out, floored


def estimator_config(res: Result) -> dict[str, Any]:
    """The fitted base model as an estimator configuration (schema in DISCREPANCY.md §7)."""
    base = res.fits[0]
    final = res.fits[-1]
    eff: dict[str, Any] = {}
    for step in res.steps:
        e = step.effect
        d: dict[str, Any] = {par.name: final.nl[par.name] for par in EFFECT_NL[e]
                             if not par.per_trial}
        for lab, c in final.coef.items():
            key = lab.split("[")[0]
            if lab.endswith("]"):
                continue
            if (e == "velocity_friction" and key == "b_visc") or \
               (e == "direction_asymmetry" and key in ("dC_out", "dsigma2_out")) or \
               (e == "layer_puncture" and key == "layer_drop") or \
               (e == "sensor_drift" and key == "drift"):
                d[key] = c
        if e == "dwell_relaxation":
            rel = [dw["relative_decay"] for t in res.evidence["per_trial"]
                   for dw in t["dwells"]]
            d["relative_decay_median"] = float(np.median(rel)) if rel else None
        eff[e] = d
    layers = []
    for i, (p, t) in enumerate(zip(res.preps, res.evidence["per_trial"])):
        coefs = {k.split("[")[0]: v for k, v in base.coef.items()
                 if k.startswith("layer") and k.endswith(f"[{i}]")}
        layers.append({"trial": p.name, "ruptures_mm": [r["depth_mm"] for r in t["ruptures"]],
                       "coefficients": coefs})
    noise = float(np.median([p.noise_n for p in res.preps]))
    params, floored = readable_params(base_paramset(base).__dict__, noise,
                                      max(float(np.max(p.stage_mm - p.surface_mm))
                                          for p in res.preps))
    return _clean({
        "schema": CONFIG_SCHEMA, "source": "nte-discrepancy", "model": 2,
        "params": params, "floored": floored, "r_n2": noise ** 2, "noise_n": noise,
        "surface_mm": [p.surface_mm + float(base.nl["surface"][i])
                       for i, p in enumerate(res.preps)],
        "tare_n": [p.tare_n for p in res.preps],
        "sign": {"force": [p.force_sign for p in res.preps],
                 "depth": [p.depth_sign for p in res.preps]},
        "layers": layers, "effects": eff})


def write(res: Result, inputs: list[str], out: Path, with_figures: bool = True) -> dict[str, Any]:
    """The report in ``out`` through the tools' safe writer: report.json, report.md,
    estimator_config.json and the figures, every file or none."""
    from ..tools.safe_write import Outputs
    with Outputs() as outs:
        outs.directory(out, "--out")
        rep = build(res, inputs)
        figs: list[str] = []
        if with_figures:
            from .figures import draw
            figs = draw(res, out, lambda p: outs.add(p, "--out"))
        rep["figures"] = figs
        rep["estimator_config"] = "estimator_config.json"
        outs.write_text(outs.add(out / "report.json", "--out"), json.dumps(rep, indent=1))
        outs.write_text(outs.add(out / "report.md", "--out"), render_md(rep, figs))
        outs.write_text(outs.add(out / "estimator_config.json", "--out"),
                        json.dumps(estimator_config(res), indent=1))
        outs.commit()
    return rep
