"""Figures of the relaxation's memory after a dwell (README "The relaxation's memory"): the
discrepancy workflow's final model with and without it (workflow._polish), one trial at a time.

    PYTHONPATH=.:tests/python .venv/bin/python tests/python/relax_memory_figures.py [--jobs 2]

Records none of them used to design the memory (``--set first``, default: `lab` phantom seeds
2132-2141, measured-like seeds 470-479 and the five phantom presets with seed 202, on which how
the memory is fitted was chosen; ``--set second``: 2142-2151, 480-489, seed 203, looked at once,
after).  Per record, in units of the record's
noise: the RMSE of the final model to the noise-free force, overall and over the retraction, and
the model's step at the reversal (prediction just after the retraction starts less just before;
the truth's own step is about one noise sd); then the medians.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
from multiprocessing import get_context  # noqa: E402

import numpy as np  # noqa: E402

from discrepancy_measured_like import make_case, phantom_trial  # noqa: E402

PRESETS = ("skin", "skin-on-muscle", "artery-filled", "muscle", "skin-incision")
#: first: the records the variants were compared on; second: records looked at only once, after
SETS = {"first": [("lab", s) for s in range(2132, 2142)]
        + [("measured-like", s) for s in range(470, 480)] + [(p, 202) for p in PRESETS],
        "second": [("lab", s) for s in range(2142, 2152)]
        + [("measured-like", s) for s in range(480, 490)] + [(p, 203) for p in PRESETS]}


def _record(kind: str, seed: int) -> tuple:
    if kind == "measured-like":
        case = make_case(seed, trials=1)
        return case.trials[0], case.truth[0], case.noise_n
    trial, truth, noise, _ = phantom_trial(kind, seed)
    return trial, truth, noise


def _figures(pred: np.ndarray, truth: np.ndarray, t: np.ndarray, v: np.ndarray,
             noise: float) -> dict[str, float]:
    back = np.flatnonzero(v < -0.05)
    i = int(back[0])
    err = pred - truth
    return {"overall": float(np.sqrt(np.mean(err ** 2))) / noise,
            "retraction": float(np.sqrt(np.mean(err[t >= t[i]] ** 2))) / noise,
            "step": float(pred[i + 1] - pred[i - 1]) / noise}


def one(job: tuple[str, int]) -> dict[str, object]:
    from reference_py.discrepancy import workflow
    kind, seed = job
    trial, truth, noise = _record(kind, seed)
    t = trial.t_s
    v = np.gradient(trial.depth_mm, t)
    res = workflow.run([trial])
    orig = workflow._polish
    try:
        workflow._polish = lambda f, *a: f
        plain = workflow.run([trial])
    finally:
        workflow._polish = orig
    return {"record": f"{kind} {seed}", "named": res.named,
            "memory": float(res.fits[-1].nl.get("relax_memory", 0.0)),
            "without": _figures(plain.predictions[-1][0], truth, t, v, noise),
            "with": _figures(res.predictions[-1][0], truth, t, v, noise)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("--set", choices=sorted(SETS), default="first",
                    help="first: lab 2132-2141, measured-like 470-479, presets seed 202 (the "
                         "variants were compared on them); second: lab 2142-2151, "
                         "measured-like 480-489, presets seed 203")
    args = ap.parse_args(argv)
    if args.jobs < 1:
        ap.error("--jobs: at least 1")
    with get_context("spawn").Pool(args.jobs) as pool:
        rows = pool.map(one, SETS[args.set], chunksize=1)
    print("| record | memory | overall, without → with | retraction | step at the reversal |")
    print("|---|---|---|---|---|")
    for r in rows:
        a, b = r["without"], r["with"]
        print(f"| {r['record']} | {r['memory']:.2f} | {a['overall']:.2f} → {b['overall']:.2f} | "
              f"{a['retraction']:.2f} → {b['retraction']:.2f} | "
              f"{a['step']:+.1f} → {b['step']:+.1f} |")
    for group in ("lab", "measured-like", "20"):
        sel = [r for r in rows if group in str(r["record"])]
        if not sel:
            continue
        med = {k: (float(np.median([r["without"][k] for r in sel])),
                   float(np.median([r["with"][k] for r in sel])))
               for k in ("overall", "retraction")}
        worse = sum(r["with"]["overall"] > 1.01 * r["without"]["overall"] for r in sel)
        kept = sum(r["memory"] > 0.0 for r in sel)
        name = "phantom presets" if group == "20" else group
        print(f"{name} ({len(sel)}): memory kept in {kept}; median overall "
              f"{med['overall'][0]:.2f} → {med['overall'][1]:.2f}, retraction "
              f"{med['retraction'][0]:.2f} → {med['retraction'][1]:.2f}; worse by > 1 %: {worse}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
