"""Running the estimator over one recorded or simulated insertion (the ``estimate`` command)."""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..bank import FilterBank, identified_names
from ..config import ContactConfig, EstimatorConfig, profile_config
from .csvio import Trial, format_real, time_us
from ..fmath import Array, real_for
from ..params import Preset
from ..starts import start_values

ESTIMATORS = ("bank", "robust")


@dataclass
class EstimateRun:
    precision: str
    model: int
    t_s: Array
    depth_mm: Array
    force_n: Array
    force_hat_n: Array
    z: Array
    innovation_n: Array
    status: Array
    params: Array        # (samples, n_identified)
    params_sd: Array
    names: tuple[str, ...]
    confidence: Array | None = None   # robust estimator only: confidence of the last refinement
    # the contact front end, when on: surface_mm (stage mm, NaN until found), tare_n (N), state
    contact: tuple[Array, Array, Array] | None = None
    config: EstimatorConfig | None = None   # the configuration the estimator ran with
    layer: Array | None = None  # Model III's layer index (layers on), per sample


def make_config(preset: Preset, model: int, profile: str, schedule: str,
                overrides: dict[str, object] | None = None) -> EstimatorConfig:
    """The profile's configuration; ``overrides``: fields to change (Model III's switches and
    constants from the command line)."""
    cfg = profile_config(profile, model, schedule)
    # Model I's fixed beta0 is the preset's beta (MODEL.md §2)
    return replace(cfg, beta0=preset.params.beta, **(overrides or {}))


def run_estimate(trial: Trial, preset: Preset, model: int, estimator: str = "bank",
                 precision: str = "float64", profile: str = "default", schedule: str = "all",
                 init_seed: int = 0, init_factor: float = 5.0, progress: bool = False,
                 overrides: dict[str, object] | None = None,
                 contact: ContactConfig | None = None,
                 strengths: dict[str, float] | None = None) -> EstimateRun:
    if estimator not in ESTIMATORS:
        raise ValueError(f"unknown estimator {estimator!r} (known: {', '.join(ESTIMATORS)})")
    R = real_for(precision)
    cfg = make_config(preset, model, profile, schedule, overrides)
    if contact is not None:
        cfg = replace(cfg, contact=contact)
    nominal = start_values(preset.params.as_list(), init_seed, init_factor, model)
    if strengths:
        # Model III's nominal relaxation strengths from --config (the bank appends its
        # defaults to seven values)
        from ..params import RELAX_NAMES
        nominal = nominal + [float(strengths[nm]) for nm in RELAX_NAMES]
    if estimator == "robust":
        from ..robust import RobustEstimator
        est = RobustEstimator(R, cfg, [nominal])
    else:
        est = FilterBank(R, cfg, [nominal])
    n = len(trial.t_s)
    t_us = time_us(trial.t_s)
    names = identified_names(cfg)
    fh = np.zeros(n, dtype=R.dtype)
    z = np.zeros(n, dtype=R.dtype)
    inn = np.zeros(n, dtype=R.dtype)
    st = np.zeros(n, dtype=np.uint32)
    pars = np.zeros((n, len(names)), dtype=R.dtype)
    sds = np.zeros((n, len(names)), dtype=R.dtype)
    conf = np.zeros(n, dtype=R.dtype) if estimator == "robust" else None
    cont = ((np.zeros(n, dtype=R.dtype), np.zeros(n, dtype=R.dtype), np.zeros(n, dtype=np.uint32))
            if cfg.contact.enabled else None)
    layer = np.zeros(n, dtype=np.uint32) if (model == 3 and cfg.layers) else None
    it = range(n)
    if progress:
        from tqdm import tqdm
        it = tqdm(it, desc="estimating", unit="sample", disable=None, leave=False)
    depth = R.arr(trial.depth_mm)
    vel = R.arr(trial.velocity_mm_s)
    force = R.arr(trial.force_n)
    for k in it:
        o = est.step(t_us[k:k + 1], depth[k:k + 1], vel[k:k + 1], force[k:k + 1])
        fh[k], z[k], inn[k], st[k] = o.force_hat[0], o.z[0], o.innovation[0], o.status[0]
        pars[k], sds[k] = o.params[:, 0], o.params_sd[:, 0]
        if conf is not None:
            conf[k] = est.confidence[0]  # type: ignore[union-attr]
        if cont is not None:
            cont[0][k], cont[1][k], cont[2][k] = o.surface_mm[0], o.tare_n[0], o.contact[0]
        if layer is not None:
            layer[k] = o.layer[0]
    return EstimateRun(precision, model, trial.t_s, trial.depth_mm, trial.force_n, fh, z, inn, st,
                       pars, sds, names, conf, cont, cfg, layer)


#: the estimator configuration files' schema (the discrepancy workflow writes the same one;
#: estconfig.py reads it)
from .estconfig import CONFIG_SCHEMA  # noqa: E402
from .export_select import EXPORT_CANDIDATES, ReplayChoice  # noqa: E402


