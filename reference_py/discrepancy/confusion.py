"""Closing-note figures of the discrepancy workflow on the blind test cases.

Prints the confusion matrix over the whole vocabulary (hidden effect -> first named effect), the
median gap shrink per effect (RMSE against the noise-free truth, in the phases the effect acts on
and overall), and the run time per trial.  The cases come from the tests' blind generator
(tests/python/discrepancy_generator.py), which the workflow itself never uses.

usage: python -m reference_py.discrepancy.confusion [--per-kind N] [--workers W]
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from .effects import NONE, VOCABULARY  # noqa: E402

SHORT = {"dwell_relaxation": "relax", "reversal_presliding": "presl", "velocity_friction": "visc",
         "direction_asymmetry": "asym", "layer_puncture": "layer", "sensor_drift": "drift",
         "tissue_motion": "motion", NONE: "none"}


def summarise(results: list[dict]) -> str:
    labels = list(VOCABULARY) + [NONE]
    lines = ["Confusion matrix (rows: hidden effect, columns: first named effect, counts)", ""]
    lines.append("hidden \\ named".ljust(22) + "".join(SHORT[c].rjust(7) for c in labels))
    singles = [r for r in results if len(r["kind"]) <= 1]
    for h in labels:
        rows = [r for r in singles if (r["kind"][0] if r["kind"] else NONE) == h]
        cnt = [sum(1 for r in rows if r["named"][0] == c) for c in labels]
        lines.append(h.ljust(22) + "".join(str(c).rjust(7) for c in cnt))
    pairs = [r for r in results if len(r["kind"]) == 2]
    if pairs:
        both = sum(1 for r in pairs if set(r["kind"]) <= set(r["named"]))
        lines += ["", f"two hidden effects {'+'.join(pairs[0]['kind'])}: both named in "
                  f"{both}/{len(pairs)}"]
    lines += ["", "Median gap shrink (1 - RMSE after / RMSE before, vs noise-free truth), "
              "cases where the hidden effect is named first", "",
              "effect".ljust(22) + "phases".rjust(10) + "overall".rjust(10) + "cases".rjust(8)]
    for h in VOCABULARY:
        rows = [r for r in singles if r["kind"] == (h,) and r["named"][0] == h]
        if rows:
            sp = np.median([1 - r["support_after"] / r["support_before"] for r in rows])
            ov = np.median([1 - r["overall_after"] / r["overall_before"] for r in rows])
            lines.append(h.ljust(22) + f"{sp:10.2f}{ov:10.2f}{len(rows):8d}")
        else:
            lines.append(h.ljust(22) + "-".rjust(10) + "-".rjust(10) + "0".rjust(8))
    rt = np.array([r["runtime_per_trial_s"] for r in results])
    lines += ["", f"Run time per trial: median {np.median(rt):.2f} s, 90th pct "
              f"{np.percentile(rt, 90):.2f} s, max {rt.max():.2f} s over {len(results)} cases"]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--per-kind", type=int, default=20)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    tests = Path(__file__).resolve().parents[2] / "tests" / "python"
    sys.path.insert(0, str(tests))
    from discrepancy_generator import run_all  # type: ignore[import-not-found]
    print(summarise(run_all(args.workers, args.per_kind)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
