"""Estimation-quality runs over many seeds, summarised as the tables in the README."""
from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from .config import profile_config
from .evaluation import BOUNDS, make_scenario, metrics, passes, run_bank, start_values
from .fmath import real_for
from .params import get_preset
from .trajectory import TrajectorySpec

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

    def label(self) -> str:
        return (f"{self.preset} M{'I' if self.model == 1 else 'II'} ×{self.factor:g} "
                f"{self.precision} {self.profile}/{self.schedule}"
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


@dataclass
class QualityResult:
    case: QualityCase
    metrics: dict[str, np.ndarray]
    passes: dict[str, np.ndarray]
    seconds: float


def run_quality(case: QualityCase, progress: bool = False) -> QualityResult:
    preset = get_preset(case.preset)
    seeds = list(range(1, case.seeds + 1))
    spec = TrajectorySpec(speed_mm_s=preset.speed_mm_s, cycles=case.cycles)
    sc = make_scenario(preset, seeds, spec)
    cfg = replace(profile_config(case.profile, case.model, case.schedule),
                  beta0=preset.params.beta)
    starts = [start_values(preset.params, s, case.factor, case.model) for s in seeds]
    t0 = time.perf_counter()
    res = run_bank(real_for(case.precision), cfg, sc, starts, progress=progress)
    seconds = time.perf_counter() - t0
    m = metrics(sc, res)
    return QualityResult(case, m, passes(m), seconds)


def format_summary(results: list[QualityResult]) -> str:
    """A markdown table: median / 90th percentile of each metric, and pass counts."""
    head = ["case", "finite"] + [c[2] + " (med / p90)" for c in METRIC_COLUMNS] + [
        "pass all", "pass replay"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in results:
        n = len(r.metrics["finite"])
        cells = [r.case.label(), f"{int(r.metrics['finite'].sum())}/{n}"]
        for key, scale, _ in METRIC_COLUMNS:
            v = r.metrics[key] * scale
            cells.append(f"{np.nanmedian(v):.3g} / {np.nanpercentile(v, 90):.3g}")
        cells += [f"{int(r.passes['all'].sum())}/{n}", f"{int(r.passes['replay'].sum())}/{n}"]
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    lines.append(f"bounds: RMSE ins ≤ {BOUNDS['rmse_ins_n'] * 1e3:g} mN, RMSE ret ≤ "
                 f"{BOUNDS['rmse_ret_n'] * 1e3:g} mN, innovation RMS ≤ "
                 f"{BOUNDS['innov_rms_n'] * 1e3:g} mN, mean NIS in [{BOUNDS['nis_lo']:g}, "
                 f"{BOUNDS['nis_hi']:g}], replay MAE ≤ {BOUNDS['replay_mae_n'] * 1e3:g} mN")
    return "\n".join(lines)
