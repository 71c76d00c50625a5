"""Shared by the C-twin tests: the paper scenarios, a batched reference runner, ULP distances.

The scenarios (inputs committed under tests/data/c_scenarios/, made by ``nte-ref simulate``):

    p10_d50  preset paper-10mms, 10 mm/s to 50 mm, 1 s dwell, back out (noise seed 1)
    p10_d80  preset paper-10mms, 10 mm/s to 80 mm
    p6_d50   preset paper-6mms,   6 mm/s to 50 mm

each estimated with Model I and II, schedules all and rotate, starting at the preset (seed 0)
and from a factor-5 start (seed 3): 24 runs per precision.  The reference runs every run of
one (model, schedule, precision, Model-I beta0) group at once on its batch axis — bit for bit
the same as one run at a time, and fast enough for the test suite.

    python tests/python/c_twin.py inputs    # regenerate the scenario inputs
    python tests/python/c_twin.py replay    # regenerate the replay files from build/host/bin/nte-run
    python tests/python/c_twin.py reversal  # regenerate tests/data/c_faults/reversal.csv
"""
from __future__ import annotations

import hashlib
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from reference_py.bank import FilterBank  # noqa: E402
from reference_py.tools.csvio import read_trial, time_us  # noqa: E402
from reference_py.tools.estimate import EstimateRun, estimate_csv_lines, make_config  # noqa: E402
from reference_py.fmath import real_for  # noqa: E402
from reference_py.params import MODEL_PARAMS, get_preset  # noqa: E402
from reference_py.starts import start_values  # noqa: E402

DATA = ROOT / "tests" / "data" / "c_scenarios"
REPLAY = ROOT / "tests" / "data" / "c_replay"
BIN = ROOT / "build" / "host" / "bin"
EXE = {"float32": BIN / "nte-run", "float64": BIN / "nte-run-double"}

SCENARIOS = {  # name: (preset, depth mm)
    "p10_d50": ("paper-10mms", 50.0),
    "p10_d80": ("paper-10mms", 80.0),
    "p6_d50": ("paper-6mms", 50.0),
}
SEEDS = (0, 3)
FACTOR = 5.0
MODELS = (1, 2)
SCHEDULES = ("all", "rotate")
#: the float build's outputs kept as plain CSV (the others by SHA-256 only)
REPLAY_CSV = ("p10_d50_m2_all_s0", "p10_d50_m1_rotate_s3")


@dataclass(frozen=True)
class Run:
    scenario: str
    model: int
    schedule: str
    seed: int

    @property
    def name(self) -> str:
        return f"{self.scenario}_m{self.model}_{self.schedule}_s{self.seed}"

    @property
    def preset(self) -> str:
        return SCENARIOS[self.scenario][0]

    def args(self) -> list[str]:
        return [str(DATA / f"{self.scenario}.csv"), "--model", str(self.model), "--preset",
                self.preset, "--schedule", self.schedule, "--init-seed", str(self.seed),
                "--init-factor", str(FACTOR)]


ALL_RUNS = [Run(s, m, sch, seed) for s in SCENARIOS for m in MODELS for sch in SCHEDULES
            for seed in SEEDS]


def groups(precision: str) -> list[tuple[str, list[Run]]]:
    """Runs that can share one batched FilterBank (same config; Model I: same beta0)."""
    out: dict[tuple, list[Run]] = {}
    for r in ALL_RUNS:
        key = (precision, r.model, r.schedule, r.preset if r.model == 1 else "")
        out.setdefault(key, []).append(r)
    return [(precision, runs) for runs in out.values()]


