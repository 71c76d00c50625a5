"""Residual statistics per phase: where and how the model and the measurements disagree."""
from __future__ import annotations

import numpy as np
from scipy.signal import lombscargle

from ..fmath import Array
from .prep import PHASES, Prepared


def _period(t: Array, r: Array) -> tuple[float, float]:
    """Dominant frequency (Hz, 0.1-1 Hz) and the share of residual power it explains."""
    if len(t) < 20 or t[-1] - t[0] < 5.0:
        return float("nan"), 0.0
    freqs = np.linspace(0.1, 1.0, 91)
    rc = r - r.mean()
    pw = lombscargle(t, rc, 2 * np.pi * freqs)
    k = int(np.argmax(pw))
    share = float(2.0 * pw[k] / (len(t) * np.var(rc) + 1e-30))
    return float(freqs[k]), float(min(share, 1.0))


def phase_stats(preps: list[Prepared], resid: list[Array]) -> dict[str, dict[str, float]]:
    """Bias, RMS, trend, decay and periodicity of the residual in each phase (all trials)."""
    out: dict[str, dict[str, float]] = {}
    for j, name in enumerate(PHASES):
        ts, rs = [], []
        decays = []
        for p, r in zip(preps, resid):
            sel = p.phase == j
            if not sel.any():
                continue
            ts.append(p.t_s[sel]); rs.append(r[sel])
            rr = r[sel]
            third = max(len(rr) // 3, 1)
            decays.append(float(np.mean(rr[:third]) - np.mean(rr[-third:])))
        if not ts:
            continue
        t, r = np.concatenate(ts), np.concatenate(rs)
        trend = float(np.polyfit(t - t.mean(), r, 1)[0]) if len(t) > 2 else 0.0
        freq, share = _period(np.concatenate(ts), r)
        out[name] = {"n": int(len(r)), "bias_n": float(r.mean()),
                     "rms_n": float(np.sqrt(np.mean(r ** 2))), "trend_n_per_s": trend,
                     "decay_n": float(np.mean(decays)), "period_hz": freq,
                     "period_power_share": share}
    return out


def speed_direction(preps: list[Prepared], resid: list[Array]) -> dict[str, object]:
    """How the residual depends on speed (per-trial bias while moving) and on direction."""
    ins, ret = PHASES.index("insertion"), PHASES.index("retraction")
    per_trial = []
    for p, r in zip(preps, resid):
        bi = float(np.mean(r[p.phase == ins])) if (p.phase == ins).any() else float("nan")
        br = float(np.mean(r[p.phase == ret])) if (p.phase == ret).any() else float("nan")
        per_trial.append({"trial": p.name, "speed_mm_s": p.speed_mm_s,
                          "bias_insertion_n": bi, "bias_retraction_n": br})
    speeds = np.array([d["speed_mm_s"] for d in per_trial])
    slope = float("nan")
    if len(per_trial) >= 2 and np.ptp(speeds) > 0:
        diff = np.array([d["bias_insertion_n"] - d["bias_retraction_n"] for d in per_trial])
        slope = float(np.polyfit(speeds, diff, 1)[0])
    return {"per_trial": per_trial, "friction_bias_slope_n_per_mm_s": slope}
