"""Figures of an estimation run, after the paper's Figs. 4-7 (matplotlib, Agg backend)."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .estimate import EstimateRun


def plot_estimate(run: EstimateRun, path: str | os.PathLike[str], title: str = "") -> None:
    """Force vs depth (measured and estimated) and every parameter with a +-3 sigma band.

    Writes ``path`` directly: the caller makes it atomic (``safe_write.Outputs``)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(run.names)
    fig, axes = plt.subplots(1 + (n + 1) // 2, 2, figsize=(11, 3.0 * (1 + (n + 1) // 2)),
                             squeeze=False)
    ax_f = plt.subplot2grid(axes.shape, (0, 0), colspan=2, fig=fig)
    for ax in axes[0]:
        ax.remove()
    ax_f.plot(run.depth_mm, run.force_n, ".", ms=2, color="0.6", label="measured")
    ax_f.plot(run.depth_mm, run.force_hat_n.astype(float), "-", lw=1.2, color="C3",
              label="estimated")
    ax_f.set_xlabel("depth (mm)")
    ax_f.set_ylabel("force (N)")
    ax_f.legend(loc="best")
    ax_f.set_title(title or f"Model {'I' if run.model == 1 else 'II'}, {run.precision}")
    # parameters over depth: insertion (depth rising) and retraction drawn separately so each
    # band is filled along a monotonic depth axis
    rising = np.concatenate([[True], np.diff(run.depth_mm) >= 0])
    for j, name in enumerate(run.names):
        ax = axes[1 + j // 2][j % 2]
        est = run.params[:, j].astype(float)
        sd = run.params_sd[:, j].astype(float)
        for sel, colour, label in ((rising, "C0", "insertion"), (~rising, "C2", "retraction")):
            if not np.any(sel):
                continue
            x = np.where(sel, run.depth_mm, np.nan)
            ax.fill_between(x, est - 3 * sd, est + 3 * sd, color=colour, alpha=0.25, lw=0)
            ax.plot(x, est, color=colour, lw=1.0, label=f"{label} ±3σ")
        ax.set_xlabel("depth (mm)")
        ax.set_ylabel(name)
        ax.legend(loc="best", fontsize=8)
    for j in range(n, 2 * ((n + 1) // 2)):
        axes[1 + j // 2][j % 2].remove()
    fig.tight_layout()
    try:
        fig.savefig(str(path), dpi=110, format=Path(path).suffix.lstrip(".") or "png")
    finally:
        plt.close(fig)
