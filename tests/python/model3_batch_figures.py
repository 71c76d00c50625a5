"""Model III's one-step innovation per phase over many records at once, for choosing its tuning:

    .venv/bin/python tests/python/model3_batch_figures.py [--set select|held|forms] [NAME=JSON ...]

Each NAME=JSON is a variant: EstimatorConfig fields over Model III's default configuration with
the contact front end on (e.g. ``'bound 1.0={"u_step_max": 1.0}'``); without any, the step bound
choices of README "Model III's step bound" (u_step_max 0, 0.1, 0.3, 1.0).  Every record runs
as recorded (air gap, tare) from the paper-10mms preset, in float64, through the reference's
bank batched over the records (one FilterBank, one element per record; a shorter record is
padded with repeats of its last sample, which the bank rejects as not later: its figures end
with it).  Per record: the one-step innovation RMS over the sensor noise in the insertion, the
dwell and the retraction, the reversal peak (config_loop_figures.py's phases and windows) and
the insertion without the samples the rupture detector flagged as tears, the reversal peak
without the first samples after a gap (config_loop_figures.reversal_peaks), and the signed mean
innovation over the noise in each phase (the part of the RMS that is a bias); printed as the median
(90th percentile, or the largest for a group of ten or fewer) per group and over all records.

Sets (seeds nothing else in the repository chose anything on):
  select  phantom seeds 201-215 of the six presets and `lab`, measured-like seeds 100-159
          (the step bound was chosen here);
  held    the README's held-out records: phantom seeds 301-310, measured-like seeds 31-50;
  forms   the measured-like generator's forms of config_loop_figures.ATLAS_FORMS (rates, noise,
          a tear over 1 mm, a stage that backs off, stick-slip, ...) on its held-out seeds
          41-50, one line per form.
About 20 s per variant and set on one core (forms: about 2 min).
"""
from __future__ import annotations

import json
import math
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import config_loop_figures as clf
from reference_py.bank import FilterBank
from reference_py.config import ContactConfig, default_config
from reference_py.fmath import real_for
from reference_py.layers import STATUS_TEAR
from reference_py.params import PRESETS
from reference_py.tools.csvio import read_trial, time_us
from reference_py.tools.plotting import PHASES, phase_of, read_truth

PRESET_NAMES = ("skin-incision", "skin-on-muscle", "muscle", "skin", "artery-filled", "lab")
SETS = {
    "select": [(p, s) for p in PRESET_NAMES for s in range(201, 216)] +
              [("measured-like", s) for s in range(100, 160)],
    "held": [(p, s) for p in PRESET_NAMES for s in clf.FIGURE_SEEDS] +
            [("measured-like", s) for s in clf.FIGURE_MEASURED_LIKE],
}
#: the step bound's choices (config.U_STEP_MAX; README "Model III's step bound")
DEFAULT_VARIANTS = {f"u_step_max {v:g}": {"u_step_max": v} for v in (0.0, 0.1, 0.3, 1.0)}
COLUMNS = ("insertion", "dwell", "retraction", "reversal peak", "insertion without tears",
           "reversal away from gaps", "ins. mean", "dwell mean", "retr. mean")


def record(d: Path, kind: str, seed: int, scale: float = 1.0, **form: object
           ) -> tuple[Path, np.ndarray, float]:
    """The record's file, each sample's phase (plotting.PHASES or "") and the sensor noise;
    ``form``: the measured-like generator's options (make_trial's keywords); ``scale``: the
    force (tare and noise with it) multiplied by it (config_loop_figures.FORCE_SCALES)."""
    if kind == "measured-like":
        return clf.measured_like_record(d, seed, scale, **form)
    f = clf.phantom(d, kind, seed)
    truth = read_truth(str(f.with_suffix(".truth.json")))
    phase = phase_of(clf.column(f, "t_s"), truth.spans)
    if scale != 1.0:
        g = d / f"{kind}_{seed}_x{scale:g}.csv"
        clf.write_record(g, clf.column(f, "t_s"), clf.column(f, "depth_mm"),
                         clf.column(f, "force_n") * scale)
        f = g
    return f, phase, float(truth.noise_n) * scale