def reference_batch(precision: str, runs: list[Run]) -> dict[str, list[str]]:
    """Estimate files (as lines) of the reference for runs sharing one configuration."""
    R = real_for(precision)
    model, schedule = runs[0].model, runs[0].schedule
    cfg = make_config(get_preset(runs[0].preset), model, "default", schedule)
    trials = [read_trial(DATA / f"{r.scenario}.csv") for r in runs]
    nominal = [start_values(get_preset(r.preset).params.as_list(), r.seed, FACTOR, model)
               for r in runs]
    bank = FilterBank(R, cfg, nominal)
    lengths = [len(t.t_s) for t in trials]
    n_max = max(lengths)

    def padded(a: np.ndarray, n: int) -> np.ndarray:
        return np.concatenate([a, np.repeat(a[-1:], n - len(a))])

    # shorter runs are padded with repeats of their last sample: rejected (time does not
    # increase), so they change nothing; their outputs are dropped
    t = np.stack([padded(time_us(tr.t_s), n_max) for tr in trials])
    l = np.stack([padded(R.arr(tr.depth_mm), n_max) for tr in trials]).astype(R.dtype)
    v = np.stack([padded(R.arr(tr.velocity_mm_s), n_max) for tr in trials]).astype(R.dtype)
    f = np.stack([padded(R.arr(tr.force_n), n_max) for tr in trials]).astype(R.dtype)
    B = len(runs)
    names = MODEL_PARAMS[model]
    fh = np.zeros((B, n_max), dtype=R.dtype)
    z = np.zeros_like(fh)
    inn = np.zeros_like(fh)
    st = np.zeros((B, n_max), dtype=np.uint32)
    pars = np.zeros((B, n_max, len(names)), dtype=R.dtype)
    sds = np.zeros_like(pars)
    for k in range(n_max):
        o = bank.step(t[:, k], l[:, k], v[:, k], f[:, k])
        fh[:, k], z[:, k], inn[:, k], st[:, k] = o.force_hat, o.z, o.innovation, o.status
        pars[:, k, :], sds[:, k, :] = o.params.T, o.params_sd.T
    out = {}
    for b, (r, tr, n) in enumerate(zip(runs, trials, lengths)):
        run = EstimateRun(precision, model, tr.t_s, tr.depth_mm, tr.force_n, fh[b, :n],
                          z[b, :n], inn[b, :n], st[b, :n], pars[b, :n], sds[b, :n], names)
        out[r.name] = estimate_csv_lines(run)
    return out


def run_c(precision: str, run: Run, out: Path) -> list[str]:
    subprocess.run([str(EXE[precision])] + run.args() + ["--out", str(out)], check=True,
                   capture_output=True)
    return out.read_text().split("\n")[:-1]


def cli_pair(precision: str, csv: Path, extra: list[str], tmp: Path) -> tuple[bytes, bytes]:
    """The estimate file of each twin's command line on `csv` with the flags `extra`:
    (nte-run's, nte-ref estimate's), written into `tmp`."""
    c_out, py_out = tmp / f"c_{precision}.csv", tmp / f"py_{precision}.csv"
    subprocess.run([str(EXE[precision]), str(csv), "--out", str(c_out)] + extra, check=True,
                   capture_output=True)
    subprocess.run([sys.executable, "-m", "reference_py", "estimate", str(csv), "--precision",
                    precision, "--out", str(py_out)] + extra, check=True, capture_output=True,
                   cwd=ROOT)
    return c_out.read_bytes(), py_out.read_bytes()


def _ordered(bits: np.ndarray, width: int) -> np.ndarray:
    """Map IEEE bit patterns to integers whose difference is the ULP distance."""
    b = bits.astype(np.int64) if width == 32 else bits.astype(object)
    sign = 1 << (width - 1)
    return np.where(b >= sign, sign - b, b) if width == 32 else \
        np.array([(sign - x) if x >= sign else x for x in b], dtype=object)


