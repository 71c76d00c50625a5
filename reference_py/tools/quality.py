"""Estimation-quality runs over many seeds, summarised as the tables in the README."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from ..config import profile_config
from .evaluation import BOUNDS, make_scenario, metrics, passes, run_bank, start_values
from ..fmath import real_for
from ..params import get_preset
from ..robust import RobustConfig
from ..sim.trajectory import TrajectorySpec

METRIC_COLUMNS = (("rmse_ins_n", 1e3, "RMSE ins mN"), ("rmse_ret_n", 1e3, "RMSE ret mN"),
                  ("innov_rms_n", 1e3, "innov RMS mN"), ("nis_mean", 1.0, "mean NIS"),
                  ("replay_mae_n", 1e3, "replay MAE mN"))


@dataclass(frozen=True)
class QualityCase:
    preset: str = "paper-10mms"
    model: int = 2
    factor: float = 1.25
    precision: str = "float64"
    profile: str = "default"
    schedule: str = "all"
    seeds: int = 100
    cycles: int = 1
    estimator: str = "bank"

    def label(self) -> str:
        return (f"{self.estimator} {self.preset} M{'I' if self.model == 1 else 'II'} "
                f"×{self.factor:g} {self.precision} {self.profile}/{self.schedule}"
                + (f" {self.cycles} cycles" if self.cycles > 1 else ""))


#: the cases the README's quality table reports (`nte-ref evaluate --matrix`)
STANDARD_MATRIX: tuple[QualityCase, ...] = (
    QualityCase(factor=1.25, precision="float64"),
    QualityCase(factor=1.25, precision="float32"),
    QualityCase(factor=5.0, precision="float64"),
    QualityCase(factor=5.0, precision="float32"),
    QualityCase(factor=1.25, schedule="rotate"),
    QualityCase(factor=1.25, profile="paper"),
    QualityCase(model=1, factor=1.25),
    QualityCase(preset="paper-6mms", factor=1.25),
    QualityCase(preset="paper-6mms", factor=1.25, precision="float32"),
)


#: bank against robust estimator, three insertion cycles each (`nte-ref evaluate --robust-matrix`)
ROBUST_MATRIX: tuple[QualityCase, ...] = tuple(
    QualityCase(estimator=e, factor=f, cycles=3, precision=p)
    for e in ("bank", "robust") for f in (1.25, 5.0) for p in ("float64", "float32")) + (
    QualityCase(estimator="robust", preset="paper-6mms", factor=5.0, cycles=3),
    QualityCase(estimator="robust", preset="needleB-tissueB-10mms", factor=5.0, cycles=3),
    QualityCase(estimator="robust", preset="needleB-tissueB-6mms", factor=5.0, cycles=3),
    QualityCase(estimator="robust", preset="needleB-tissueA-10mms", factor=5.0, cycles=3),
)


@dataclass
class QualityResult:
    case: QualityCase
    metrics: dict[str, np.ndarray]
    passes: dict[str, np.ndarray]
    seconds: float
    first_cycle: dict[str, np.ndarray] | None = None   # metrics of cycle 1 (multi-cycle runs)
    first_passes: dict[str, np.ndarray] | None = None


def run_quality(case: QualityCase, progress: bool = False) -> QualityResult:
    preset = get_preset(case.preset)
    seeds = list(range(1, case.seeds + 1))
    spec = TrajectorySpec(speed_mm_s=preset.speed_mm_s, cycles=case.cycles)
    if case.cycles > 1:
        # bank and robust estimator alike rest at the surface until the robust estimator's
        # refinement of an insertion is adopted (one buffer entry a sample), to the next 0.1 s
        spec = replace(spec, rest_s=max(spec.rest_s, math.ceil(
            RobustConfig().slices() / spec.rate_hz * 10.0) / 10.0))
    sc = make_scenario(preset, seeds, spec)
    cfg = replace(profile_config(case.profile, case.model, case.schedule),
                  beta0=preset.params.beta)
    starts = [start_values(preset.params, s, case.factor, case.model) for s in seeds]
    t0 = time.perf_counter()
    res = run_bank(real_for(case.precision), cfg, sc, starts, progress=progress,
                   estimator=case.estimator)
    seconds = time.perf_counter() - t0
    m = metrics(sc, res)
    out = QualityResult(case, m, passes(m), seconds)
    if case.cycles > 1:
        out.first_cycle = metrics(sc, res, cycle=0)
        out.first_passes = passes(out.first_cycle)
    return out


def format_summary(results: list[QualityResult]) -> str:
    """A markdown table: median / 90th percentile of each metric, and pass counts."""
    multi = any(r.first_cycle is not None for r in results)
    head = ["case", "finite"] + [c[2] + " (med / p90)" for c in METRIC_COLUMNS] + [
        "pass all", "pass RMSE+replay", "pass replay"]
    if multi:
        head += ["cycle 1: replay MAE mN (med / p90)", "cycle 1: pass RMSE+replay"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in results:
        n = len(r.metrics["finite"])
        cells = [r.case.label(), f"{int(r.metrics['finite'].sum())}/{n}"]
        for key, scale, _ in METRIC_COLUMNS:
            v = r.metrics[key] * scale
            cells.append(f"{np.nanmedian(v):.3g} / {np.nanpercentile(v, 90):.3g}")
        cells += [f"{int(r.passes['all'].sum())}/{n}", f"{int(r.passes['identified'].sum())}/{n}",
                  f"{int(r.passes['replay'].sum())}/{n}"]
        if multi:
            if r.first_cycle is not None and r.first_passes is not None:
                v = r.first_cycle["replay_mae_n"] * 1e3
                cells += [f"{np.median(v):.3g} / {np.percentile(v, 90):.3g}",
                          f"{int(r.first_passes['identified'].sum())}/{n}"]
            else:
                cells += ["", ""]
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    lines.append("RMSE and replay of the last cycle (the only one for single-cycle runs); "
                 "innovation RMS and NIS over the whole run after the first second.")
    lines.append(f"bounds: RMSE ins ≤ {BOUNDS['rmse_ins_n'] * 1e3:g} mN, RMSE ret ≤ "
                 f"{BOUNDS['rmse_ret_n'] * 1e3:g} mN, innovation RMS ≤ "
                 f"{BOUNDS['innov_rms_n'] * 1e3:g} mN, mean NIS in [{BOUNDS['nis_lo']:g}, "
                 f"{BOUNDS['nis_hi']:g}], replay MAE ≤ {BOUNDS['replay_mae_n'] * 1e3:g} mN")
    return "\n".join(lines)
