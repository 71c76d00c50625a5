"""Writing the report directory: report.json (the numbers), report.md (rendered from report.json
only, so the text can be recomputed from the JSON) and figures."""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from .effects import (EFFECT_MEANING, EFFECT_NL, EFFECT_PHASES, LIN_BOUNDS, NONE,
                      depths_below_fitted_surface, lin_bound)
from .prep import PHASES
from .accept import WORSEN_NOISE_X
from .nextsteps import render as render_next
from .nextsteps import what_next
from .unexplained import UNEXPLAINED_WINDOW_S, UNEXPLAINED_X
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


#: the linear coefficients of each effect that the report lists (per trial ones end in "[i]")
_EFFECT_COEFS = {"velocity_friction": ("b_visc",), "direction_asymmetry": ("dC_out", "dsigma2_out"),
                 "layer_puncture": ("layer_drop",), "sensor_drift": ("drift",),
                 "dwell_relaxation": ("relax_",), "reversal_presliding": ("presliding_",)}
_COEF_UNITS = {"b_visc": "N s/mm^2", "dC_out": "N/mm", "dsigma2_out": "N/mm", "layer_drop": "N",
               "drift": "N/s"}


def _effect_values(res: Result, name: str) -> list[dict[str, Any]]:
    """The parameters of one named effect in the final model (the one estimator_config.json
    exports): name, unit, value, standard error (nonlinear ones), whether the config carries it.
    The report's effect parameters and the config's ``effects`` block are both read from here."""
    f = res.fits[-1]
    se = f.nl_se or {}
    rows: list[dict[str, Any]] = []
    for par in EFFECT_NL[name]:
        rows.append({"name": par.name, "unit": par.unit, "value": f.nl[par.name],
                     "se": se.get(par.name), "export": not par.per_trial})
    for lab, c in f.coef.items():
        key = lab.split("[")[0]
        if any(key == w or (w.endswith("_") and key.startswith(w))
               for w in _EFFECT_COEFS.get(name, ())):
            rows.append({"name": lab, "unit": _COEF_UNITS.get(key, "N"), "value": c, "se": None,
                         "export": key in _COEF_UNITS and not lab.endswith("]")})
    if name == "direction_asymmetry":
        rows.append({"name": "retraction/insertion sigma2 ratio", "unit": "",
                     "value": (f.coef["sigma2"] + f.coef["dsigma2_out"]) / f.coef["sigma2"]
                     if f.coef["sigma2"] else None, "se": None, "export": False})
    if name == "dwell_relaxation":
        rel = [dw["relative_decay"] for t in res.evidence["per_trial"]  # type: ignore[union-attr]
               for dw in t["dwells"]]
        rows.append({"name": "relative_decay_median", "unit": "1",
                     "value": float(np.median(rel)) if rel else None, "se": None, "export": True})
    return rows


