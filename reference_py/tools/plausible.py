"""Random plausible scenarios: every output finite, |force_hat| within 10x the input's force.

    nte-ref plausible [--scenarios N] [--first-seed K] [--jobs J] [--engine c|reference]
                      [--c-bin DIR] [--batch B] [--show S]

Each scenario is drawn from its own seed (numpy default_rng(seed)), so any one can be rerun
alone (--first-seed K --scenarios 1): a preset's parameters as the truth; an LSPB insertion
(speed 0.4-50 mm/s log-uniform, depth 5-150 mm, dwell 0-60 s, blends 100-10 000 mm/s^2)
sampled at 20-1 000 Hz (log-uniform; one in four irregular, every time stamp jittered by up
to +-40 % of the period); white force noise 0.5-50 mN (log-uniform); Model I or II; float32 or
float64; the bank (9 in 10) or the robust estimator; the start at the preset with each
identified parameter multiplied by up to a factor 1-5 (starts.py); and with probability 1/4
each: a depth jump (the depth signal steps by 2-20 mm for 0.2-2 s, a slipping encoder), a
saturated force sensor (clipped at 40-90 % of the peak) and an inverted force sign (a sensor
mounted the other way round).  A scenario is capped at MAX_SAMPLES samples: past it the dwell
is shortened, then the rate lowered (never below 20 Hz), then the depth.

The property, on every sample: force_hat, z and the innovation finite, and |force_hat| <=
10 x the largest |force| of the input (within ROUNDING: the estimator enforces the same factor,
reference_py/bank.py DATA_BOUND, in its own precision).  Engine c (default): each scenario is
written to a temporary CSV and estimated by the C library's host programs (nte-run, nte-run-double in
--c-bin, default build/host/bin; make build), which agree with the reference at 0 ULP
(tests/python/test_plausible.py checks it on a fixed subset); engine reference: bank scenarios
of one configuration run together on the reference's batch axis (bit for bit the same as one at
a time), robust scenarios one by one (slow: about 250 samples/s).  Prints the counts, the
largest ratio |force_hat| / max|force|, the DIVERGED flags and every violating seed; exit
status 1 on any violation.
"""
from __future__ import annotations

import argparse
import math
import os
import subprocess
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from ..bank import STATUS_DIVERGED, FilterBank
from ..fmath import real_for
from ..params import PRESETS, get_preset
from ..robust import RobustEstimator
from ..starts import start_values
from .c_engine import C_BIN, C_EXE
from .csvio import format_real, time_us
from .estimate import make_config
from ..sim.simulate import simulate_force
from ..sim.trajectory import TrajectorySpec, lspb_profile

MAX_SAMPLES = 6000
BOUND = 10.0   # |force_hat| <= BOUND * max|force input|
#: the property's slack: the estimator's own bound (bank.DATA_BOUND, the same factor) is
#: computed in its working precision, so the limit it publishes can sit half a float32 ulp
#: above BOUND x the force it saw
ROUNDING = 2.0 ** -23


@dataclass(frozen=True)
class Scenario:
    seed: int
    preset: str
    rate_hz: float
    irregular: bool
    speed_mm_s: float
    depth_mm: float
    dwell_s: float
    accel_mm_s2: float
    noise_n: float
    model: int
    precision: str
    estimator: str
    init_factor: float
    init_seed: int
    jump_mm: float       # 0: no depth jump
    saturation: float    # 0: no saturation, else the clip level as a fraction of the peak
    inverted: bool       # the force recorded with the opposite sign

    def spec(self) -> TrajectorySpec:
        return TrajectorySpec(depth_mm=self.depth_mm, speed_mm_s=self.speed_mm_s,
                              accel_mm_s2=self.accel_mm_s2, dwell_s=self.dwell_s,
                              rate_hz=self.rate_hz)

    def estimator_args(self) -> list[str]:
        """The same run by the command-line programs (nte-ref estimate, nte-run).  The
        scenarios draw forces of either sign and any range on purpose: the programs' units check
        (which would take some for a sensor of the opposite sign) is off, as in the reference's
        run of the samples."""
        return ["--model", str(self.model), "--estimator", self.estimator, "--preset",
                self.preset, "--init-seed", str(self.init_seed), "--init-factor",
                repr(self.init_factor), "--no-units-check"]


