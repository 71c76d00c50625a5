"""The C robust estimator equals reference_py/robust.py bit for bit.

Requires build/host/bin/nte-run and nte-run-double (``make build``; skipped with a reason when
they are missing).  Inputs (committed under tests/data/c_robust/, made by ``nte-ref simulate
--cycles 2``; regenerate with ``python tests/python/test_c_robust.py inputs``):

    p10_c2  preset paper-10mms, 10 mm/s to 50 mm, 1 s dwell, back out, two cycles (noise seed 1)
    p6_c2   preset paper-6mms,   6 mm/s to 30 mm, 1 s dwell, back out, two cycles

each with 8.6 s at the surface before and after every cycle (``--rest 8.6``: the default
refinement, one buffer entry a sample, is adopted 1 710 samples after the insertion).

Runs (schedule all, default profile, RobustConfig defaults): Model II on p10_c2 from the preset
(seed 0) and from a factor-5 start (seed 3), Model II on p6_c2 (seed 0), Model I on p10_c2 from
a factor-5 start (seed 3).  Each insertion ends with a refinement, so every run covers the
buffer, its decimation, both LM starts, the bank restart and (second cycle) the convergence
test.  The reference runs each model's runs at once on its batch axis (RobustEstimator is
element-wise: bit for bit the same as one run at a time) and is cached under
build/host/c_twin_cache, keyed by a hash of the reference sources, the inputs and this file.
Every output column — status, every real and the confidence — must be the same bits (the
estimate files are compared as text, every real printed with round-trip digits); the largest
ULP distance is printed.
"""
from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from c_twin import EXE, FACTOR, ROOT, ulp_distance

DATA = ROOT / "tests" / "data" / "c_robust"
SCENARIOS = {  # name: (preset, depth mm)
    "p10_c2": ("paper-10mms", 50.0),
    "p6_c2": ("paper-6mms", 30.0),
}
PRECISIONS = ("float32", "float64")
#: rest at the surface before and after each cycle, s: the default refinement is adopted 1 710
#: samples (8.55 s at 200 Hz) after the insertion, so each cycle's is adopted before the next
REST_S = 8.6


@dataclass(frozen=True)
class RobustRun:
    scenario: str
    model: int
    seed: int

    @property
    def name(self) -> str:
        return f"{self.scenario}_m{self.model}_s{self.seed}"

    @property
    def preset(self) -> str:
        return SCENARIOS[self.scenario][0]

    def args(self) -> list[str]:
        return [str(DATA / f"{self.scenario}.csv"), "--model", str(self.model), "--preset",
                self.preset, "--init-seed", str(self.seed), "--init-factor", str(FACTOR),
                "--estimator", "robust"]


RUNS = [RobustRun("p10_c2", 2, 0), RobustRun("p10_c2", 2, 3), RobustRun("p6_c2", 2, 0),
        RobustRun("p10_c2", 1, 3)]


def reference_robust(precision: str, runs: list[RobustRun]) -> dict[str, list[str]]:
    """Estimate files (as lines) of the reference robust estimator for runs sharing a config."""
    from reference_py.tools.csvio import read_trial, time_us
    from reference_py.tools.estimate import EstimateRun, estimate_csv_lines, make_config
    from reference_py.fmath import real_for
    from reference_py.params import MODEL_PARAMS, get_preset
    from reference_py.robust import RobustEstimator
    from reference_py.starts import start_values

    R = real_for(precision)
    model = runs[0].model
    cfg = make_config(get_preset(runs[0].preset), model, "default", "all")
    trials = [read_trial(DATA / f"{r.scenario}.csv") for r in runs]
    nominal = [start_values(get_preset(r.preset).params.as_list(), r.seed, FACTOR, model)
               for r in runs]
    est = RobustEstimator(R, cfg, nominal)
    lengths = [len(t.t_s) for t in trials]
    n_max = max(lengths)

    def padded(a: np.ndarray, n: int) -> np.ndarray:
        return np.concatenate([a, np.repeat(a[-1:], n - len(a))])

    # shorter runs are padded with repeats of their last sample: rejected (time does not
    # increase), so neither the bank nor the buffer changes; their outputs are dropped
    t = np.stack([padded(time_us(tr.t_s), n_max) for tr in trials])
    l = np.stack([padded(R.arr(tr.depth_mm), n_max) for tr in trials]).astype(R.dtype)
    v = np.stack([padded(R.arr(tr.velocity_mm_s), n_max) for tr in trials]).astype(R.dtype)
    f = np.stack([padded(R.arr(tr.force_n), n_max) for tr in trials]).astype(R.dtype)
    B = len(runs)
    names = MODEL_PARAMS[model]
    fh = np.zeros((B, n_max), dtype=R.dtype)
    z, inn, conf = np.zeros_like(fh), np.zeros_like(fh), np.zeros_like(fh)
    st = np.zeros((B, n_max), dtype=np.uint32)
    pars = np.zeros((B, n_max, len(names)), dtype=R.dtype)
    sds = np.zeros_like(pars)
    for k in range(n_max):
        o = est.step(t[:, k], l[:, k], v[:, k], f[:, k])
        fh[:, k], z[:, k], inn[:, k], st[:, k] = o.force_hat, o.z, o.innovation, o.status
        pars[:, k, :], sds[:, k, :] = o.params.T, o.params_sd.T
        conf[:, k] = est.confidence
    out = {}
    for b, (r, tr, n) in enumerate(zip(runs, trials, lengths)):
        run = EstimateRun(precision, model, tr.t_s, tr.depth_mm, tr.force_n, fh[b, :n],
                          z[b, :n], inn[b, :n], st[b, :n], pars[b, :n], sds[b, :n], names,
                          conf[b, :n])
        out[r.name] = estimate_csv_lines(run)
    return out


