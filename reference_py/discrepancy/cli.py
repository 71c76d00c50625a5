"""nte-discrepancy: find where the force model and measured insertions disagree, name the missing
physical effect, add it and show the gap shrink.

usage: python -m reference_py.discrepancy.cli FILE [FILE ...] --out DIR [--no-figures]

FILE    measured trials: CSV with t_s, depth_mm, force_n (optional velocity_mm_s).  Several
        files are trials of the same needle and tissue: one base parameter set is fitted to all.
--out   report directory: report.md, report.json and PNG figures.

Exit status: 0 success, 2 bad input (message on stderr naming file, line and column).
"""
from __future__ import annotations

import os

# the fits solve thousands of small problems: BLAS threads only add overhead
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import sys  # noqa: E402
from pathlib import Path  # noqa: E402

from ..tools.cli import OneLineParser, add_unit_arguments, units_from  # noqa: E402
from ..tools.safe_write import check_directory  # noqa: E402
from .io import InputError, read_trial  # noqa: E402
from .prep import TooShort  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = OneLineParser(prog="nte-discrepancy", description=__doc__)  # one-line refusals
    ap.add_argument("files", nargs="+", metavar="FILE", help="measured trials (CSV)")
    ap.add_argument("--out", required=True, metavar="DIR",
                    help="report directory (created if absent; its parent must exist)")
    ap.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    add_unit_arguments(ap)
    args = ap.parse_args(argv)
    try:
        check_directory(args.out, "--out")
        trials = [read_trial(f, units_from(args)) for f in args.files]
    except (InputError, ValueError) as exc:
        print(f"nte-discrepancy: {exc}", file=sys.stderr)
        return 2
    from .report import write
    from .workflow import run
    try:
        res = run(trials)
    except TooShort as exc:
        print(f"nte-discrepancy: {exc}", file=sys.stderr)
        return 2
    for name, why in res.skipped:
        print(f"nte-discrepancy: skipped {name}: {why}", file=sys.stderr)
    try:
        rep = write(res, [str(f) for f in args.files], Path(args.out), not args.no_figures)
    except ValueError as exc:       # an output the safe writer refuses
        print(f"nte-discrepancy: {exc}", file=sys.stderr)
        return 2
    print(f"named: {', '.join(rep['named'])}; report in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