def ulp_distance(text_a: list[str], text_b: list[str], precision: str) -> int:
    """Largest ULP distance between two estimate files' real cells (status excluded)."""
    if len(text_a) != len(text_b):
        return sys.maxsize
    dt, ut, width = ((np.float32, np.uint32, 32) if precision == "float32"
                     else (np.float64, np.uint64, 64))
    worst = 0
    for la, lb in zip(text_a[1:], text_b[1:]):
        if la == lb:
            continue
        ca, cb = la.split(","), lb.split(",")
        if len(ca) != len(cb) or ca[4] != cb[4] or ca[0] != cb[0]:
            return sys.maxsize
        idx = [1, 2, 3] + list(range(5, len(ca)))
        a = np.array([float(ca[i]) for i in idx], dtype=dt).view(ut)
        b = np.array([float(cb[i]) for i in idx], dtype=dt).view(ut)
        oa, ob = _ordered(a, width), _ordered(b, width)
        worst = max(worst, max(abs(int(x) - int(y)) for x, y in zip(oa, ob)))
    return worst


def reference_key() -> str:
    """Hash of everything the reference results depend on (sources, inputs, this file)."""
    h = hashlib.sha256()
    files = sorted((ROOT / "reference_py").glob("*.py")) + sorted(DATA.glob("*.csv"))
    for p in files + [Path(__file__)]:
        h.update(p.name.encode())
        h.update(p.read_bytes())
    return h.hexdigest()[:20]


def sha256_lines(lines: list[str]) -> str:
    return hashlib.sha256(("\n".join(lines) + "\n").encode()).hexdigest()


def make_inputs() -> None:
    DATA.mkdir(parents=True, exist_ok=True)
    for name, (preset, depth) in SCENARIOS.items():
        subprocess.run([sys.executable, "-m", "reference_py", "simulate", "--preset", preset,
                        "--depth", str(depth), "--dwell", "1", "--seed", "1",
                        "--out", str(DATA / f"{name}.csv")], check=True, cwd=ROOT)


def make_reversal() -> None:
    """tests/data/c_faults/reversal.csv: 10 mm/s in to 30 mm, then at once -10 mm/s back out
    (no blend: the velocity jumps by 20 mm/s between two samples), preset paper-10mms truth,
    exact sign, 2 mN noise (seed 1).  For the C fault-injection test."""
    from reference_py.tools.csvio import write_atomic
    from reference_py.sim.simulate import simulate_force
    rate, speed, depth = 200.0, 10.0, 30.0
    n_in = int(round(depth / speed * rate))
    t = np.arange(2 * n_in + 41) / rate
    k = np.arange(len(t))
    l = np.where(k <= n_in, k * (speed / rate), np.maximum(0.0, (2 * n_in - k) * (speed / rate)))
    v = np.where(k < n_in, speed, np.where(l > 0.0, -speed, 0.0))
    truth = simulate_force(get_preset("paper-10mms").params, t, l, v)[0][0]
    noisy = truth + np.random.default_rng(1).normal(0.0, 2e-3, len(t))
    lines = ["# abrupt reversal at full speed at t = %.3f s" % (n_in / rate),
             "t_s,depth_mm,velocity_mm_s,force_n,force_true_n"]
    lines += ["%.17g,%.17g,%.17g,%.17g,%.17g" % row for row in zip(t, l, v, noisy, truth)]
    write_atomic(ROOT / "tests" / "data" / "c_faults" / "reversal.csv", lines)


def make_replay() -> None:
    import tempfile
    REPLAY.mkdir(parents=True, exist_ok=True)
    manifest = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in ALL_RUNS:
            lines = run_c("float32", r, Path(tmp) / "est.csv")
            manifest.append(f"{sha256_lines(lines)}  {r.name}")
            if r.name in REPLAY_CSV:
                (REPLAY / f"{r.name}.csv").write_text("\n".join(lines) + "\n")
    (REPLAY / "SHA256SUMS").write_text("\n".join(manifest) + "\n")


if __name__ == "__main__":
    {"inputs": make_inputs, "replay": make_replay, "reversal": make_reversal}[sys.argv[1]]()