def _params_dict(rows: list[dict[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for r in rows:
        u = f" [{r['unit']}]" if r["unit"] else ""
        out[f"{r['name']}{u}"] = r["value"]
        if r["se"] is not None:
            out[f"{r['name']} standard error{u}"] = r["se"]
    return out


#: a fitted value within this fraction of its search range (log range for log-searched values)
#: from a bound counts as at the bound (the fit stops near, rarely on, a bound)
AT_BOUND_FRAC = 0.01
#: a linear coefficient within this of its lower bound is at it (the bounded solve puts it there)
AT_BOUND_LIN = 1e-9


def check_parameter(name: str, value: float, lo: float, hi: float, se: float | None = None,
                    log: bool = True, fit: str = "final", trial: str | None = None
                    ) -> list[dict[str, Any]]:
    """Flags of one fitted value: ``at_bound`` when it sits at (within AT_BOUND_FRAC of the
    range of) a bound of its fit, ``se_above_value`` when its standard error exceeds it (only
    for positive, log-searched values: a signed correction near 0 has no scale to compare)."""
    out: list[dict[str, Any]] = []
    base = {"parameter": name, "trial": trial, "value": float(value), "fit": fit}
    if not math.isfinite(value):
        return out
    for side, b in (("lower", lo), ("upper", hi)):
        if not math.isfinite(b):
            continue
        if math.isfinite(lo) and math.isfinite(hi) and hi > lo:
            if log and lo > 0 and value > 0:
                d = abs(math.log(value) - math.log(b)) / (math.log(hi) - math.log(lo))
            else:
                d = abs(value - b) / (hi - lo)
            hit = d <= AT_BOUND_FRAC
        else:
            hit = (value <= b + AT_BOUND_LIN) if side == "lower" else (value >= b - AT_BOUND_LIN)
        if hit:
            out.append({**base, "kind": "at_bound", "bound": float(b), "side": side})
    if log and se is not None and math.isfinite(se) and se > abs(value):
        out.append({**base, "kind": "se_above_value", "se": float(se)})
    return out


def parameter_flags(res: Result) -> list[dict[str, Any]]:
    """Every reported value at a bound of its fit or with a standard error above it: the base
    model's (base fit: shape, surfaces, sigma0, sigma1, sigma2, layer coefficients) and the named
    effects' (final fit), under the names and in the units the report shows them."""
    from .effects import BASE_NL, BETA0_DEFAULT
    out: list[dict[str, Any]] = []
    names = [p.name for p in res.preps]

    def nl_flags(f: Any, specs: Any, fit_name: str) -> None:
        se = f.nl_se or {}
        for par in specs:
            if not par.flag_bounds:
                continue
            vals = np.atleast_1d(np.asarray(f.nl[par.name], dtype=float))
            ses = np.atleast_1d(np.asarray(se[par.name], dtype=float)) if par.name in se \
                else np.full(len(vals), np.nan)
            for i, v in enumerate(vals):
                tr = names[i] if par.per_trial and i < len(names) else None
                s_i = float(ses[i]) if i < len(ses) and np.isfinite(ses[i]) else None
                out.extend(check_parameter(par.name, float(v), par.lo, par.hi, s_i, par.log,
                                           fit_name, tr))

    def lin_flags(coef: dict[str, float], keep: Any, fit_name: str) -> None:
        for lab, c in coef.items():
            if not keep(lab):
                continue
            lo, hi = lin_bound(lab)
            name, scale = lab.split("[")[0], 1.0
            if name in ("A", "C"):      # shown as sigma0 = A / beta, sigma1 = C / beta
                name, scale = {"A": "sigma0", "C": "sigma1"}[name], 1.0 / BETA0_DEFAULT
            tr = None
            if lab.endswith("]"):
                i = int(lab[lab.index("[") + 1:-1])
                tr = names[i] if i < len(names) else str(i)
            for fl in check_parameter(name, c, lo, hi, None, False, fit_name, tr):
                fl["value"] = c * scale
                if "bound" in fl:
                    fl["bound"] = fl["bound"] * scale
                out.append(fl)

    base = res.fits[0]
    nl_flags(base, BASE_NL, "base")
    lin_flags(base.coef, lambda lab: lab.split("[")[0] in ("A", "C", "sigma2")
              or lab.startswith("layer") and lab.split("[")[0] != "layer_drop", "base")
    final = res.fits[-1]
    for step in res.steps:
        nl_flags(final, EFFECT_NL[step.effect], "final")
        keys = _EFFECT_COEFS.get(step.effect, ())
        lin_flags(final.coef, lambda lab, keys=keys: any(
            lab.split("[")[0] == w or (w.endswith("_") and lab.startswith(w)) for w in keys),
            "final")
    return out


def gap_chain(res: Result) -> list[dict[str, Any]]:
    """The models of the gap table, in the order the effects were added: the base (one layer
    when ruptures were detected), the multi-layer base (+layer_puncture), then one model per
    added effect; each with its errors per phase.  Effect j's gap is chain[j] -> chain[j+1]."""
    chain = []
    if any(res.layers) and res.errors_one_layer is not None:
        chain.append({"model": "base", "errors": res.errors_one_layer})
        chain.append({"model": "+layer_puncture", "errors": res.errors[0]})
    else:
        chain.append({"model": "base (with its layers)" if any(res.layers) else "base",
                      "errors": res.errors[0]})
    for step, err in zip(res.steps, res.errors[1:]):
        chain.append({"model": f"+{step.effect}", "errors": err})
    return chain


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
            "layer_drop": "0 < drop < insertion peak",
            "layer_load": "k1, k2 of each layer <= the trial's largest force (N)"}


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


def _worsens(step: Any) -> dict[str, Any] | None:
    """The phase the model explained (RMSE <= 3x the noise) that this effect's refit made worse
    by more than accept.WORSEN_NOISE_X times the noise, or None (issue 22 item 4: reported, not
    refused; accept.py says why)."""
    row = next((c for c in step.candidates if c.get("name") == step.effect), {})
    ratio = row.get("worst_phase_ratio")
    if ratio is None or not ratio > 1.0:
        return None
    return {"phase": row["worst_phase"], "rmse_before_n": row["worst_phase_rmse_before_n"],
            "rmse_after_n": row["worst_phase_rmse_after_n"], "allowance_x_noise": WORSEN_NOISE_X}


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
                     "of {}, {:.1f}-{:.1f} s, depth {:.1f}-{:.1f} mm, {:.0f}x the noise; it looks "
                     "like {})".format(
                         UNEXPLAINED_X, res.unexplained[0]["phase"], res.unexplained[0]["trial"],
                         res.unexplained[0]["t_from_s"], res.unexplained[0]["t_to_s"],
                         res.unexplained[0]["depth_from_mm"], res.unexplained[0]["depth_to_mm"],
                         res.unexplained[0]["over_noise"], res.unexplained[0]["description"])
                     if res.unexplained else
                     f"explained: no structure above {UNEXPLAINED_X:.0f}x the noise remains")}


