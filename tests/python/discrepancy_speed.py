"""CPU time of the discrepancy workflow on one six-trial condition (README "Speed").

    .venv/bin/python tests/python/discrepancy_speed.py [--seeds A B ...]

One BLAS thread, as `make test` runs (set before numpy loads), so the figure is the work done,
not how many cores the machine lends.  Two conditions: six skin-on-muscle phantom records
(3 247 samples each, seeds 1-6; the case test_discrepancy_solver budgets) and, for each
measured-like seed given (default 368, which no tuning used), six trials of that condition
(about 2 900 samples each; the issue's target is for 2 500).  Prints samples, effects named, CPU
seconds (this process and its workers) and wall seconds.  With ``--jobs 1`` (the default) the
CPU figure is the work done, which a busy machine changes little; ``--jobs N`` runs the
condition's independent fits on N workers (pool.py), as nte-discrepancy does by default, and
the wall figure is then the one to read.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import resource  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

from discrepancy_measured_like import make_case, phantom_trial  # noqa: E402

from reference_py.discrepancy.workflow import run  # noqa: E402


def _cpu() -> float:
    """CPU seconds of this process and of its workers that have ended."""
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + kids.ru_utime + kids.ru_stime


def _timed(label: str, trials: list, jobs: int) -> None:
    t0, w0 = _cpu(), time.perf_counter()
    res = run(trials, jobs=jobs)
    cpu, wall = _cpu() - t0, time.perf_counter() - w0
    n = sum(len(tr.t_s) for tr in trials) // len(trials)
    print(f"{label:<34} {len(trials)} x {n:5d} samples  {cpu:5.1f} s CPU  {wall:5.1f} s wall  "
          f"named: {', '.join(res.named) or 'none'}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[368],
                    help="measured-like condition seeds (default 368)")
    ap.add_argument("--jobs", type=int, default=1,
                    help="worker processes for the condition's fits (default 1)")
    args = ap.parse_args(argv)
    if any(s < 0 for s in args.seeds):
        ap.error("--seeds: a seed is a non-negative integer")
    if args.jobs < 1:
        ap.error("--jobs: at least 1")
    _timed("phantom skin-on-muscle 1-6", [phantom_trial("skin-on-muscle", s)[0]
                                         for s in range(1, 7)], args.jobs)
    for seed in args.seeds:
        _timed(f"measured-like {seed}", make_case(seed, trials=6).trials, args.jobs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
