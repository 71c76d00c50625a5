"""nte-discrepancy: find where the force model and measured insertions disagree, name the missing
physical effect, add it and show the gap shrink.

usage: nte-discrepancy FILE [FILE ...] --out DIR [--no-figures] [--each] [--jobs N]
                       [--force-unit U] [--time-unit U] [--depth-unit U]
                       [--force-sign +1|-1] [--depth-sign +1|-1] [--depth-offset MM]
                       [--no-units-check]
                       [--columns t=NAME,depth=NAME,force=NAME[,velocity=NAME]]

FILE    measured trials: CSV with t_s, depth_mm, force_n (optional velocity_mm_s; a spreadsheet
        export with a byte-order mark and quoted cells is fine), or a candump log (.log) of the
        bench's Depth and Force frames, decoded with the project's DBC.  Several files are
        trials of the same needle and tissue: one base parameter set is fitted to all.
--out   report directory: report.md, report.json, estimator_config.json and PNG figures
        (all written together or none; the directory is checked before the run).
--each  run every FILE as its own condition, into DIR/<file stem>/ (with --jobs N in parallel).
--jobs  worker processes (default: the CPUs this process may use): with --each, conditions side
        by side; for one condition, its fits that do not depend on each other (the base
        model's starts, a round's screens and refines) and its figures.  The report is the
        same for every N.
--force-unit, --time-unit, --depth-unit, --force-sign, --depth-sign, --depth-offset,
--no-units-check
        how the CSV was recorded (converted by the tools' CSV reader, which refuses implausible
        units or signs naming the likely option).  A record that still reads negative on
        insertion (a candump log, or --no-units-check) is detected per trial, flipped, and the
        report says so.
--columns  a logger's own column names (e.g. t=time_us,depth=pz,force=fz with --time-unit us):
        the CSV is read as it is (the velocity computed from the depth unless velocity= names it).

Exit status: 0 success, 2 bad input or options (one line on stderr naming file, line and column
or the option).
"""
from __future__ import annotations

import os

# the fits solve thousands of small problems: BLAS threads only add overhead
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import sys  # noqa: E402
from pathlib import Path  # noqa: E402

from ..tools.arguments import OneLineParser, add_unit_arguments, units_from  # noqa: E402
from ..tools.safe_write import check_directory  # noqa: E402
from .io import InputError, Trial, read_trial  # noqa: E402
from .pool import available_cpus, forked  # noqa: E402
from .prep import TooShort  # noqa: E402

def _one(job: tuple[list[Trial], list[str], str, bool, int]) -> tuple[str, str, list]:
    trials, names, out, figs, jobs = job
    from .report import write
    from .workflow import run
    try:
        res = run(trials, jobs=jobs)
    except TooShort as exc:
        return out, f"error: {exc}", []
    try:
        rep = write(res, names, Path(out), figs, jobs)
    except ValueError as exc:       # an output the safe writer refuses
        return out, f"error: {exc}", res.skipped
    return out, f"named: {', '.join(rep['named'])}; {rep['verdict']['text']}", res.skipped


def main(argv: list[str] | None = None) -> int:
    ap = OneLineParser(prog="nte-discrepancy", description=__doc__)  # one-line refusals
    ap.add_argument("files", nargs="+", metavar="FILE", help="measured trials (CSV, or candump .log)")
    ap.add_argument("--out", required=True, metavar="DIR",
                    help="report directory (created if absent; its parent must exist)")
    ap.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    add_unit_arguments(ap)
    ap.add_argument("--each", action="store_true",
                    help="run every FILE as its own condition, into DIR/<file stem>/")
    ap.add_argument("--jobs", type=int, default=available_cpus(), metavar="N",
                    help="worker processes (default: the CPUs this process may use)")
    args = ap.parse_args(argv)
    if args.jobs < 1:
        print(f"nte-discrepancy: --jobs {args.jobs}: must be >= 1", file=sys.stderr)
        return 2
    out = Path(args.out)
    try:
        check_directory(args.out, "--out")
        trials = [read_trial(f, units_from(args)) for f in args.files]
    except (InputError, ValueError) as exc:
        print(f"nte-discrepancy: {exc}", file=sys.stderr)
        return 2
    for trial in trials:
        for line in (trial.note or "").splitlines():
            print(f"nte-discrepancy: {line}", file=sys.stderr)
    figs = not args.no_figures
    if args.each:
        stems = [Path(f).stem for f in args.files]
        if len(set(stems)) < len(stems):
            print("nte-discrepancy: --each: two FILEs share a name (their reports would collide)",
                  file=sys.stderr)
            return 2
        out.mkdir(exist_ok=True)
        jobs = [([t], [f], str(out / Path(f).stem), figs, 1)
                for t, f in zip(trials, args.files)]
    else:
        jobs = [(trials, list(args.files), str(out), figs, 1)]
    if len(jobs) == 1:      # one condition: the workers share its fits
        jobs = [(*jobs[0][:4], args.jobs)]
    if args.jobs > 1 and len(jobs) > 1:
        with forked(args.jobs) as pool:
            results = list(pool.map(_one, jobs))
    else:
        results = [_one(j) for j in jobs]
    status = 0
    for where, line, skipped in results:
        for name, why in skipped:
            print(f"nte-discrepancy: skipped {name}: {why}", file=sys.stderr)
        if line.startswith("error: "):
            print(f"nte-discrepancy: {where}: {line[7:]}", file=sys.stderr)
            status = 2
        else:
            print(f"{line}; report in {where}")
    return status


if __name__ == "__main__":
    sys.exit(main())