def export_config(run: EstimateRun, choice: "ReplayChoice") -> dict[str, object]:
    """What the estimator identified, as an estimator configuration (``--export-config``): the
    seven force-model parameters and their standard deviations: the snapshot that replays the
    record best from depth alone, fitted to it (export_select.py, export_refine.py; the fixed
    ones at the preset, sd 0; Model I's beta is its fixed beta0), the replay's figures, the noise variance and, for Model III,
    its switches, constants and identified strengths; with the contact front end on, the
    surface and tare it ended with."""
    import math
    from ..params import PARAM_NAMES
    cfg = run.config
    assert cfg is not None
    out: dict[str, object] = {
        "schema": CONFIG_SCHEMA, "source": "nte-ref estimate", "model": run.model,
        "params": dict(zip(PARAM_NAMES, choice.params)),
        "params_sd": dict(zip(PARAM_NAMES, choice.params_sd)),
        "r_n2": float(cfg.r_n2), "samples": len(run.t_s),
        "replay": {"t_s": choice.t_s, "candidates": EXPORT_CANDIDATES,
                   "rmse_n": _json_real(choice.rmse_n),
                   "final_rmse_n": _json_real(choice.final_rmse_n),
                   "peak_n": _json_real(choice.peak_n),
                   "fit_rmse_n": _json_real(choice.fit_rmse_n),
                   "fit_passes": choice.fit_passes}}
    if run.model == 3:
        out["model3"] = {
            "direction_memory": cfg.direction_memory, "presliding_mm": choice.presliding_mm,
            "relaxation": cfg.relaxation, "relax_branches": cfg.relax_branches,
            "tau_fast_s": cfg.tau_fast_s, "tau_slow_s": cfg.tau_slow_s,
            "strengths": choice.strengths, "strengths_sd": choice.strengths_sd}
        if choice.layer_sets:
            from ..params import LAYER_SET_NAMES
            out["model3"]["layer_sets"] = [  # type: ignore[index]
                {"start_mm": start, **dict(zip(LAYER_SET_NAMES, values)),
                 "sd": {nm: _json_real(x) for nm, x in zip(LAYER_SET_NAMES, sds)}}
                for start, values, sds in choice.layer_sets]
    if run.contact is not None:
        surface = float(run.contact[0][-1])
        out["surface_mm"] = surface if math.isfinite(surface) else None
        out["tare_n"] = float(run.contact[1][-1])
    return out


def _json_real(x: float) -> float | None:
    """A float for JSON, null when not finite (NaN is not JSON)."""
    import math
    return float(x) if math.isfinite(x) else None


def final_estimates_lines(run: EstimateRun) -> list[str]:
    """What ``estimate`` prints of the estimates: the bank's shared model at the last sample,
    each parameter as the filter that owns it (Table I) left it, with its standard deviation."""
    from ..bank import filter_subsets
    assert run.config is not None
    owner = {name: i + 1 for i, names in enumerate(filter_subsets(run.config)) for name in names}
    roman = "I" * run.model
    lines = [f"{len(run.t_s)} samples, Model {roman}, {run.precision}; final estimates (± 1 sd): "
             f"the bank's shared model at the last sample, each parameter as the filter that "
             f"owns it (Table I) left it:"]
    for j, name in enumerate(run.names):
        lines.append(f"  {name:7s} = {float(run.params[-1, j]):.6g} ± "
                     f"{float(run.params_sd[-1, j]):.3g}  (filter {owner[name]})")
    return lines


def estimate_csv_lines(run: EstimateRun) -> list[str]:
    """The estimate file, line by line: the same text the C host program writes."""
    header = ["t_s", "force_hat_n", "z", "innovation_n", "status"]
    for name in run.names:
        header += [name, name + "_sd"]
    if run.confidence is not None:
        header.append("confidence")
    if run.contact is not None:
        header += ["surface_mm", "tare_n", "contact"]
    if run.layer is not None:
        header.append("layer")
    lines = [",".join(header)]
    p = run.precision
    for k in range(len(run.t_s)):
        cells = ["%.17g" % float(run.t_s[k]), format_real(run.force_hat_n[k], p),
                 format_real(run.z[k], p), format_real(run.innovation_n[k], p),
                 "%d" % int(run.status[k])]
        for j in range(len(run.names)):
            cells += [format_real(run.params[k, j], p), format_real(run.params_sd[k, j], p)]
        if run.confidence is not None:
            cells.append(format_real(run.confidence[k], p))
        if run.contact is not None:
            cells += [format_real(run.contact[0][k], p), format_real(run.contact[1][k], p),
                      "%d" % int(run.contact[2][k])]
        if run.layer is not None:
            cells.append("%d" % int(run.layer[k]))
        lines.append(",".join(cells))
    return lines


__all__ = ["EstimateRun", "run_estimate", "estimate_csv_lines", "final_estimates_lines",
           "make_config", "export_config", "CONFIG_SCHEMA"]
