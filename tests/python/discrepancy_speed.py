"""CPU time of the discrepancy workflow on one six-trial condition (README "Speed").

    .venv/bin/python tests/python/discrepancy_speed.py [--seeds A B ...]

One BLAS thread, as `make test` runs (set before numpy loads), so the figure is the work done,
not how many cores the machine lends.  Two conditions: six skin-on-muscle phantom records
(3 247 samples each, seeds 1-6; the case test_discrepancy_solver budgets) and, for each
measured-like seed given (default 368, which no tuning used), six trials of that condition
(about 2 900 samples each; the issue's target is for 2 500).  Prints samples, effects named and CPU seconds;
CPU time, not wall time, so a busy machine changes the figure little.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

from discrepancy_measured_like import make_case, phantom_trial  # noqa: E402

from reference_py.discrepancy.workflow import run  # noqa: E402


def _timed(label: str, trials: list) -> None:
    t0 = time.process_time()
    res = run(trials)
    cpu = time.process_time() - t0
    n = sum(len(tr.t_s) for tr in trials) // len(trials)
    print(f"{label:<34} {len(trials)} x {n:5d} samples  {cpu:5.1f} s CPU  "
          f"named: {', '.join(res.named) or 'none'}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[368],
                    help="measured-like condition seeds (default 368)")
    args = ap.parse_args(argv)
    if any(s < 0 for s in args.seeds):
        ap.error("--seeds: a seed is a non-negative integer")
    _timed("phantom skin-on-muscle 1-6", [phantom_trial("skin-on-muscle", s)[0]
                                         for s in range(1, 7)])
    for seed in args.seeds:
        _timed(f"measured-like {seed}", make_case(seed, trials=6).trials)
    return 0


if __name__ == "__main__":
    sys.exit(main())