def draw(seed: int, max_samples: int = MAX_SAMPLES) -> Scenario:
    rng = np.random.default_rng(seed)

    def logu(lo: float, hi: float) -> float:
        return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))

    preset = list(PRESETS)[int(rng.integers(len(PRESETS)))]
    rate, speed = logu(20.0, 1000.0), logu(0.4, 50.0)
    depth, dwell = float(rng.uniform(5.0, 150.0)), float(rng.uniform(0.0, 60.0))
    accel = logu(100.0, 10000.0)
    irregular = bool(rng.uniform() < 0.25)
    noise = logu(0.5e-3, 50e-3)
    model = int(rng.integers(1, 3))
    precision = ("float32", "float64")[int(rng.integers(2))]
    estimator = "robust" if rng.uniform() < 0.1 else "bank"
    factor = float(rng.uniform(1.0, 5.0))
    init_seed = int(rng.integers(1, 1000))
    jump = float(rng.uniform(2.0, 20.0) * rng.choice([-1.0, 1.0])) if rng.uniform() < 0.25 else 0.0
    sat = float(rng.uniform(0.4, 0.9)) if rng.uniform() < 0.25 else 0.0
    inverted = bool(rng.uniform() < 0.25)
    # cap the length: the dwell first, then the rate (>= 20 Hz), then the depth
    move = depth / speed
    if (2.0 * move + dwell) * rate > max_samples:
        dwell = max(0.0, max_samples / rate - 2.0 * move)
    if (2.0 * move + dwell) * rate > max_samples:
        rate = max(20.0, max_samples / (2.0 * move + dwell))
    if (2.0 * move + dwell) * rate > max_samples:
        depth = max(5.0, 0.5 * speed * max_samples / rate)
    return Scenario(seed, preset, rate, irregular, speed, depth, dwell, accel, noise, model,
                    precision, estimator, factor, init_seed, jump, sat, inverted)


def samples(sc: Scenario) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t_s, depth_mm, velocity_mm_s, force_n) of a scenario, float64."""
    rng = np.random.default_rng([sc.seed, 1])
    t, l, v, _ = lspb_profile(sc.spec())
    if sc.irregular:
        t = t + rng.uniform(-0.4, 0.4, len(t)) / sc.rate_hz
        t[0] = 0.0
    truth = simulate_force(get_preset(sc.preset).params, t, l, v)[0][0]
    f = truth + rng.normal(0.0, sc.noise_n, len(t))
    if sc.saturation > 0.0:
        top = sc.saturation * float(np.max(np.abs(truth)))
        f = np.clip(f, -top, top)
    if sc.jump_mm != 0.0:
        n = len(t)
        k0 = int(rng.integers(0, max(1, n - 1)))
        k1 = min(n, k0 + max(1, int(rng.uniform(0.2, 2.0) * sc.rate_hz)))
        l = l.copy()
        l[k0:k1] = np.maximum(0.0, l[k0:k1] + sc.jump_mm)
    if sc.inverted:
        f = -f
    return t, l, v, f


def csv_lines(sc: Scenario) -> list[str]:
    """The scenario as an input file for nte-ref estimate and nte-run."""
    t, l, v, f = samples(sc)
    return ["t_s,depth_mm,velocity_mm_s,force_n"] + [
        ",".join(format_real(x, "float64") for x in row) for row in zip(t, l, v, f)]


@dataclass
class Outcome:
    seed: int
    n: int
    finite: bool
    ratio: float        # max |force_hat| / max |force input|
    diverged: int       # samples flagged DIVERGED

    @property
    def ok(self) -> bool:
        return self.finite and self.ratio <= BOUND * (1.0 + ROUNDING)


def run_batch(scs: list[Scenario]) -> list[Outcome]:
    """Scenarios of one configuration (model, precision, estimator; Model I: preset, whose
    beta is its beta0) on the batch axis."""
    sc0 = scs[0]
    R = real_for(sc0.precision)
    cfg = make_config(get_preset(sc0.preset), sc0.model, "default", "all")
    nominal = [start_values(get_preset(s.preset).params.as_list(), s.init_seed, s.init_factor,
                            s.model) for s in scs]
    data = [samples(s) for s in scs]
    est = (RobustEstimator(R, cfg, nominal) if sc0.estimator == "robust"
           else FilterBank(R, cfg, nominal))
    n = [len(d[0]) for d in data]
    n_max = max(n)

    def pad(a: np.ndarray) -> np.ndarray:
        # shorter runs repeat their last sample: rejected (time does not increase)
        return np.concatenate([a, np.repeat(a[-1:], n_max - len(a))])

    t = np.stack([pad(time_us(d[0])) for d in data])
    l, v, f = (np.stack([pad(R.arr(d[i])) for d in data]) for i in (1, 2, 3))
    B = len(scs)
    finite = np.ones(B, dtype=bool)
    peak = np.zeros(B)
    div = np.zeros(B, dtype=np.int64)
    live_n = np.asarray(n)
    for k in range(n_max):
        o = est.step(t[:, k], l[:, k], v[:, k], f[:, k])
        live = k < live_n
        finite &= ~live | (np.isfinite(o.force_hat) & np.isfinite(o.z)
                           & np.isfinite(o.innovation))
        peak = np.where(live, np.maximum(peak, np.abs(o.force_hat.astype(np.float64))), peak)
        div += live & ((o.status & np.uint32(STATUS_DIVERGED)) != 0)
    fin = np.array([float(np.max(np.abs(R.arr(d[3])))) for d in data])
    return [Outcome(s.seed, n[b], bool(finite[b]), float(peak[b] / fin[b]), int(div[b]))
            for b, s in enumerate(scs)]


def outcome(sc: Scenario, force_in: np.ndarray, force_hat: np.ndarray, z: np.ndarray,
            innovation: np.ndarray, status: np.ndarray) -> Outcome:
    """The property's figures of one run (its outputs as float64 arrays)."""
    finite = bool(np.all(np.isfinite(force_hat)) and np.all(np.isfinite(z))
                  and np.all(np.isfinite(innovation)))
    peak = float(np.max(np.abs(force_hat))) if finite else math.inf
    return Outcome(sc.seed, len(force_hat), finite, peak / float(np.max(np.abs(force_in))),
                   int(np.count_nonzero(status.astype(np.uint32) & np.uint32(STATUS_DIVERGED))))