def build(res: Result, inputs: list[str]) -> dict[str, Any]:
    """The whole report as a JSON-ready dict.  Its ``export`` is estimator_config.json itself
    (written from it), and report.md is rendered from this dict alone: one source for all
    three files."""
    chain = gap_chain(res)
    off = len(chain) - 1 - len(res.steps)     # 1 when layer_puncture has its own column
    effects = []
    if any(res.layers):
        effects.append({
            "name": "layer_puncture", "meaning": EFFECT_MEANING["layer_puncture"],
            "parameters": {"layers_per_trial": res.layers,
                           "ruptures": [t["ruptures"] for t in res.evidence["per_trial"]]},
            "score": {"local": "force drops seen in the first insertion; the multi-layer base "
                      "model switches to each layer's own parameters there"},
            "acts_on_phases": list(EFFECT_PHASES["layer_puncture"]),
            "errors_before": chain[0]["errors"] if off else None,
            "errors_after": chain[off]["errors"]})
    values = {step.effect: _effect_values(res, step.effect) for step in res.steps}
    for k, step in enumerate(res.steps):
        effects.append({
            "name": step.effect, "meaning": EFFECT_MEANING[step.effect],
            "parameters": _params_dict(values[step.effect]),
            "magnitude": _magnitude(res, k), "share_of_explained_gap": _share(res, k),
            "score": {"delta_bic_local": step.delta_bic, "heldout_gain": step.heldout_gain,
                      "own_phase_gain": step.own_phase_gain, "local_evidence": step.local},
            "acts_on_phases": list(EFFECT_PHASES[step.effect]),
            "errors_before": chain[k + off]["errors"], "errors_after": chain[k + off + 1]["errors"],
            "worsens": _worsens(step), "candidates": step.candidates})
    export = _export(res, values)
    base = base_paramset(res.fits[0])
    base_se = res.fits[0].nl_se or {}
    surf = np.atleast_1d(res.fits[0].nl["surface"])
    trials = [{"name": p.name, "samples": int(len(p.t_s)), "surface_offset_mm": p.surface_mm,
               "surface_correction_mm": float(surf[i]),
               "surface_fitted_mm": export["surface_mm"][i],
               "tare_n": export["tare_n"][i], "noise_n": p.noise_n,
               "puncture_depth_mm": p.puncture_mm, "speed_mm_s": p.speed_mm_s,
               "rate_hz": 1.0 / float(np.median(np.diff(p.t_s))),
               "cycles": _reversals(p.phase),
               "phase_samples": {ph: int(np.count_nonzero(p.phase == j))
                                 for j, ph in enumerate(PHASES)}}
              for i, p in enumerate(res.preps)]
    rep = _clean({
        "inputs": inputs, "named": res.named, "effects": effects,
        "verdict": verdict(res), "bounds": bounds_table(),
        "bound_violations": bound_violations(res), "flags": parameter_flags(res),
        "local_evidence": res.evidence, "validation": res.validation,
        "base_model": {"model": "II (alpha, f2 from the joint Model I fit; see DISCREPANCY.md), "
                                "plus one parameter set per detected layer",
                       "params": export["params"], "fitted_params": base.__dict__,
                       "floored": export["floored"], "from_layers": export["from_layers"],
                       "shape": {k: {"value": float(res.fits[0].nl[k]),
                                     "se": float(base_se[k]) if k in base_se else None}
                                 for k in ("p", "g0", "alpha")},
                       "layer_coefficients": {k: v for k, v in res.fits[0].coef.items()
                                              if k.startswith("layer")},
                       "zero_in_air": True},
        "trials": trials, "skipped": [{"name": n, "reason": r} for n, r in res.skipped],
        "shared_fit": len(res.preps) > 1, "heldout_scheme": res.heldout_scheme,
        "gap_models": [c["model"] for c in chain], "errors": [c["errors"] for c in chain],
        "final_round": res.last_round,
        "residual_stats_before": res.stats_before, "residual_stats_after": res.stats_after,
        "speed_direction": res.speed_dir, "notes": res.notes, "runtime_s": res.runtime_s,
        "export": export})
    rep["what_next"] = _clean(what_next(rep))     # read off the report itself
    return rep