def run_batch(recs: list[tuple[Path, np.ndarray, float]], fields: dict[str, object]
              ) -> np.ndarray:
    """One row of COLUMNS per record, Model III's default with ``fields`` over it."""
    R = real_for("float64")
    cfg = replace(default_config(3), contact=ContactConfig(enabled=True), **fields)
    trials = [read_trial(str(f)) for f, _, _ in recs]
    n, batch = max(len(t.t_s) for t in trials), len(trials)
    t_us = np.zeros((n, batch), dtype=np.int64)
    depth, vel, force = (np.zeros((n, batch)) for _ in range(3))
    for b, tr in enumerate(trials):
        m = len(tr.t_s)
        t_us[:m, b] = time_us(tr.t_s)
        t_us[m:, b] = t_us[m - 1, b]
        for dst, src in ((depth, tr.depth_mm), (vel, tr.velocity_mm_s), (force, tr.force_n)):
            dst[:m, b] = src
            dst[m:, b] = src[-1]
    bank = FilterBank(R, cfg, [PRESETS["paper-10mms"].params.as_list()] * batch)
    innovation = np.zeros((n, batch))
    status = np.zeros((n, batch), dtype=np.int64)
    for k in range(n):
        o = bank.step(t_us[k], R.arr(depth[k]), R.arr(vel[k]), R.arr(force[k]))
        innovation[k], status[k] = o.innovation, o.status
    rows = []
    for b, (_, phase, noise) in enumerate(recs):
        m = len(trials[b].t_s)
        inn, st, t = innovation[:m, b], status[:m, b], trials[b].t_s
        row = [float(np.sqrt(np.mean(inn[phase == name] ** 2))) / noise for name in PHASES]
        peak, away = clf.reversal_peaks(t, inn, phase)
        row.append(peak / noise)
        kept = (phase == "insertion") & ((st & STATUS_TEAR) == 0)
        row.append(float(np.sqrt(np.mean(inn[kept] ** 2))) / noise)
        row.append(away / noise)
        # the signed mean per phase: how much of the RMS is a one-step bias (the prediction
        # short of a rising force, beyond a falling one), not noise
        row += [float(np.mean(inn[phase == name])) / noise for name in PHASES]
        rows.append(row)
    return np.asarray(rows)


def summary(a: np.ndarray) -> str:
    tail = (lambda col: np.percentile(col, 90)) if len(a) > 10 else np.max
    return "  ".join(f"{np.median(a[:, k]):5.2f} ({tail(a[:, k]):5.1f})" for k in range(a.shape[1]))


def by_form(variants: dict[str, dict[str, object]]) -> int:
    """``--set forms``: per variant, one line per form of the measured-like generator."""
    print(f"Model III, files as recorded, the measured-like generator's forms, seeds "
          f"{clf.FORM_SEEDS[0]}-{clf.FORM_SEEDS[-1]}: one-step innovation RMS / noise, median "
          f"(the largest)")
    print(f"{'':22s}" + "  ".join(f"{c[:13]:>13s}" for c in COLUMNS))
    for label, fields in variants.items():
        print(label)
        for form, kw in clf.ATLAS_FORMS.items():
            with tempfile.TemporaryDirectory() as tmp:
                recs = [record(Path(tmp), "measured-like", s, **kw) for s in clf.FORM_SEEDS]
                print(f"  {form[:20]:20s}{summary(run_batch(recs, fields))}", flush=True)
    return 0


def main(argv: list[str]) -> int:
    set_name, scale = "select", 1.0
    if argv[:1] == ["--set"] and len(argv) > 1:
        set_name, argv = argv[1], argv[2:]
    if argv[:1] == ["--scale"] and len(argv) > 1:
        try:
            scale = float(argv[1])
        except ValueError:
            scale = math.nan
        if not (math.isfinite(scale) and 1e-4 <= scale <= 1e4):
            print(f"model3_batch_figures.py: --scale must be a number in [1e-4, 1e4] "
                  f"(got {argv[1]!r})", file=sys.stderr)
            return 2
        argv = argv[2:]
    variants: dict[str, dict[str, object]] = {}
    for a in argv:
        name, sep, text = a.partition("=")
        try:
            fields = json.loads(text) if sep else None
        except json.JSONDecodeError:
            fields = None
        if set_name not in (*SETS, "forms") or not isinstance(fields, dict):
            print("usage: model3_batch_figures.py [--set select|held|forms] [NAME=JSON ...] "
                  f"(sets: {', '.join((*SETS, 'forms'))}; JSON: an object of EstimatorConfig fields); "
                  f"not one: {a!r}", file=sys.stderr)
            return 2
        variants[name] = fields
    if set_name not in (*SETS, "forms"):
        print(f"usage: model3_batch_figures.py [--set select|held|forms] [NAME=JSON ...]; "
              f"unknown set {set_name!r}", file=sys.stderr)
        return 2
    variants = variants or DEFAULT_VARIANTS
    if set_name == "forms":
        return by_form(variants)
    names = SETS[set_name]
    kinds = list(dict.fromkeys(kind for kind, _ in names))
    with tempfile.TemporaryDirectory() as tmp:
        recs = [record(Path(tmp), kind, seed, scale) for kind, seed in names]
        print(f"Model III, files as recorded, set {set_name} ({len(recs)} records, force and "
              f"noise x{scale:g}): one-step "
              f"innovation RMS / noise, median (90th percentile; the largest for ten or fewer)")
        print(f"{'':22s}" + "  ".join(f"{c[:13]:>13s}" for c in COLUMNS))
        for label, fields in variants.items():
            t0 = time.time()
            a = run_batch(recs, fields)
            print(f"{label}  [{time.time() - t0:.0f} s]")
            for kind in kinds:
                idx = [i for i, (k, _) in enumerate(names) if k == kind]
                print(f"  {kind:20s}{summary(a[idx])}")
            phantom = [i for i, (k, _) in enumerate(names) if k in PRESET_NAMES]
            print(f"  {'phantom (pooled)':20s}{summary(a[phantom])}")
            print(f"  {'all':20s}{summary(a)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
