"""A Model III truth for the tests: the reference model's own equations run forward (float64).

The force of Model III (reference_py/MODEL.md §3b) along an LSPB insertion, dwell and
retraction: z by the reference's RK3 / exponential step on 10 sub-steps per sample, the
direction state s by its exact per-sample update, the elastic force fe = sigma0 z l + s l fr,
each relaxation memory m_i <- a_i m_i + (1 - a_i) fe and the published force fe - sum g_i m_i;
z, s and m reset at the surface.  Gaussian noise is added with a fixed seed.

    python tests/python/model3_truth.py OUT.csv     # write one record (for a look)
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from reference_py.fmath import F64  # noqa: E402
from reference_py.model import ScaledParams, clamp_depth, depth_terms, output  # noqa: E402
from reference_py.params import ParamSet, get_preset  # noqa: E402
from reference_py.rk3 import rk3_step  # noqa: E402
from reference_py.sim.trajectory import TrajectorySpec, lspb_profile  # noqa: E402


def model3_force(p: ParamSet, t: np.ndarray, l: np.ndarray, g: tuple[float, ...],
                 tau: tuple[float, ...], delta: float) -> tuple[np.ndarray, np.ndarray]:
    """(force, elastic force) of Model III with the physical parameters p, strengths g and time
    constants tau (one entry per branch), turn-over length delta (mm)."""
    R = F64
    th = ScaledParams(R, p.as_list(), 1).theta([R.full(1, 0.0)] * 7)
    n = len(t)
    f = np.zeros(n)
    fe_all = np.zeros(n)
    z = R.full(1, 0.0)
    s = 0.0
    m = [0.0] * len(g)
    for k in range(1, n):
        la, lb = float(clamp_depth(R, R.arr([l[k - 1]]))[0]), float(clamp_depth(R, R.arr([l[k]]))[0])
        dt = t[k] - t[k - 1]
        if lb <= 0.0:
            z, s, m = R.full(1, 0.0), 0.0, [0.0] * len(g)
            continue
        z = rk3_step(R, th, z, R.arr([la]), R.arr([lb]), R.arr([dt]), 10).z
        dl = lb - la
        sig = float(np.sign(dl))
        s = sig + (s - sig) * np.exp(-abs(dl) / delta)
        d = depth_terms(R, th, R.arr([lb]))
        fe = float(output(th, d, z, R.arr([s])).h[0])
        m = [np.exp(-dt / tk) * mk + (1.0 - np.exp(-dt / tk)) * fe for mk, tk in zip(m, tau)]
        f[k] = fe - sum(gk * mk for gk, mk in zip(g, m))
        fe_all[k] = fe
    return f, fe_all


def model3_record(depth: float = 30.0, speed: float = 10.0, dwell: float = 3.0,
                  rate: float = 100.0, noise: float = 2e-3, seed: int = 1,
                  g: tuple[float, ...] = (0.15, 0.2), tau: tuple[float, ...] = (0.3, 3.0),
                  delta: float = 1.5, preset: str = "paper-10mms") -> list[str]:
    """CSV lines (t_s, depth_mm, velocity_mm_s, force_n, force_true_n) of one record."""
    spec = TrajectorySpec(depth_mm=depth, speed_mm_s=speed, accel_mm_s2=100.0, dwell_s=dwell,
                          rate_hz=rate)
    t, l, v, _ = lspb_profile(spec)
    truth, _ = model3_force(get_preset(preset).params, t, l, g, tau, delta)
    noisy = truth + np.random.default_rng(seed).normal(0.0, noise, len(t))
    lines = ["t_s,depth_mm,velocity_mm_s,force_n,force_true_n"]
    lines += ["%.17g,%.17g,%.17g,%.17g,%.17g" % row for row in zip(t, l, v, noisy, truth)]
    return lines


if __name__ == "__main__":
    Path(sys.argv[1]).write_text("\n".join(model3_record()) + "\n")
