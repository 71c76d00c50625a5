"""The layer sets' figures (README, "Layer sets"), printed; run after `make build`:

    .venv/bin/python tests/python/layer_sets_figures.py [PRESET,...] [FIRST LAST] [ML_FIRST ML_LAST]

The atlas (identify on one record with `--model 3 --contact on --export-config`, predict another
trial of the same condition from its depth alone with `--config --predict-only`), RMSE to the
noise-free force over its peak, with the export as it is (layer sets), without them
(`--no-layer-sets`: one parameter set), and with the sets' starts moved by -2, -1, +1, +2 mm
(a trial that tears earlier or later than the one identified).  Records, by default the ones
the README reports, not used to choose the export's shifts (development: phantom
skin-on-muscle and artery-filled seeds 201-205, measured-like seeds 22-30):

* phantom presets, files as recorded, seed k identified and seed k + 1 predicted (the last
  predicts the first), the true surface given as a robot registered to the tissue knows it;
* the measured-like generator (tests/python/discrepancy_measured_like.py: another force law and
  sampling), each record identified as generated and predicted on its truth under a fresh
  noise draw, the tare removed.

The runs are nte-run-double's (bit for bit the reference's: test_config_loop.py, for speed).
"""
from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from config_loop_figures import C, phantom, run, write_record  # noqa: E402

PRESETS = ("skin-on-muscle", "skin", "muscle", "artery-filled", "skin-incision")
SHIFTS_MM = (-2.0, -1.0, 1.0, 2.0)


def predict(d: Path, cfg: Path, record: Path, truth: np.ndarray, surface: float | None) -> float:
    """RMSE / peak, %, of the prediction of record from cfg."""
    extra = ["--surface", repr(surface)] if surface is not None else []
    run(str(record), "--config", str(cfg), "--predict-only", *extra, "--out", str(d / "p.csv"))
    est = np.genfromtxt(d / "p.csv", delimiter=",", names=True)["force_hat_n"]
    return 100.0 * float(np.sqrt(np.mean((est - truth) ** 2))) / float(np.max(np.abs(truth)))


def moved(d: Path, cfg: Path, shift: float) -> Path:
    doc = json.loads(cfg.read_text())
    for s in doc.get("model3", {}).get("layer_sets", []):
        s["start_mm"] = max(0.05, s["start_mm"] + shift)
    out = d / "moved.json"
    out.write_text(json.dumps(doc))
    return out


def one_pair(d: Path, source: Path, target: Path, truth: np.ndarray,
             surface: float | None) -> list[float]:
    """[without sets, with sets, then each shift of their starts], % of the peak."""
    with_sets, single = d / "sets.json", d / "single.json"
    for cfg, extra in ((with_sets, []), (single, ["--no-layer-sets"])):
        run(str(source), "--model", "3", "--contact", "on", *extra, "--out",
            str(d / "id.csv"), "--export-config", str(cfg))
    row = [predict(d, single, target, truth, surface), predict(d, with_sets, target, truth,
                                                               surface)]
    return row + [predict(d, moved(d, with_sets, s), target, truth, surface) for s in SHIFTS_MM]


def phantom_rows(d: Path, presets: list[str], seeds: list[int]) -> list[list[float]]:
    rows = []
    for preset in presets:
        for i, s in enumerate(seeds):
            src, dst = phantom(d, preset, s), phantom(d, preset, seeds[(i + 1) % len(seeds)])
            truth = np.genfromtxt(dst, delimiter=",", names=True)["force_true_n"]
            surface = json.loads(dst.with_suffix(".truth.json").read_text())["surface_mm"]
            rows.append(one_pair(d, src, dst, truth, surface))
            print(f"   {preset:15s} {s}: " + _cells(rows[-1]), flush=True)
    return rows


def measured_like_rows(d: Path, seeds: range) -> list[list[float]]:
    from discrepancy_measured_like import make_trial
    rows = []
    for seed in seeds:
        tr, truth, sigma, _ = make_trial(seed)
        a, b = d / "ml_a.csv", d / "ml_b.csv"
        fresh = truth + np.random.default_rng(1000 + seed).normal(0.0, sigma, len(truth))
        for path, force in ((a, tr.force_n), (b, fresh)):
            write_record(path, tr.t_s, tr.depth_mm, force)
        rows.append(one_pair(d, a, b, truth - truth[0], None))
        print(f"   measured-like   {seed}: " + _cells(rows[-1]), flush=True)
    return rows


def _cells(row: list[float]) -> str:
    labels = ["without", "sets"] + [f"{s:+.0f} mm" for s in SHIFTS_MM]
    return "  ".join(f"{lb} {v:5.1f} %" for lb, v in zip(labels, row))


def summary(label: str, rows: list[list[float]]) -> None:
    r = np.array(rows)
    cells = [f"{np.median(r[:, j]):.1f} % ({np.max(r[:, j]):.1f})" for j in range(r.shape[1])]
    worse = [f"{int(np.sum(r[:, j] > r[:, 0]))}/{len(r)}" for j in range(1, r.shape[1])]
    print(f"| {label}, {len(r)} pairs | " + " | ".join(cells) + " |")
    print("|   worse than without sets | | " + " | ".join(worse) + " |")


def main(argv: list[str]) -> None:
    if not C.exists():
        raise SystemExit(f"{C} missing: make build")
    presets = argv[0].split(",") if argv else list(PRESETS)
    first, last = (int(argv[1]), int(argv[2])) if len(argv) > 2 else (301, 310)
    ml = range(int(argv[3]), int(argv[4]) + 1) if len(argv) > 4 else range(31, 51)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        print(f"phantom {', '.join(presets)}, seeds {first}-{last}:")
        ph = phantom_rows(d, presets, list(range(first, last + 1)))
        print(f"measured-like seeds {ml[0]}-{ml[-1]}:")
        mlr = measured_like_rows(d, ml)
    print("\n| records | without sets | sets | " + " | ".join(f"starts {s:+.0f} mm"
                                                             for s in SHIFTS_MM) + " |")
    print("|---|---|---|" + "---|" * len(SHIFTS_MM))
    summary("phantom", ph)
    summary("measured-like", mlr)


if __name__ == "__main__":
    main(sys.argv[1:])
