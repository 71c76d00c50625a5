"""Figures of the report (matplotlib, Agg): per trial, force vs time with phases shaded, force vs
depth, and the residual before and after the added effects."""
from __future__ import annotations

from pathlib import Path
from typing import Callable

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .pool import forked  # noqa: E402
from .prep import PHASES  # noqa: E402
from .workflow import Result  # noqa: E402

_COLORS = {"out_of_tissue": "#eeeeee", "loading": "#fde0c5", "insertion": "#d4e8d4",
           "dwell": "#d6e2f5", "reversal": "#f5d6e8", "retraction": "#e8e0f5",
           "after_exit": "#f0f0e0"}


def _shade(ax, t: np.ndarray, phase: np.ndarray) -> None:  # type: ignore[no-untyped-def]
    edges = np.nonzero(np.diff(phase))[0] + 1
    starts = np.concatenate([[0], edges])
    stops = np.concatenate([edges, [len(t)]])
    seen = set()
    for a, b in zip(starts, stops):
        name = PHASES[int(phase[a])]
        ax.axvspan(t[a], t[min(b, len(t) - 1)], color=_COLORS[name], lw=0,
                   label=None if name in seen else name)
        seen.add(name)


def draw(res: Result, out: Path, place: Callable[[Path], Path] = lambda p: p, jobs: int = 1
         ) -> list[str]:
    """Write the figures, one per trial (``jobs`` > 1: drawn by that many worker processes,
    forked, the same bytes); returns their file names (relative to ``out``).  ``place`` gives
    the file to write for a name (the safe writer's), asked here, in this process."""
    names = [f"trial{i}_{p.name}.png" for i, p in enumerate(res.preps)]
    tasks = [(res, i, place(out / name)) for i, name in enumerate(names)]
    if jobs > 1 and len(tasks) > 1:
        with forked(jobs) as pool:
            list(pool.map(_draw_trial, *zip(*tasks)))
    else:
        for t in tasks:
            _draw_trial(*t)
    return names


def _draw_trial(res: Result, i: int, path: Path) -> None:
    """Trial i's figure: force vs time, force vs depth, the residual before and after."""
    last = "+".join(s.effect for s in res.steps) or "base"
    p = res.preps[i]
    # a fixed layout and fixed legend places: tight_layout draws the figure once more and
    # loc="best" searches the data for a free corner (together 1.5 s of 2.7 s for six trials)
    fig, axes = plt.subplots(3, 1, figsize=(9, 9))
    fig.subplots_adjust(left=0.09, right=0.98, bottom=0.06, top=0.96, hspace=0.45)
    ax = axes[0]
    _shade(ax, p.t_s, p.phase)
    ax.plot(p.t_s, p.force_n + p.tare_n, "k.", ms=1.5, label="measured")
    ax.plot(p.t_s, res.predictions[0][i], "C0-", lw=1, label="base model")
    if len(res.predictions) > 1:
        ax.plot(p.t_s, res.predictions[-1][i], "C3-", lw=1, label=f"base {last}")
    ax.set(xlabel="t (s)", ylabel="force (N)", title=f"{p.name}: force vs time")
    ax.legend(fontsize=6, ncol=4, loc="upper right")
    ax = axes[1]
    l = p.stage_mm - p.surface_mm
    ax.plot(l, p.force_n + p.tare_n, "k.", ms=1.5, label="measured")
    ax.plot(l, res.predictions[-1][i], "C3-", lw=1, label="final model")
    ax.set(xlabel="depth below surface (mm)", ylabel="force (N)", title="force vs depth")
    ax.legend(fontsize=6, loc="upper left")
    ax = axes[2]
    ax.plot(p.t_s, p.force_n + p.tare_n - res.predictions[0][i], "C0.", ms=1.5,
            label="residual, base")
    ax.plot(p.t_s, p.force_n + p.tare_n - res.predictions[-1][i], "C3.", ms=1.5,
            label=f"residual, base {last}")
    ax.set(xlabel="t (s)", ylabel="residual (N)", title="residual before and after")
    ax.legend(fontsize=6, loc="upper right")
    fig.savefig(path, dpi=80, format="png")
    plt.close(fig)