def _reversals(phase: np.ndarray) -> int:
    """Insertion-to-retraction reversals in a trial (runs of the reversal phase)."""
    rev = (phase == PHASES.index("reversal")).astype(int)
    return int(np.count_nonzero(np.diff(np.concatenate([[0], rev])) == 1))


def _flag_lines(flags: list[dict[str, Any]]) -> list[str]:
    """One line per flagged parameter and kind; the trials of a per-trial value on one line."""
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
    for f in flags:
        key = (f["parameter"], f["kind"], f.get("side"), f["fit"], f.get("trial") is None)
        groups.setdefault(key, []).append(f)
    out = []
    for fs in groups.values():
        if len(fs) == 1 or fs[0].get("trial") is None:
            out += [_flag_text(f) for f in fs]
            continue
        f = fs[0]
        vals = ", ".join(f"{g['trial']}: {_fmt(g['value'])}" for g in fs)
        if f["kind"] == "at_bound":
            out.append(f"{f['parameter']} ({vals}) at its {f['side']} bound {_fmt(f['bound'])} "
                       f"({f['fit']} fit)")
        else:
            ses = ", ".join(f"{g['trial']}: {_fmt(g['se'])}" for g in fs)
            out.append(f"{f['parameter']} ({vals}) with standard errors ({ses}) above the values "
                       f"({f['fit']} fit)")
    return out