def run_c(sc: Scenario, c_bin: Path = C_BIN) -> Outcome:
    """One scenario through the C library's host program (nte-run or nte-run-double)."""
    exe = c_bin / C_EXE[sc.precision]
    with tempfile.TemporaryDirectory(prefix="nte-plausible-") as tmp:
        src, dst = Path(tmp) / "in.csv", Path(tmp) / "est.csv"
        src.write_text("\n".join(csv_lines(sc)) + "\n")
        r = subprocess.run([str(exe), str(src), *sc.estimator_args(), "--out", str(dst)],
                           capture_output=True, text=True)
        if r.returncode != 0:
            raise RuntimeError(f"{exe.name} failed on scenario {sc.seed}: "
                               f"{(r.stderr.strip().splitlines() or ['?'])[-1]}")
        rows = np.genfromtxt(dst, delimiter=",", skip_header=1, usecols=(1, 2, 3, 4),
                             ndmin=2, dtype=np.float64)
    f_in = np.abs(_force_seen(sc.precision, samples(sc)[3]))
    return outcome(sc, f_in, rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3])


def _force_seen(precision: str, force: np.ndarray) -> np.ndarray:
    """The input force as the estimator sees it (rounded to its precision), float64."""
    return real_for(precision).arr(force).astype(np.float64)


def _key(sc: Scenario) -> tuple[int, str, str, str, bool]:
    # one configuration and one sign of f2 (the f1 parametrisation) per batch
    preset = sc.preset if sc.model == 1 else ""
    return (sc.model, sc.precision, sc.estimator, preset, get_preset(sc.preset).params.f2 < 0.0)


def batches(seeds: range, batch: int) -> list[list[Scenario]]:
    groups: dict[tuple[int, str, str, str, bool], list[Scenario]] = {}
    for s in seeds:
        sc = draw(s)
        groups.setdefault(_key(sc), []).append(sc)
    out: list[list[Scenario]] = []
    for key, scs in sorted(groups.items()):
        size = 1 if key[2] == "robust" else batch
        # similar lengths together: less padding
        scs = sorted(scs, key=lambda s: len(lspb_profile(s.spec())[0]))
        out += [scs[i:i + size] for i in range(0, len(scs), size)]
    return out