def robust_key() -> str:
    h = hashlib.sha256()
    files = sorted((ROOT / "reference_py").glob("*.py")) + sorted(DATA.glob("*.csv"))
    for p in files + [Path(__file__)]:
        h.update(p.name.encode())
        h.update(p.read_bytes())
    return "robust-" + h.hexdigest()[:20]


def jobs() -> list[tuple[str, list[RobustRun]]]:
    by_model: dict[int, list[RobustRun]] = {}
    for r in RUNS:  # Model I's beta0 is the preset's: its runs share one preset here
        by_model.setdefault(r.model, []).append(r)
    return [(p, runs) for p in PRECISIONS for runs in by_model.values()]


pytestmark = pytest.mark.skipif(
    not all(p.exists() for p in EXE.values()),
    reason="build/host/bin/nte-run{,-double} missing: build the firmware first (make build)")


@pytest.fixture(scope="module")
def reference() -> dict[tuple[str, str], list[str]]:
    """Every run's reference estimate file (about two minutes on two cores; cached)."""
    cache = ROOT / "build" / "host" / "c_twin_cache" / f"{robust_key()}.json"
    if cache.exists():
        raw = json.loads(cache.read_text())
        return {tuple(k.split("|", 1)): v for k, v in raw.items()}  # type: ignore[misc]
    todo = jobs()
    out: dict[tuple[str, str], list[str]] = {}
    with ProcessPoolExecutor(max_workers=min(len(todo), os.cpu_count() or 1)) as pool:
        for (precision, _), res in zip(todo, pool.map(reference_robust, *zip(*todo))):
            for name, lines in res.items():
                out[(precision, name)] = lines
    cache.parent.mkdir(parents=True, exist_ok=True)
    cache.write_text(json.dumps({f"{p}|{n}": v for (p, n), v in out.items()}))
    return out


def run_c(precision: str, run: RobustRun, out: Path) -> list[str]:
    subprocess.run([str(EXE[precision])] + run.args() + ["--out", str(out)], check=True,
                   capture_output=True)
    return out.read_text().split("\n")[:-1]


@pytest.mark.parametrize("precision", PRECISIONS)
def test_robust_bit_identical(reference, precision, tmp_path):
    worst = 0
    failures = []
    refinements = 0
    for r in RUNS:
        c_lines = run_c(precision, r, tmp_path / f"{r.name}.csv")
        ref = reference[(precision, r.name)]
        assert c_lines[0] == ref[0] and ref[0].endswith(",confidence")
        ulp = 0 if c_lines == ref else ulp_distance(c_lines, ref, precision)
        worst = max(worst, ulp)
        if ulp != 0 or c_lines != ref:
            first = next((k for k, (a, b) in enumerate(zip(c_lines, ref)) if a != b), None)
            failures.append(f"{r.name}: max ULP {ulp}, first differing line {first}")
        status = [int(line.split(",")[4]) for line in ref[1:]]
        refinements += sum(1 for s in status if s & (1 << 9))
    print(f"\n{precision}: {len(RUNS)} robust runs, {refinements} refinements, "
          f"max ULP distance C vs reference = {worst}")
    assert refinements >= 2 * len(RUNS), "every insertion cycle should end with a refinement"
    assert not failures, "\n".join(failures)


def make_inputs() -> None:
    DATA.mkdir(parents=True, exist_ok=True)
    for name, (preset, depth) in SCENARIOS.items():
        subprocess.run([sys.executable, "-m", "reference_py", "simulate", "--preset", preset,
                        "--depth", str(depth), "--dwell", "1", "--seed", "1", "--cycles", "2",
                        "--rest", str(REST_S), "--out", str(DATA / f"{name}.csv")],
                       check=True, cwd=ROOT)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    {"inputs": make_inputs}[sys.argv[1]]()