def _flag_text(f: dict[str, Any]) -> str:
    who = f"{f['parameter']}" + (f"[{f['trial']}]" if f.get("trial") else "")
    if f["kind"] == "at_bound":
        return (f"{who} = {_fmt(f['value'])} at its {f['side']} bound {_fmt(f['bound'])} "
                f"({f['fit']} fit)")
    return (f"{who} = {_fmt(f['value'])} with standard error {_fmt(f['se'])} above it "
            f"({f['fit']} fit)")


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
    described = [w for w in rep["verdict"]["where"] if "looks_like" in w]
    if described:
        head = ("A stick-slip series, then where the residual stays above the threshold "
                "(largest first):" if described[0]["looks_like"] == "periodic drops" else
                "Where the residual stays above the threshold (largest first):")
        L += [head, "",
              "| trial | phase | time (s) | depth (mm) | x noise | looks like |",
              "|---|---|---|---|---|---|"]
        L += [f"| {w['trial']} | {w['phase']} | {w['t_from_s']:.1f}-{w['t_to_s']:.1f} | "
              f"{w['depth_from_mm']:.1f}-{w['depth_to_mm']:.1f} | {w['over_noise']:.0f} | "
              f"{w['description']} |" for w in described[:5]]
        L += [""]
    val = rep["validation"]
    if "shrink" in val:
        L += [f"Held-out validation ({val['scheme']}): RMSE base {_fmt(val['rmse_base_n'])} N, "
              f"final {_fmt(val['rmse_final_n'])} N, shrink {_fmt(val['shrink'])}", ""]
    if rep["bound_violations"]:
        L += ["Parameters outside their bounds: " + "; ".join(rep["bound_violations"]), ""]
    if rep["flags"]:
        L += [f"**Check these values ({len(rep['flags'])} flag(s)): at a bound of their fit, or "
              "with a standard error above the value**", ""]
        L += [f"- FLAG {t}" for t in _flag_lines(rep["flags"])] + [""]
    else:
        L += ["No fitted value is at a bound or has a standard error above it.", ""]
    L += [f"- {n}" for n in rep["notes"]]
    if rep["skipped"]:
        L += [""] + [f"- skipped {s['name']}: {s['reason']}" for s in rep["skipped"]]
    L += ["", "## Trials", "", "| trial | samples | surface detected mm | surface correction mm "
          "| surface fitted mm | tare N | noise N | puncture mm | speed mm/s |",
          "|---|---|---|---|---|---|---|---|---|"]
    for t in rep["trials"]:
        L.append(f"| {t['name']} | {t['samples']} | {_fmt(t['surface_offset_mm'])} | "
                 f"{_fmt(t['surface_correction_mm'])} | {_fmt(t['surface_fitted_mm'])} | "
                 f"{_fmt(t['tare_n'])} | {_fmt(t['noise_n'])} | {_fmt(t['puncture_depth_mm'])} "
                 f"| {_fmt(t['speed_mm_s'])} |")
    bm = rep["base_model"]
    L += ["", "## 1. Base model", "", "As written to estimator_config.json:", ""]
    for k, v in bm["params"].items():
        fl, ly = bm["floored"].get(k), bm["from_layers"].get(k)
        L.append(f"- {k} = {_fmt(v)}"
                 + (f" (the layers' shaft friction over the depth; the base's own "
                    f"{_fmt(ly['fitted'])})" if ly else "")
                 + (f" (fitted {_fmt(fl['fitted'])}, floored)" if fl else ""))
    L += ["", "Shape of the fit (normalised):", ""]
    L += [f"- {k} = {_fmt(v['value'])}" + (f" ± {_fmt(v['se'])}" if v["se"] is not None else "")
          for k, v in bm["shape"].items()]
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
        if e.get("worsens"):
            w = e["worsens"]
            L += [f"- WARNING: its refit makes the {w['phase']} phase, which the model explained, "
                  f"worse: RMSE {_fmt(w['rmse_before_n'])} -> {_fmt(w['rmse_after_n'])} N (more "
                  f"than {_fmt(w['allowance_x_noise'])}x the noise)"]
        L += ["", "Parameters" + (" (final model, as exported):" if "magnitude" in e else ":")]
        L += [f"- {p} = {_fmt(v)}" for p, v in e["parameters"].items()]
        L += _candidate_table(e.get("candidates", []))
    if not rep["effects"]:
        L += ["No candidate is significant: `none` (the base model explains the data).", ""]
    if rep["final_round"]:
        L += ["### The last round's candidates", ""]
        L += _candidate_table(rep["final_round"])
    L += ["## 5. Gap before and after each added effect (RMSE / MAE, N)", ""]
    models = rep["gap_models"]
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
    if "what_next" in rep:
        L += [""] + render_next(rep["what_next"])
    L += ["", "## Figures", ""] + [f"![{Path(f).stem}]({f})" for f in figures]
    L += ["", f"Run time: {rep['runtime_s']:.2f} s", ""]
    return "\n".join(L)


def _candidate_table(candidates: list[dict[str, object]]) -> list[str]:
    """One round's candidates: score, held-out gain and, for a refused one, why."""
    L = ["| candidate | delta BIC | held-out gain | refused because |", "|---|---|---|---|"]
    for c in candidates:
        L.append(f"| {c['name']} | {_fmt(c.get('delta_bic'))} | {_fmt(c.get('heldout_gain'))} | "
                 f"{c.get('rejected', '')} |")
    return L + [""]


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


