"""``nte-ref phantom``: one record of the realistic phantom to CSV and its truth to JSON, or the
lab phantom's statistics beside the measured ones.

The command only: the phantom is :mod:`reference_py.sim` (tissue force, calibration, sensor and
record, statistics; PHANTOM.md); here are its options, the files it writes (both or neither) and
what it prints.
"""
from __future__ import annotations

import argparse
import os

from ..sim.calibration import LAB, PRESETS
from ..sim.phantom import PhantomResult, simulate_phantom, truth_json, truth_path
from ..sim.phantom_stats import format_stats_table, lab_statistics, result_stats


def write_phantom(csv_path: str | os.PathLike[str], res: PhantomResult) -> str:
    """Write the record (CSV) and its ground truth (JSON sidecar); returns the sidecar's path."""
    from .safe_write import Outputs
    side = truth_path(csv_path)
    with Outputs() as outs:                     # both files or neither
        outs.write_lines(outs.add(side, "--out"), [truth_json(res)])
        outs.write_lines(outs.add(csv_path, "--out"), res.csv_lines())
        outs.commit()
    return side


def _speeds(text: str) -> tuple[float, ...]:
    try:
        vals = tuple(float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a comma-separated list of speeds: {text!r}") \
            from None
    return vals


def _sign(text: str) -> int:
    if text not in ("1", "+1", "-1"):
        raise argparse.ArgumentTypeError(f"must be +1 or -1 (got {text!r})")
    return int(text)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``nte-ref phantom``."""
    p.add_argument("name", nargs="?", default="skin-on-muscle",
                   help=f"preset ({', '.join(PRESETS)}) or '{LAB}' (random tissue drawn from the "
                        "measured distributions; the seed picks it); default skin-on-muscle")
    p.add_argument("--out", metavar="FILE.csv",
                   help="record to write (the ground truth goes to FILE.truth.json)")
    p.add_argument("--seed", type=int, default=1, metavar="K",
                   help="seed of the sensor noise (and of the lab tissue), default 1")
    p.add_argument("--rate", type=float, metavar="HZ", help="sample rate (default: the preset's)")
    p.add_argument("--speed", type=_speeds, metavar="MM_S[,MM_S...]",
                   help="cruise speed(s), one insertion cycle per speed (default: the preset's)")
    p.add_argument("--stroke", type=float, metavar="MM", help="stage stroke (default 25)")
    p.add_argument("--dwell", type=float, metavar="S", help="dwell at full stroke (default 5.26)")
    p.add_argument("--surface", type=float, metavar="MM",
                   help="stage position where the tip touches the tissue (default: the preset's)")
    p.add_argument("--noise", type=float, metavar="N", help="white force noise sd (default 0.012)")
    p.add_argument("--offset", type=float, metavar="N", help="sensor offset after tare")
    p.add_argument("--drift", type=float, metavar="N_S", help="linear sensor drift, N/s")
    p.add_argument("--walk", type=float, metavar="N_SQRT_S", help="random-walk drift intensity")
    p.add_argument("--jitter", type=float, metavar="F",
                   help="timestamp jitter, fraction of the period, in [0, 0.5)")
    p.add_argument("--gaps", type=int, metavar="K", help="number of missing stretches (0.3 s)")
    p.add_argument("--force-sign", type=_sign, metavar="+1|-1",
                   help="-1: force recorded negative on insertion")
    p.add_argument("--depth-sign", type=_sign, metavar="+1|-1",
                   help="-1: depth recorded negative on insertion")
    p.add_argument("--stats", action="store_true",
                   help="print the lab phantom's statistics beside the measured ones (and each "
                        "preset's) instead of writing a record")
    p.add_argument("--trials", type=int, default=100, metavar="N",
                   help="lab records for --stats (default 100)")
    p.add_argument("--first-seed", type=int, default=1001, metavar="K",
                   help="first lab seed for --stats (default 1001: seeds 1-100 tuned the "
                        "generator, 1001 on were not looked at while tuning)")


def run(a: argparse.Namespace) -> int:
    """Handler of ``nte-ref phantom``: bad values raise ValueError (the caller exits 2)."""
    if a.stats:
        if a.trials < 1:
            raise ValueError(f"--trials must be >= 1 (got {a.trials})")
        if a.first_seed < 0:
            raise ValueError(f"--first-seed must be >= 0 (got {a.first_seed})")
        stats = lab_statistics(a.trials, a.first_seed)
        presets = {n: result_stats(simulate_phantom(n, seed=1)) for n in PRESETS}
        print(format_stats_table(stats, presets, a.first_seed))
        return 0
    if not a.out:
        raise ValueError("--out FILE.csv is required (or --stats)")
    res = simulate_phantom(a.name, rate_hz=a.rate, seed=a.seed, speeds_mm_s=a.speed,
                           stroke_mm=a.stroke, dwell_s=a.dwell, surface_mm=a.surface,
                           noise_n=a.noise, offset_n=a.offset, drift_n_s=a.drift,
                           walk_n_sqrt_s=a.walk, jitter=a.jitter, gaps=a.gaps,
                           force_sign=a.force_sign, depth_sign=a.depth_sign)
    side = write_phantom(a.out, res)
    tr = res.truth
    print(f"wrote {len(res.t_s)} samples ({res.t_s[-1]:.2f} s) to {a.out} and the truth to "
          f"{side}: surface at {tr['surface_mm']:.2f} mm, ruptures per cycle "
          f"{tr['ruptures_per_cycle']}")
    return 0