def _run_c_list(scs: list[Scenario], c_bin: Path) -> list[Outcome]:
    return [run_c(sc, c_bin) for sc in scs]


def run(seeds: range, batch: int = 200, jobs: int = 1, engine: str = "c",
        c_bin: Path = C_BIN) -> list[Outcome]:
    if engine == "c":
        scs = [draw(s) for s in seeds]
        work = [scs[i:i + 25] for i in range(0, len(scs), 25)]
        task = partial(_run_c_list, c_bin=c_bin)
    else:
        work = batches(seeds, batch)
        # longest first, so the pool's last tasks are short
        work.sort(key=lambda b: -sum(len(lspb_profile(s.spec())[0]) for s in b))
        task = run_batch
    if jobs == 1:
        res = [task(b) for b in work]
    else:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            res = list(pool.map(task, work))
    return sorted((o for r in res for o in r), key=lambda o: o.seed)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scenarios", type=int, default=1000, metavar="N",
                   help="number of scenarios, seeds K..K+N-1 (default 1000; 1..1000000)")
    p.add_argument("--first-seed", type=int, default=0, metavar="K",
                   help="first scenario seed (default 0)")
    p.add_argument("--jobs", type=int, default=1, metavar="J",
                   help="worker processes (default 1; 1..64)")
    p.add_argument("--engine", choices=("c", "reference"), default="c",
                   help="c: the C library's host programs (default; 0 ULP from the "
                        "reference); reference: the numpy reference (slow)")
    p.add_argument("--c-bin", type=Path, default=C_BIN, metavar="DIR",
                   help="where nte-run and nte-run-double are (default build/host/bin)")
    p.add_argument("--batch", type=int, default=200, metavar="B",
                   help="engine reference: bank scenarios run together on the batch axis "
                        "(default 200; 1..10000)")
    p.add_argument("--show", type=int, default=0, metavar="S",
                   help="also print the S scenarios with the largest ratio (default 0)")


def main_run(a: argparse.Namespace) -> int:
    if not 1 <= a.scenarios <= 1_000_000:
        raise ValueError(f"--scenarios must be in 1..1000000 (got {a.scenarios})")
    if not 0 <= a.first_seed <= 2**62:
        raise ValueError(f"--first-seed must be in 0..2^62 (got {a.first_seed})")
    if not 1 <= a.jobs <= 64:
        raise ValueError(f"--jobs must be in 1..64 (got {a.jobs})")
    if not 1 <= a.batch <= 10_000:
        raise ValueError(f"--batch must be in 1..10000 (got {a.batch})")
    if not 0 <= a.show <= 1000:
        raise ValueError(f"--show must be in 0..1000 (got {a.show})")
    if a.engine == "c":
        for exe in C_EXE.values():
            if not os.access(a.c_bin / exe, os.X_OK):
                raise ValueError(f"--c-bin: {a.c_bin / exe} is not an executable "
                                 f"(make build, or --engine reference)")
    t0 = time.perf_counter()
    res = run(range(a.first_seed, a.first_seed + a.scenarios), a.batch, a.jobs, a.engine,
              a.c_bin)
    bad = [r for r in res if not r.ok]
    worst = max(res, key=lambda r: r.ratio)
    print(f"scenarios {len(res)} (seeds {a.first_seed}..{a.first_seed + a.scenarios - 1}), "
          f"samples {sum(r.n for r in res)}, engine {a.engine}, "
          f"{time.perf_counter() - t0:.0f} s with {a.jobs} job(s)")
    print(f"violations {len(bad)} (non-finite {sum(not r.finite for r in res)}, "
          f"|force_hat| > {BOUND:g} x max|force| {sum(r.finite and not r.ok for r in res)})")
    print(f"largest |force_hat| / max|force| {worst.ratio:.3f} (seed {worst.seed}); "
          f"scenarios with DIVERGED flags {sum(r.diverged > 0 for r in res)}")
    for r in sorted(res, key=lambda r: -r.ratio)[:a.show]:
        print(f"  seed {r.seed}: ratio {r.ratio:.3f}, diverged {r.diverged}, {draw(r.seed)}")
    for r in bad:
        print(f"  VIOLATION seed {r.seed}: finite {r.finite}, ratio {r.ratio:.3g}")
    return 1 if bad else 0