def one_layer_friction(res: Result) -> float | None:
    """The multi-layer base's shaft friction as one density over the depth, for a Model II
    config (one sigma2 for every depth): per trial with ruptures, sigma2 plus each band's own
    friction (fric_0 over [0, r_1], fric_j over [r_j, r_j+1]) times the length of the band the
    needle reached, over the deepest tissue depth -- the layered model's friction at the deepest
    point, spread evenly; the median over those trials.  None without ruptures (sigma2 is then
    the whole friction).  Written as sigma2 because the base's own sigma2 carries only what no
    band does: with every band's friction free, the fit puts it near 0 (skin-on-muscle records
    1-5: 0.0007 N/mm, floored; the estimator started there innovated 1.2x as much as from the
    paper's defaults, 3x as much as from this value; config_loop_figures.py --workflow)."""
    base = res.fits[0]
    per_trial = []
    for i, (p, t) in enumerate(zip(res.preps, res.evidence["per_trial"])):  # type: ignore
        if not t["ruptures"]:
            continue
        deepest, *_ = depths_below_fitted_surface([float(np.max(p.stage_mm - p.surface_mm))],
                                                  base.nl, i)
        if not deepest > 0.0:
            continue
        edges = [0.0] + depths_below_fitted_surface([r["depth_mm"] for r in t["ruptures"]],
                                                    base.nl, i) + [deepest]
        keys = [f"layer0_fric[{i}]"] + [f"layer{j + 1}_fric[{i}]"
                                        for j in range(len(t["ruptures"]))]
        force = sum(base.coef.get(k, 0.0) * max(0.0, min(hi, deepest) - max(lo, 0.0))
                    for k, lo, hi in zip(keys, edges[:-1], edges[1:]))
        per_trial.append(base.coef["sigma2"] + force / deepest)
    return float(np.median(per_trial)) if per_trial else None


def _export(res: Result, values: dict[str, list[dict[str, Any]]]) -> dict[str, Any]:
    """The estimator configuration (schema in DISCREPANCY.md §7): the base fit's parameters,
    surfaces and layers, and the named effects' shared parameters from ``values`` (the rows
    the report's effect parameters come from)."""
    base = res.fits[0]
    eff = {e: {r["name"]: r["value"] for r in rows if r["export"]}
           for e, rows in values.items()}
    layers = []
    for i, (p, t) in enumerate(zip(res.preps, res.evidence["per_trial"])):  # type: ignore
        coefs = {k.split("[")[0]: v for k, v in base.coef.items()
                 if k.startswith("layer") and k.endswith(f"[{i}]")}
        layers.append({"trial": p.name, "ruptures_mm": [r["depth_mm"] for r in t["ruptures"]],
                       "coefficients": coefs})
    noise = float(np.median([p.noise_n for p in res.preps]))
    fitted = base_paramset(base).__dict__
    spread = one_layer_friction(res)
    layered = {}
    if spread is not None:
        layered["sigma2"] = {"fitted": float(fitted["sigma2"]), "written": spread}
        fitted = {**fitted, "sigma2": spread}
    params, floored = readable_params(fitted, noise, max(float(np.max(p.stage_mm - p.surface_mm))
                                                         for p in res.preps))
    return _clean({
        "schema": CONFIG_SCHEMA, "source": "nte-discrepancy", "model": 2,
        "params": params, "floored": floored, "from_layers": layered,
        "r_n2": noise ** 2, "noise_n": noise,
        "surface_mm": [p.surface_mm + float(np.atleast_1d(base.nl["surface"])[i])
                       for i, p in enumerate(res.preps)],
        "tare_n": [p.tare_n for p in res.preps],
        "sign": {"force": [p.force_sign for p in res.preps],
                 "depth": [p.depth_sign for p in res.preps]},
        "layers": layers, "effects": eff})


def estimator_config(res: Result) -> dict[str, Any]:
    """The fitted base model as an estimator configuration: the report's ``export``."""
    return dict(build(res, [])["export"])


def write(res: Result, inputs: list[str], out: Path, with_figures: bool = True, jobs: int = 1
          ) -> dict[str, Any]:
    """The report in ``out`` through the tools' safe writer: report.json, report.md,
    estimator_config.json and the figures (drawn by ``jobs`` processes), every file or none."""
    from ..tools.safe_write import Outputs
    with Outputs() as outs:
        outs.directory(out, "--out")
        rep = build(res, inputs)
        figs: list[str] = []
        if with_figures:
            from .figures import draw
            figs = draw(res, out, lambda p: outs.add(p, "--out"), jobs)
        rep["figures"] = figs
        rep["estimator_config"] = "estimator_config.json"
        outs.write_text(outs.add(out / "report.json", "--out"), json.dumps(rep, indent=1))
        outs.write_text(outs.add(out / "report.md", "--out"), render_md(rep, figs))
        outs.write_text(outs.add(out / "estimator_config.json", "--out"),
                        json.dumps(rep["export"], indent=1))
        outs.commit()
    return rep
