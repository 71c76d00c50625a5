"""Confusion of the discrepancy workflow on blind cases whose effect forms it was not written for.

The cases come from the blind generator beside this script (discrepancy_generator.py, which the
workflow never uses): every vocabulary effect in two or three physically different forms, some of
which the effect library fits ("library") and some it does not ("held out"), plus cases without a
hidden effect, relaxation + pre-sliding pairs and a stick-slip oscillation outside the vocabulary.

Prints, from one run: the confusion matrix per effect (all forms), per form, and restricted to the
held-out forms (rows: hidden, columns: first effect named); the pair and 'none' rows; the
"unexplained" verdict on stick-slip and on the vocabulary's own cases (also graded against the
noise-free truth); parameters outside their documented bounds; the median gap shrink; the run
time per trial.

usage: .venv/bin/python tests/python/discrepancy_confusion.py [--full | --cases N] [--first K]
                                                              [--workers W] [--results FILE]
                                                              [--regrade FILE]
  --full      20 cases per effect form (and per none / pair / stick-slip kind), ~460 cases
  --cases N   N cases per kind (default 4: the CI subset of tests/python/test_discrepancy_blind.py)

It lives in tests/, beside its generator, because the cases are the tests' own: an examiner the
product never imports (README, "Blind confusion").
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import discrepancy_generator  # noqa: E402
from reference_py.discrepancy.effects import NONE, VOCABULARY  # noqa: E402

SHORT = {"dwell_relaxation": "relax", "reversal_presliding": "presl", "velocity_friction": "visc",
         "direction_asymmetry": "asym", "layer_puncture": "layer", "sensor_drift": "drift",
         "tissue_motion": "motion", NONE: "none", "error": "error"}
PAIR_KIND, NONE_KIND, OOV_KIND = "pair", "none", "stick_slip"
CI_CASES, FULL_CASES = 4, 20


def _single(r: dict) -> bool:
    return "/" in r["kind"]


def _effect(r: dict) -> str:
    return str(r["kind"]).split("/")[0]


def _held(r: dict) -> bool:
    return bool(r["held_out"].get(_effect(r)))


def _matrix(title: str, rows: list[tuple[str, list[dict]]], cols: list[str]) -> list[str]:
    width = max([22] + [len(n) + 2 for n, _ in rows])
    out = [title, "", "hidden \\ named".ljust(width) + "".join(SHORT.get(c, c)[:6].rjust(7)
                                                               for c in cols) + "   right"]
    for name, rs in rows:
        cnt = [sum(1 for r in rs if r["first"] == c) for c in cols]
        want = _effect(rs[0]) if rs and _single(rs[0]) else NONE
        right = sum(1 for r in rs if r["first"] == want)
        out.append(name.ljust(width) + "".join((str(c) if c else ".").rjust(7) for c in cnt)
                   + f"{right:5d}/{len(rs)}")
    return out + [""]


def summarise(results: list[dict]) -> str:
    """The figures of one blind run (rows of ``discrepancy_generator.run_case``) as text."""
    cols = list(VOCABULARY) + [NONE]
    if any(r["first"] not in cols for r in results):
        cols.append("error")
    singles = [r for r in results if _single(r)]
    nones = [r for r in results if r["kind"] == NONE_KIND]
    effects = [e for e in VOCABULARY if any(_effect(r) == e for r in singles)]
    per_effect = [(e, [r for r in singles if _effect(r) == e]) for e in effects]
    forms = sorted({r["kind"] for r in singles}, key=lambda k: (effects.index(k.split("/")[0]),
                                                                 k))
    per_form = [(k + ("" if not _held(rs[0]) else " *"), rs) for k in forms
                for rs in [[r for r in singles if r["kind"] == k]]]
    held = [(e, [r for r in rs if _held(r)]) for e, rs in per_effect]
    held = [(e, rs) for e, rs in held if rs]
    extra = [("none", nones)] if nones else []
    n = len(results)
    L = [f"Blind run: {n} cases ({sum(len(t) for _, t in per_effect)} with one hidden effect, "
         f"{len(nones)} without, {sum(1 for r in results if r['kind'] == PAIR_KIND)} pairs, "
         f"{sum(1 for r in results if r['kind'] == OOV_KIND)} stick-slip)", ""]
    L += _matrix("Confusion per effect, all forms (rows: hidden; columns: first named)",
                 per_effect + extra, cols)
    L += _matrix("Confusion per form (* held out: a form the effect library does not contain)",
                 per_form, cols)
    L += _matrix("Confusion restricted to held-out forms", held, cols)
    pairs = [r for r in results if r["kind"] == PAIR_KIND]
    if pairs:
        both = [r for r in pairs if set(r["effects"]) <= set(r["named"])]
        L.append(f"relaxation + pre-sliding pairs: both named in {len(both)}/{len(pairs)}")
        for fr in sorted({tuple(sorted(r["forms"].items())) for r in pairs}):
            rs = [r for r in pairs if tuple(sorted(r["forms"].items())) == fr]
            ok = sum(1 for r in rs if set(r["effects"]) <= set(r["named"]))
            L.append("  " + " + ".join(f for _, f in fr).ljust(34) + f"{ok}/{len(rs)}")
        L.append("")
    oov = [r for r in results if r["kind"] == OOV_KIND]
    vocab = [r for r in results if r["kind"] != OOV_KIND]
    known = [r for r in results if r["unexplained"] is not None]
    if not known:
        L += ["'unexplained' verdict: the report carries none", ""]
    else:
        fired = sum(1 for r in oov if r["unexplained"])
        silent = sum(1 for r in vocab if r["unexplained"] is False)
        # what the final model leaves, judged on the noise-free truth with the verdict's rule
        left, fits = discrepancy_generator.verdict_against_truth(vocab)
        L += [f"'unexplained' verdict: fires on stick-slip {fired}/{len(oov)}; silent on the "
              f"vocabulary's own cases {silent}/{len(vocab)}",
              f"  against the truth (the final model leaves a stretch over the verdict's "
              f"threshold): fires on {sum(1 for r in left if r['unexplained'])}/{len(left)} "
              f"that do, silent on {sum(1 for r in fits if not r['unexplained'])}/{len(fits)} "
              f"that do not", ""]
    viol = [r for r in results if r["violations"]]
    L.append(f"Cases with a parameter outside its documented bounds: {len(viol)}/{n}")
    firsts: dict[str, int] = {}
    for r in viol:
        firsts[r["violations"][0]] = firsts.get(r["violations"][0], 0) + 1
    for v, c in sorted(firsts.items(), key=lambda x: -x[1])[:5]:
        L.append(f"  {c:4d}x {v}")
    L += ["", "Median gap shrink (1 - RMSE after / before, vs the noise-free truth), cases whose "
          "hidden effect is named first", "",
          "effect".ljust(22) + "phases".rjust(10) + "overall".rjust(10) + "cases".rjust(8)]
    for e, rs in per_effect:
        hit = [r for r in rs if r["first"] == e]
        if hit:
            sp = np.median([1 - r["support_after"] / r["support_before"] for r in hit])
            ov = np.median([1 - r["overall_after"] / r["overall_before"] for r in hit])
            L.append(e.ljust(22) + f"{sp:10.2f}{ov:10.2f}{len(hit):8d}")
        else:
            L.append(e.ljust(22) + "-".rjust(10) + "-".rjust(10) + "0".rjust(8))
    rt = np.array([r["runtime_per_trial_s"] for r in results])
    errs = [r for r in results if r.get("error")]
    L += ["", f"Run time per trial: median {np.median(rt):.2f} s, 90th pct "
          f"{np.percentile(rt, 90):.2f} s, max {rt.max():.2f} s over {n} cases"
          + (f"; {len(errs)} cases raised (first: {errs[0]['error']})" if errs else "")]
    return "\n".join(L)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="discrepancy_confusion.py",
                                 description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    size = ap.add_mutually_exclusive_group()
    size.add_argument("--full", action="store_true",
                      help=f"{FULL_CASES} cases per effect form and per other kind")
    size.add_argument("--cases", type=int, default=CI_CASES, metavar="N",
                      help=f"cases per kind (default {CI_CASES}, the CI subset)")
    ap.add_argument("--first", type=int, default=0, metavar="K",
                    help="run cases K .. K + N - 1 of each kind (default 0; a K beyond the "
                         "cases any figure was tuned on draws held-out cases)")
    ap.add_argument("--workers", type=int, default=2, metavar="W")
    ap.add_argument("--results", metavar="FILE", help="also write the per-case rows as JSON")
    ap.add_argument("--regrade", metavar="FILE",
                    help="summarise a --results file instead of running the cases")
    args = ap.parse_args(argv)
    if args.cases < 1 or args.workers < 1:
        ap.error("--cases and --workers must be at least 1")
    if args.first < 0:
        ap.error("--first must be at least 0")
    if args.regrade:
        try:
            with open(args.regrade) as fh:
                rows = json.load(fh)
            if not isinstance(rows, list) or not all(isinstance(r, dict) and "kind" in r
                                                     for r in rows):
                raise ValueError("not a list of case rows")
        except (OSError, ValueError) as exc:
            print(f"confusion: --regrade {args.regrade}: {exc}", file=sys.stderr)
            return 2
        print(summarise(rows))
        return 0
    if args.results:
        parent = Path(args.results).resolve().parent
        if not parent.is_dir() or not os.access(parent, os.W_OK):
            print(f"confusion: --results {args.results}: directory {parent} is missing or not "
                  "writable", file=sys.stderr)
            return 2
    cases = FULL_CASES if args.full else args.cases
    rows = discrepancy_generator.run_all(discrepancy_generator.jobs_for(cases, first=args.first),
                                         workers=args.workers, progress=sys.stderr.isatty())
    if args.results:
        with open(args.results, "w") as fh:
            json.dump(rows, fh)
    print(summarise(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
