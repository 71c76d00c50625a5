"""The figures of a phantom record, measured the way the 331 public trials were summarised.

``record_stats`` reads one record as the measured trials were read (insertion peak, ruptures,
dwell decay and its two time scales, retraction minimum, turn-over travel); ``lab_statistics``
summarises many ``lab`` records (p10 / median / p90) and ``format_stats_table`` sets them beside
the measured figures (:data:`reference_py.sim.calibration.MEASURED`): ``nte-ref phantom --stats``
and the tests that hold the generator to the measurements.
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from ..fmath import Array
from .calibration import LAB, MEASURED
from .phantom import PhantomResult, simulate_phantom


def record_stats(t_s: Array, depth_mm: Array, force_n: Array, cycle_marks: Sequence[dict[str, float]],
                 surface_mm: float | None = None) -> dict[str, float]:
    """Figures of the first cycle of a record (force and depth positive on insertion).

    baseline: median force in the rest before the stage starts; peak: maximum during insertion;
    ruptures: drops > 0.15 N within 0.1 s during insertion (on a 50 ms moving average; drops
    closer than 0.15 s count once);
    dwell decay: fall of the force over the dwell relative to its start (0.1 s means); retraction
    minimum; turn-over: stage travel from the reversal until the force first crosses zero.
    """
    m = cycle_marks[0]
    f = np.asarray(force_n, dtype=float)
    t = np.asarray(t_s, dtype=float)
    base = float(np.median(f[t < m["start_s"]])) if np.any(t < m["start_s"]) else 0.0
    f = f - base
    dtm = float(np.median(np.diff(t)))
    win = max(1, int(round(0.05 / dtm)))
    fs = np.convolve(f, np.ones(win) / win, mode="same")
    ins = (t >= m["start_s"]) & (t <= m["insertion_end_s"] - 0.05)
    peak = float(np.max(f[ins]))
    ruptures = count_drops(t, fs, ins)

    def mean_near(t0: float, t1: float) -> float:
        sel = (t >= t0) & (t <= t1)
        return float(np.mean(f[sel]))
    f_start = mean_near(m["insertion_end_s"], m["insertion_end_s"] + 0.1)
    f_end = mean_near(m["retraction_start_s"] - 0.1, m["retraction_start_s"])
    ret = (t >= m["retraction_start_s"]) & (t <= m["retraction_end_s"])
    rmin = float(np.min(fs[ret]))
    ir = np.flatnonzero(ret)
    cross = ir[np.flatnonzero(fs[ir] < 0.0)]
    x_rev = float(np.max(np.abs(depth_mm)))
    turn = float(x_rev - abs(depth_mm[cross[0]])) if cross.size else float("nan")
    imin = ir[int(np.argmin(fs[ir]))]
    dw = (t >= m["insertion_end_s"]) & (t <= m["retraction_start_s"])
    tau_fast, tau_slow = dwell_time_scales(t[dw] - m["insertion_end_s"], f[dw])
    out = {"peak_n": peak, "ruptures": float(ruptures),
           "dwell_decay_pct": 100.0 * (f_start - f_end) / f_start,
           "dwell_tau_fast_s": tau_fast, "dwell_tau_slow_s": tau_slow,
           "retraction_min_n": rmin, "turnover_mm": turn,
           "min_travel_mm": float(x_rev - abs(depth_mm[imin]))}
    if surface_mm is not None:
        out["surface_mm"] = float(surface_mm)
    return out


_TAU_FAST_GRID = np.geomspace(0.05, 1.0, 24)
_TAU_SLOW_GRID = np.geomspace(1.0, 20.0, 24)


def dwell_time_scales(t: Array, f: Array) -> tuple[float, float]:
    """Time constants (fast, slow) of f = c0 + c1 exp(-t/tau_1) + c2 exp(-t/tau_2) fitted by
    least squares over a log grid (tau_1 0.05-1 s, tau_2 1-20 s; the c linear)."""
    if t.size < 8:
        return float("nan"), float("nan")
    e1 = np.exp(-t[None, :] / _TAU_FAST_GRID[:, None])
    e2 = np.exp(-t[None, :] / _TAU_SLOW_GRID[:, None])
    n1, n2 = len(_TAU_FAST_GRID), len(_TAU_SLOW_GRID)
    A = np.empty((n1, n2, t.size, 3))            # every pair's design matrix at once
    A[..., 0] = 1.0
    A[..., 1] = e1[:, None, :]
    A[..., 2] = e2[None, :, :]
    q, r = np.linalg.qr(A)
    coef = np.linalg.solve(r, np.einsum("ijnk,n->ijk", q, f)[..., None])[..., 0]
    sse = np.sum((np.einsum("ijnk,ijk->ijn", A, coef) - f) ** 2, axis=-1)
    i, j = np.unravel_index(int(np.argmin(sse)), sse.shape)
    return float(_TAU_FAST_GRID[i]), float(_TAU_SLOW_GRID[j])


def count_drops(t: Array, fs: Array, sel: Array, drop_n: float = 0.15, within_s: float = 0.1,
                merge_s: float = 0.15) -> int:
    """Number of drops larger than drop_n within within_s, both ends inside sel; drops whose
    marked samples are closer than merge_s count as one."""
    idx = np.flatnonzero(sel)
    if idx.size < 2:
        return 0
    seg_t, seg_f = t[idx], fs[idx]
    j_end = np.searchsorted(seg_t, seg_t + within_s, side="right")
    # forward running minimum over (k, j_end[k]) by a sparse-table of minima
    n = seg_f.size
    levels = [seg_f]
    span = 1
    while 2 * span <= n:
        prev = levels[-1]
        levels.append(np.minimum(prev[:-span], prev[span:]) if prev.size > span else prev)
        span *= 2
    lo = np.arange(n) + 1
    hi = np.minimum(j_end, n)                     # exclusive
    length = hi - lo
    ok = length > 0
    lvl = np.zeros(n, dtype=int)
    lvl[ok] = np.floor(np.log2(length[ok])).astype(int)
    fmin = np.full(n, np.inf)
    for L in np.unique(lvl[ok]):
        rows = np.flatnonzero(ok & (lvl == L))
        tab = levels[L]
        w = 1 << L
        fmin[rows] = np.minimum(tab[lo[rows]], tab[hi[rows] - w])
    mark = np.flatnonzero((seg_f - fmin) > drop_n)
    if mark.size == 0:
        return 0
    return int(1 + np.count_nonzero(np.diff(seg_t[mark]) > merge_s))


def result_stats(res: PhantomResult) -> dict[str, float]:
    fs, ds = res.spec.sensor.force_sign, res.spec.sensor.depth_sign
    st = record_stats(res.t_s, ds * res.depth_mm, fs * res.force_n, res.truth["cycles"],
                      res.truth["surface_mm"])
    st["noise_mn"] = 1e3 * res.spec.sensor.noise_n
    st["rate_hz"] = res.spec.sensor.rate_hz
    return st


def lab_statistics(n: int = 100, first_seed: int = 1) -> dict[str, Any]:
    """Statistics over n lab records (seeds first_seed ...): p10/median/p90 and rupture shares."""
    rows = [result_stats(simulate_phantom(LAB, seed=s)) for s in range(first_seed, first_seed + n)]
    return summarise(rows)


def summarise(rows: list[dict[str, float]]) -> dict[str, Any]:
    out: dict[str, Any] = {"n": len(rows)}
    for key in ("rate_hz", "noise_mn", "surface_mm", "peak_n", "dwell_decay_pct",
                "dwell_tau_fast_s", "dwell_tau_slow_s", "retraction_min_n", "turnover_mm",
                "min_travel_mm"):
        vals = np.array([r[key] for r in rows if key in r and np.isfinite(r[key])])
        out[key] = tuple(float(q) for q in np.percentile(vals, [10, 50, 90])) if vals.size else None
    counts = np.array([int(r["ruptures"]) for r in rows])
    out["ruptures"] = {k: float(np.mean(np.minimum(counts, 5) == k)) for k in range(6)}
    return out


def format_stats_table(stats: dict[str, Any], presets: dict[str, dict[str, float]] | None = None,
                       first_seed: int = 1) -> str:
    """The lab statistics beside the measured ones (and one row per preset)."""
    lines = [f"{'figure':22s} {'measured p10/med/p90':>24s} {'phantom lab p10/med/p90':>26s}"]
    labels = {"rate_hz": "sampling, Hz", "noise_mn": "noise, mN", "surface_mm": "surface, mm",
              "peak_n": "insertion peak, N", "dwell_decay_pct": "dwell decay, %",
              "dwell_tau_fast_s": "dwell fast tau, s", "dwell_tau_slow_s": "dwell slow tau, s",
              "retraction_min_n": "retraction min, N", "turnover_mm": "turn-over travel, mm"}
    ranges = {"dwell_tau_fast_s": "~0.3", "dwell_tau_slow_s": "2 - 5"}
    for key, label in labels.items():
        meas = ranges.get(key) or " / ".join(f"{v:.3g}" for v in MEASURED[key])
        ph = stats.get(key)
        ph_txt = " / ".join(f"{v:.3g}" for v in ph) if ph else "-"
        lines.append(f"{label:22s} {meas:>24s} {ph_txt:>26s}")
    mr = MEASURED["ruptures"]
    pr = stats["ruptures"]
    meas_r = f"{mr[0]:.0%} {mr[1]:.0%} {mr[2]:.0%} {mr[3]:.0%} {mr[4] + mr[5]:.0%}"
    ph_r = f"{pr[0]:.0%} {pr[1]:.0%} {pr[2]:.0%} {pr[3]:.0%} {pr[4] + pr[5]:.0%}"
    lines.append(f"{'ruptures 0/1/2/3/4+':22s} {meas_r:>24s} {ph_r:>26s}")
    mt = stats.get("min_travel_mm")
    if mt:
        lines.append(f"{'min. travel, mm':22s} {'(not measured)':>24s} "
                     f"{' / '.join(f'{v:.3g}' for v in mt):>26s}")
    last = first_seed + stats["n"] - 1
    lines.append(f"(phantom: {stats['n']} lab records, seeds {first_seed}..{last}; turn-over = stage "
                 "travel from the reversal to the first zero crossing)")
    if presets:
        lines.append("")
        lines.append(f"{'preset':16s} {'peak N':>7s} {'rupt':>5s} {'decay %':>8s} "
                     f"{'ret.min N':>10s} {'turn mm':>8s} {'surface':>8s}")
        for name, st in presets.items():
            lines.append(f"{name:16s} {st['peak_n']:7.2f} {int(st['ruptures']):5d} "
                         f"{st['dwell_decay_pct']:8.1f} {st['retraction_min_n']:10.2f} "
                         f"{st['turnover_mm']:8.2f} {st['surface_mm']:8.1f}")
    return "\n".join(lines)
