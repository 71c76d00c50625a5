"""`nte-ref bench`: samples per second of the reference bank, float64 and float32, against the
same switching bank written with filterpy's ExtendedKalmanFilter class — measured in one run.

The scenario is the paper's 10 mm/s insertion repeated until it holds the requested number of
samples (10 000 by default), one run (batch of 1), the default tuning.  The filterpy version
runs the same model, RK3 transition and Jacobians but leaves the covariance algebra to filterpy
(and has no gate or guards); it exists to put our figures next to a well-known implementation.
"""
from __future__ import annotations

import time

import numpy as np

from ..bank import FilterBank
from ..config import default_config
from ..fmath import F32, F64, Real
from ..model import ScaledParams, clamp_depth, depth_terms, output, output_du, output_dz, smooth_sign
from ..params import FILTER_SUBSETS, IDX, PARAM_NAMES, get_preset
from ..rk3 import rk3_step
from ..sim.simulate import simulate_force
from ..sim.trajectory import TrajectorySpec, lspb_profile


def bench_scenario(samples: int):
    preset = get_preset("paper-10mms")
    cycles = 1
    while True:
        t, l, v, _ = lspb_profile(TrajectorySpec(cycles=cycles))
        if len(t) >= samples:
            break
        cycles += 1
    t, l, v = t[:samples], l[:samples], v[:samples]
    f = simulate_force(preset.params, t, l, v)[0][0]
    f = f + np.random.default_rng(1).normal(0.0, 2e-3, len(f))
    return preset, np.floor(t * 1e6 + 0.5).astype(np.int64), l, v, f


def time_reference(R: Real, preset, t_us, l, v, f, batch: int = 1  # type: ignore[no-untyped-def]
                   ) -> float:
    """Seconds to run ``batch`` copies of the scenario side by side on the batch axis."""
    bank = FilterBank(R, default_config(), [preset.params.as_list()] * batch)
    la, va, fa = (np.repeat(R.arr(x)[:, None], batch, axis=1) for x in (l, v, f))
    ta = np.repeat(t_us[:, None], batch, axis=1)
    t0 = time.perf_counter()
    for k in range(len(t_us)):
        bank.step(ta[k], la[k], va[k], fa[k])
    return time.perf_counter() - t0


def time_filterpy(preset, t_us, l, v, f) -> float:  # type: ignore[no-untyped-def]
    from filterpy.kalman import ExtendedKalmanFilter

    cfg = default_config()
    R = F64
    sp = ScaledParams(R, preset.params.as_list(), 1)
    u = [R.full(1, 0.0) for _ in PARAM_NAMES]
    th = sp.theta(u)
    subsets = FILTER_SUBSETS[cfg.model]
    filters = []
    for names in subsets:
        n = len(names) + 1
        kf = ExtendedKalmanFilter(dim_x=n, dim_z=1)
        kf.P = np.diag([cfg.p0_z] + [cfg.p0_u] * (n - 1))
        kf.Q = np.diag([cfg.q_z] + [cfg.q_for(nm) for nm in names])
        kf.R = np.array([[cfg.r_n2]])
        filters.append(kf)
    z = np.zeros(1)
    eps = R.full(1, cfg.eps_mm_s)
    t0 = time.perf_counter()
    for k in range(1, len(t_us)):
        dt = R.full(1, (t_us[k] - t_us[k - 1]) / 1e6)
        la, lb = clamp_depth(R, R.full(1, l[k - 1])), clamp_depth(R, R.full(1, l[k]))
        s = smooth_sign(R, R.full(1, v[k]), eps)
        z_post = z
        for names, kf in zip(subsets, filters):
            pred = rk3_step(R, th, z, la, lb, dt, cfg.substeps, names)
            zp = pred.z if lb[0] > 0 else np.zeros(1)
            n = len(names) + 1
            F = np.eye(n)
            F[0, 0] = pred.dz_dz0[0] if lb[0] > 0 else 0.0
            for a, nm in enumerate(names):
                F[0, a + 1] = pred.dz_du[nm][0] if lb[0] > 0 else 0.0
            kf.F = F
            kf.x = np.array([[zp[0]]] + [[u[IDX[nm]][0]] for nm in names])
            kf.P = F @ kf.P @ F.T + kf.Q
            d = depth_terms(R, th, lb)
            o = output(th, d, zp, s)
            H = np.array([[output_dz(th, d, o)[0]] +
                          [output_du(th, d, zp, o, nm)[0] for nm in names]])
            kf.update(np.array([f[k]]), HJacobian=lambda _x, H=H: H,
                      Hx=lambda _x, h=o.h[0]: np.array([[h]]))
            for a, nm in enumerate(names):
                u[IDX[nm]] = np.array([kf.x[a + 1, 0]])
            th = sp.refresh(th, u, names)
            z_post = np.array([kf.x[0, 0]])
        z = z_post
    return time.perf_counter() - t0


def time_c_program(exe, preset, t_us, l, v, f) -> float | None:  # type: ignore[no-untyped-def]
    """Seconds for the C host program on the same samples (whole process, CSV I/O included)."""
    import os
    import subprocess
    import tempfile
    if not os.path.exists(exe):
        return None
    with tempfile.TemporaryDirectory() as tmp:
        src, out = os.path.join(tmp, "in.csv"), os.path.join(tmp, "out.csv")
        with open(src, "w") as fh:
            fh.write("t_s,depth_mm,velocity_mm_s,force_n\n")
            for row in zip(t_us / 1e6, l, v, f):
                fh.write("%.17g,%.17g,%.17g,%.17g\n" % row)
        t0 = time.perf_counter()
        subprocess.run([exe, src, "--model", "2", "--preset", preset.name, "--out", out],
                       check=True, capture_output=True)
        return time.perf_counter() - t0


def run_bench(samples: int = 10_000) -> dict[str, float]:
    preset, t_us, l, v, f = bench_scenario(samples)
    n = len(t_us)
    print(f"scenario: paper-10mms, {n} samples, Model II bank (three filters every sample), "
          f"one run")
    results = {
        "reference float64": n / time_reference(F64, preset, t_us, l, v, f),
        "reference float32": n / time_reference(F32, preset, t_us, l, v, f),
        "filterpy EKF class (float64)": n / time_filterpy(preset, t_us, l, v, f),
    }
    # the batch axis is how the test suite runs 100 seeds at once: samples of all runs per second
    m = min(n, 1000)
    results["reference float64, batch of 100"] = (
        100 * m / time_reference(F64, preset, t_us[:m], l[:m], v[:m], f[:m], batch=100))
    from pathlib import Path
    bindir = Path(__file__).resolve().parents[2] / "build" / "host" / "bin"
    for label, exe in (("C nte-run float (whole process)", "nte-run"),
                       ("C nte-run-double (whole process)", "nte-run-double")):
        secs = time_c_program(str(bindir / exe), preset, t_us, l, v, f)
        if secs is not None:
            results[label] = n / secs
    base = results["reference float64"]
    print(f"{'implementation':34s} {'samples/s':>10s} {'vs reference float64':>22s}")
    for name, rate in results.items():
        print(f"{name:34s} {rate:10.0f} {rate / base:21.2f}x")
    return results
