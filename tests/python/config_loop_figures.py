"""The loop's figures on the phantom (issue 21), printed; run after `make build`:

    .venv/bin/python tests/python/config_loop_figures.py [PRESET...]

1. The workflow's config: `nte-discrepancy` on the tuning seeds' records (1-5) writes
   estimator_config.json; on each held-out record (seeds 101-110, files as recorded: air gap,
   tare) the one-step innovation RMS of the estimator with `--config` against Model II's
   default (`--model 2`, no config); `config_loop_figures.py --workflow [PRESET]` prints this
   part alone.
2. The atlas: identify on one record with `--model M --contact on --export-config`, predict
   the next record of the same condition (a different seed; the pairs cycle through the group)
   with `--config --predict-only --surface` (the record's true surface, as a robot registered
   to the tissue knows it): RMSE to the noise-free force, over its peak; Model II and Model III.

3. The atlas on a second generator held out from the export's development: the measured-like
   records of discrepancy_measured_like.py (another force law and sampling; seeds 11-21), each
   identified as generated and predicted on the same record's truth under a fresh noise draw
   (the same insertion measured again), RMSE to the truth less its tare over the peak; part 6
   predicts another insertion instead.
4. The one-step innovation RMS over the sensor noise per phase (insertion, dwell, retraction)
   and the reversal's peak (the largest |innovation| / noise within 1 s after the retraction
   starts), files as recorded, Model II's default beside Model III's (contact front end on),
   median and 90th percentile over records, and the insertion again without the samples
   Model III's rupture detector flagged as tears, and the reversal's peak again without the
   first samples after a gap in the record (reversal_peaks)
   (`config_loop_figures.py --phases PRESET...` prints this part alone): the phantom presets
   and `lab` on seeds 301-310, and the measured-like generator on seeds 31-50.  Model III's
   gate (config.GATE_REOPEN_AFTER) was chosen on skin-on-muscle seeds 101-102 and compared on
   seeds 201-210 and measured-like seeds 11-30; these seeds were not looked at.
5. The atlas of part 3 under other forms of the measured-like generator (rates, noise, a tear
   that runs on, a stage that backs off, stick-slip, no membrane; held-out seeds 41-50):
   `config_loop_figures.py --forms` prints this part alone.
6. The atlas of part 3 on another trial of the same condition (make_trial's ``trial``: the
   same tissue, speed and rate; the stage starting +-1.5 mm elsewhere, each tear +-0.3 mm and
   x0.85-1.15, a new clock, tare and noise; held-out seeds 320-339): identify on the record,
   predict trial 1 from its depth alone, once with `--surface` (its true surface, a robot
   registered to the tissue) and once with the surface the config carries;
   `config_loop_figures.py --trials` prints this part alone; `--trials HZ MM_S FIRST LAST`
   at one sampling rate and stage speed (the generator draws both per seed: 76-100 Hz,
   1-3 mm/s) on seeds FIRST..LAST.
7. Part 4's measured-like figures with force and noise scaled together by 0.1, 0.03 and 0.01
   (the same insertions on a smaller force range and a quieter sensor, down to the 0.05-0.5 N
   and 0.3 mN of relaxation-test rigs): `config_loop_figures.py --scaled` prints this part
   alone.

The estimator runs are nte-run-double's (bit for bit the reference's: test_config_loop.py), for
speed.  Tuning seeds 1-5, held-out seeds 101-110.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from reference_py.layers import STATUS_TEAR
from reference_py.tools.plotting import (PHASES, phase_of, read_input, read_truth,
                                         spans_from_motion)

ROOT = Path(__file__).resolve().parents[2]
C = ROOT / "build" / "host" / "bin" / "nte-run-double"
VENV = Path(sys.executable).parent
TUNING = (1, 2, 3, 4, 5)
HELD_OUT = tuple(range(101, 111))


def phantom(d: Path, preset: str, seed: int) -> Path:
    f = d / f"{preset}_{seed}.csv"
    if not f.exists():
        subprocess.run([str(VENV / "nte-ref"), "phantom", preset, "--seed", str(seed),
                        "--out", str(f)], check=True, capture_output=True)
    return f


def run(*args: str) -> None:
    r = subprocess.run([str(C), *args], capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(r.stderr)


def column(f: Path, name: str) -> np.ndarray:
    return np.genfromtxt(f, delimiter=",", names=True)[name]


def innovation_rms(f: Path) -> float:
    return float(np.sqrt(np.mean(column(f, "innovation_n") ** 2)))


def atlas(d: Path, preset: str, seeds: tuple[int, ...], model: int) -> list[tuple[float, float]]:
    """(RMSE N, peak N) of each prediction of seeds[i + 1] from seeds[i]'s identification."""
    out = []
    for i, s in enumerate(seeds):
        t = seeds[(i + 1) % len(seeds)]
        src, dst = phantom(d, preset, s), phantom(d, preset, t)
        cfg = d / f"x{model}_{s}.json"
        run(str(src), "--model", str(model), "--contact", "on", "--out", str(d / "id.csv"),
            "--export-config", str(cfg))
        surface = json.loads(dst.with_suffix(".truth.json").read_text())["surface_mm"]
        run(str(dst), "--config", str(cfg), "--predict-only", "--surface", str(surface),
            "--out", str(d / "pr.csv"))
        truth = column(dst, "force_true_n")
        err = column(d / "pr.csv", "force_hat_n") - truth
        out.append((float(np.sqrt(np.mean(err ** 2))), float(np.max(np.abs(truth)))))
    return out


def write_record(path: Path, t: np.ndarray, x: np.ndarray, f: np.ndarray) -> None:
    path.write_text("t_s,depth_mm,force_n\n" + "".join(
        "%.17g,%.17g,%.17g\n" % r for r in zip(t, x, f)))


def identify(d: Path, record: Path, model: int, cfg: Path) -> Path:
    """Model ``model`` (contact front end on) over ``record``, its export written to ``cfg``."""
    run(str(record), "--model", str(model), "--contact", "on", "--out", str(d / "id.csv"),
        "--export-config", str(cfg))
    return cfg


def predicted_percent(d: Path, record: Path, cfg: Path, target: np.ndarray,
                      *surface: str) -> float:
    """RMSE of ``cfg``'s prediction of ``record`` from its depth alone (``surface``: e.g.
    "--surface", "12.3"; none: the config's) to ``target`` (N), in % of the target's peak."""
    run(str(record), "--config", str(cfg), "--predict-only", *surface, "--out",
        str(d / "pr.csv"))
    err = column(d / "pr.csv", "force_hat_n") - target
    return 100.0 * float(np.sqrt(np.mean(err ** 2))) / float(np.max(np.abs(target)))


def measured_like_atlas(d: Path, seeds: range) -> None:
    from discrepancy_measured_like import make_trial

    print(f"3. atlas on the measured-like generator (held out), seeds {seeds[0]}-{seeds[-1]}: "
          "RMSE / peak of the prediction of the same record under a fresh noise draw")
    rel: dict[int, list[float]] = {2: [], 3: []}
    for seed in seeds:
        tr, truth, sigma, _ = make_trial(seed)
        a, b = d / f"ml{seed}a.csv", d / f"ml{seed}b.csv"
        write_record(a, tr.t_s, tr.depth_mm, tr.force_n)
        rng = np.random.default_rng(1000 + seed)
        write_record(b, tr.t_s, tr.depth_mm, truth + rng.normal(0.0, sigma, len(truth)))
        target = truth - truth[0]           # the record starts in the air: truth[0] is the tare
        line = f"   seed {seed}:"
        for model in (2, 3):
            cfg = identify(d, a, model, d / f"ml{seed}_{model}.json")
            rel[model].append(predicted_percent(d, b, cfg, target))
            line += f" Model {'I' * model} {rel[model][-1]:.1f} %"
        print(line)
    for model in (2, 3):
        print(f"   Model {'I' * model}: median {np.median(rel[model]):.1f} %, "
              f"range {np.min(rel[model]):.1f}-{np.max(rel[model]):.1f} %")


FIGURE_SEEDS = tuple(range(301, 311))
FIGURE_MEASURED_LIKE = range(31, 51)
MODEL_ARGS = {2: ("--model", "2"), 3: ("--model", "3", "--contact", "on")}


#: the reversal's figure: the largest |one-step innovation| over the noise within this long
#: after each retraction starts (issue 21: "no spike above 5x noise at a reversal")
REVERSAL_WINDOW_S = 1.0
#: a sample interval over this many times the record's median interval is a gap (frames lost);
#: the one-step innovation of the sample that ends it predicts across the whole gap, and the
#: next few may still carry it (a refused update is retried on the next sample)
GAP_FACTOR = 3.0
#: samples set aside from a gap's end, its own included, for the peak "away from gaps"
GAP_SKIP = 5


def reversal_peaks(t: np.ndarray, innovation: np.ndarray, phase: np.ndarray
                   ) -> tuple[float, float]:
    """The reversal's figures, N: the largest |innovation| within REVERSAL_WINDOW_S after each
    start of a retraction (the largest over cycles; 0 without one), and the same without the
    GAP_SKIP samples from the end of each gap (GAP_FACTOR).  Measured-like records lose frames,
    and a gap at the turn-over makes its first innovation a prediction over up to 0.3 s of it:
    held-out seeds 31-50 have a gap in 9 of 20 reversal windows."""
    back = phase == "retraction"
    starts = t[1:][back[1:] & ~back[:-1]]
    dt = np.diff(t, prepend=t[0])
    near_gap = np.zeros(len(t), dtype=bool)
    if len(t) > 2:
        for k in np.flatnonzero(dt > GAP_FACTOR * np.median(dt[1:])):
            near_gap[k:k + GAP_SKIP] = True
    peak = away = 0.0
    for t0 in starts:
        window = (t >= t0) & (t < t0 + REVERSAL_WINDOW_S)
        peak = max(peak, float(np.max(np.abs(innovation[window]))))
        if np.any(window & ~near_gap):
            away = max(away, float(np.max(np.abs(innovation[window & ~near_gap]))))
    return peak, away


def phase_rms_by_model(d: Path, record: Path, phase: np.ndarray, noise: float
                       ) -> dict[int, list[float]]:
    """Each model's one-step innovation RMS over the noise in every phase of PHASES (``phase``:
    each sample's phase name, plotting.phase_of), then the reversal's largest |innovation| over
    the noise (REVERSAL_WINDOW_S after each start of a retraction, the largest over cycles)."""
    out = {}
    for model in (2, 3):
        run(str(record), *MODEL_ARGS[model], "--out", str(d / "ph.csv"))
        innovation = column(d / "ph.csv", "innovation_n")
        t = column(d / "ph.csv", "t_s")
        out[model] = [float(np.sqrt(np.mean(innovation[phase == name] ** 2))) / noise
                      for name in PHASES]
        peak, away = reversal_peaks(t, innovation, phase)
        out[model].append(peak / noise)
        # the insertion without the tears' own samples (Model III's rupture detector flags
        # them; a drop within a sample no one-step prediction sees coming): what the model
        # leaves once the tears are counted apart
        status = column(d / "ph.csv", "status").astype(np.int64)
        kept = (phase == "insertion") & ((status & STATUS_TEAR) == 0)
        out[model].append(float(np.sqrt(np.mean(innovation[kept] ** 2))) / noise)
        out[model].append(away / noise)
    return out


def print_phase_rows(label: str, rows: dict[int, list[list[float]]]) -> None:
    for model in (2, 3):
        a = np.asarray(rows[model])
        cells = ", ".join(f"{n} {np.median(a[:, k]):.1f} ({np.percentile(a[:, k], 90):.1f})"
                          for k, n in enumerate(PHASES + ("reversal peak",
                                                          "insertion without the tear samples",
                                                          "reversal peak away from gaps")))
        print(f"   {label:15s} Model {'I' * model:3s}: {cells}")


def measured_like_record(d: Path, seed: int, scale: float = 1.0, **form: object
                         ) -> tuple[Path, np.ndarray, float]:
    """The measured-like record of ``seed`` (make_trial's ``form`` options) written to a file,
    its force (tare and noise with it) times ``scale``: the file, each sample's phase as
    `nte-ref plot` draws it from the motion (insertion and dwell only where the true force is
    above twice the noise: the air gap is no phase) and the noise sd (N, times ``scale``)."""
    from discrepancy_measured_like import make_trial
    tr, force_true, sigma, _ = make_trial(seed, **form)  # type: ignore[arg-type]
    f = d / f"ml{seed}.csv"
    write_record(f, tr.t_s, tr.depth_mm, tr.force_n * scale)
    phase = phase_of(tr.t_s, spans_from_motion(read_input(str(f))))
    in_air = force_true - force_true[0] <= 2.0 * sigma
    phase[in_air & (phase != "retraction")] = ""
    return f, phase, float(sigma) * scale


def innovation_by_phase(d: Path, presets: list[str]) -> None:
    """Part 4.  The phases as `nte-ref plot` draws them: the phantom's from its truth file's
    cycles, the measured-like records' from their motion (insertion and dwell only where the
    true force is above twice the noise: the air gap is no phase)."""
    from discrepancy_measured_like import make_trial
    print(f"4. one-step innovation RMS / noise per phase, median (90th percentile), files as "
          f"recorded; phantom seeds {FIGURE_SEEDS[0]}-{FIGURE_SEEDS[-1]}, measured-like seeds "
          f"{FIGURE_MEASURED_LIKE[0]}-{FIGURE_MEASURED_LIKE[-1]}")
    pooled: dict[int, list[list[float]]] = {2: [], 3: []}
    for preset in [*presets, "lab"]:
        rows: dict[int, list[list[float]]] = {2: [], 3: []}
        for s in FIGURE_SEEDS:
            f = phantom(d, preset, s)
            truth = read_truth(str(f.with_suffix(".truth.json")))
            phase = phase_of(column(f, "t_s"), truth.spans)
            for model, row in phase_rms_by_model(d, f, phase, float(truth.noise_n)).items():
                rows[model].append(row)
                pooled[model].append(row)
        print_phase_rows(preset, rows)
    print_phase_rows("all phantom", pooled)
    rows = {2: [], 3: []}
    for seed in FIGURE_MEASURED_LIKE:
        f, phase, sigma = measured_like_record(d, seed)
        for model, row in phase_rms_by_model(d, f, phase, sigma).items():
            rows[model].append(row)
    print_phase_rows("measured-like", rows)


#: part 5: the generator's options, each a form of measured insertion the export was not
#: developed on (MODEL.md §9 ranges: rates, noise, tears that run on, a stage that backs off)
ATLAS_FORMS: dict[str, dict[str, object]] = {
    "default": {}, "unload 0.5 mm": {"unload_mm": 0.5}, "stick-slip": {"stick_slip": True},
    "tear over 1 mm": {"release_mm": 1.0}, "50 Hz": {"rate_hz": 50.0},
    "200 Hz": {"rate_hz": 200.0}, "noise 50 mN": {"noise": 0.05},
    "no membrane": {"n_layers": 0}, "membranes x0.3": {"rupture_scale": 0.3}}
FORM_SEEDS = range(41, 51)


def atlas_by_form(d: Path) -> None:
    """Part 5 (``--forms``): the measured-like atlas of part 3 on held-out seeds 41-50 under
    each of ATLAS_FORMS: RMSE / peak, median and worst, Model II beside Model III."""
    from discrepancy_measured_like import make_trial
    print(f"5. atlas by form of the measured-like generator, seeds {FORM_SEEDS[0]}-"
          f"{FORM_SEEDS[-1]}: RMSE / peak, median (worst)")
    for form, kw in ATLAS_FORMS.items():
        rel: dict[int, list[float]] = {2: [], 3: []}
        for seed in FORM_SEEDS:
            tr, truth, sigma, _ = make_trial(seed, **kw)  # type: ignore[arg-type]
            a, b = d / "form_a.csv", d / "form_b.csv"
            write_record(a, tr.t_s, tr.depth_mm, tr.force_n)
            rng = np.random.default_rng(1000 + seed)
            write_record(b, tr.t_s, tr.depth_mm, truth + rng.normal(0.0, sigma, len(truth)))
            target = truth - truth[0]
            for model in (2, 3):
                cfg = identify(d, a, model, d / "form.json")
                rel[model].append(predicted_percent(d, b, cfg, target))
        print(f"   {form:15s} " + "  ".join(
            f"Model {'I' * m}: {np.median(rel[m]):.1f} % ({np.max(rel[m]):.1f} %)"
            for m in (2, 3)))


TRIAL_SEEDS = range(320, 340)


def atlas_other_trial(d: Path, seeds: range = TRIAL_SEEDS, rate_hz: float | None = None,
                      speed: float | None = None) -> None:
    """Part 6 (``--trials``): identify on a measured-like record, predict another trial of
    its condition with its true surface and with the config's, and (part 3's case, for
    comparison) the same record's truth under a fresh noise draw; RMSE / peak, median (worst).
    ``rate_hz``, ``speed`` (mm/s): the condition's, in place of the generator's draw."""
    from discrepancy_measured_like import make_trial, surface_of
    fixed = "" if rate_hz is None else f", {rate_hz:g} Hz, {speed:g} mm/s"
    print(f"6. atlas on another trial of the same condition (measured-like, seeds "
          f"{seeds[0]}-{seeds[-1]}{fixed}): RMSE / peak, median (worst)")
    cases = ("another trial, its true surface (--surface)", "another trial, the config surface",
             "the same record again (part 3)")
    rel: dict[tuple[int, str], list[float]] = {(m, c): [] for m in (2, 3) for c in cases}
    for seed in seeds:
        first, truth0, sigma, _ = make_trial(seed, rate_hz=rate_hz, speed=speed)
        other, truth1, _, _ = make_trial(seed, trial=1, rate_hz=rate_hz, speed=speed)
        a = d / "trial_a.csv"
        write_record(a, first.t_s, first.depth_mm, first.force_n)
        rng = np.random.default_rng(1000 + seed)
        again = (first.t_s, first.depth_mm, truth0 + rng.normal(0.0, sigma, len(truth0)))
        second = (other.t_s, other.depth_mm, other.force_n)
        targets = {cases[0]: (second, truth1,
                              ("--surface", str(surface_of(seed, 1, rate_hz, speed)))),
                   cases[1]: (second, truth1, ()), cases[2]: (again, truth0, ())}
        for model in (2, 3):
            cfg = identify(d, a, model, d / "trial.json")
            for case, (rec, truth, surface) in targets.items():
                b = d / "trial_b.csv"
                write_record(b, *rec)
                rel[(model, case)].append(predicted_percent(d, b, cfg, truth - truth[0],
                                                            *surface))
    for case in cases:
        print(f"   {case:45s}" + "  ".join(
            f"Model {'I' * m}: {np.median(rel[(m, case)]):.1f} % ({np.max(rel[(m, case)]):.1f} %)"
            for m in (2, 3)))


#: part 7: force and noise scaled together, as the same insertions would read on a smaller
#: force range and a quieter sensor (the second protocol of MODEL.md §9: 0.05-0.5 N, 0.3 mN)
FORCE_SCALES = (1.0, 0.1, 0.03, 0.01)


def innovation_by_scale(d: Path) -> None:
    """Part 7 (``--scaled``): part 4's measured-like figures with each record's force (and so
    its noise and tare) multiplied by each of FORCE_SCALES.  Model III's tuning has absolute
    numbers in it (R = (2 mN)^2, the front end's noise floor sqrt(R) and its 10 mN threshold
    floor, the nominal starts), so its figures are not the same at every scale."""
    print(f"7. part 4 with force and noise scaled together, measured-like seeds "
          f"{FIGURE_MEASURED_LIKE[0]}-{FIGURE_MEASURED_LIKE[-1]}")
    for scale in FORCE_SCALES:
        rows: dict[int, list[list[float]]] = {2: [], 3: []}
        for seed in FIGURE_MEASURED_LIKE:
            f, phase, sigma = measured_like_record(d, seed, scale)
            for model, row in phase_rms_by_model(d, f, phase, sigma).items():
                rows[model].append(row)
        print_phase_rows(f"x{scale:g}", rows)


def trials_condition(args: list[str]) -> tuple[range, float | None, float | None]:
    """``--trials``' seeds, rate (Hz) and speed (mm/s) from ``[HZ MM_S FIRST LAST]``; exits
    with status 2 and the reason on anything else."""
    if not args:
        return TRIAL_SEEDS, None, None
    try:
        if len(args) != 4:
            raise ValueError("four values")
        rate, speed, first, last = float(args[0]), float(args[1]), int(args[2]), int(args[3])
    except ValueError:
        rate = speed = math.nan
        first = last = 0
    if not (10.0 <= rate <= 2000.0 and 0.1 <= speed <= 20.0 and 0 <= first <= last):
        print(f"usage: config_loop_figures.py --trials [HZ MM_S FIRST LAST] (a rate of 10-2000 "
              f"Hz, a stage speed of 0.1-20 mm/s, seeds FIRST <= LAST, both >= 0); "
              f"got {' '.join(args)!r}", file=sys.stderr)
        raise SystemExit(2)
    return range(first, last + 1), rate, speed


def main(presets: list[str]) -> None:
    if not C.exists():
        raise SystemExit(f"{C} missing: make build")
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        if presets[:1] == ["--phases"]:
            # part 4 alone
            innovation_by_phase(d, presets[1:] or ["skin-on-muscle"])
            return
        if presets[:1] == ["--forms"]:
            atlas_by_form(d)     # part 5 alone
            return
        if presets[:1] == ["--trials"]:
            atlas_other_trial(d, *trials_condition(presets[1:]))     # part 6 alone
            return
        if presets[:1] == ["--scaled"]:
            innovation_by_scale(d)   # part 7 alone
            return
        workflow_only = presets[:1] == ["--workflow"]
        if workflow_only:
            presets = presets[1:] or ["skin-on-muscle"]
        preset = presets[0]
        tune = [str(phantom(d, preset, s)) for s in TUNING]
        subprocess.run([str(VENV / "nte-discrepancy"), *tune, "--out", str(d / "disc"),
                        "--no-figures"], check=True, capture_output=True)
        cfg = d / "disc" / "estimator_config.json"
        ratios = []
        print(f"1. innovation RMS (N), {preset}, held-out seeds {HELD_OUT[0]}-{HELD_OUT[-1]}, "
              f"as recorded: Model II default | --config (workflow on seeds 1-5)")
        for s in HELD_OUT:
            f = phantom(d, preset, s)
            run(str(f), "--model", "2", "--out", str(d / "def.csv"))
            run(str(f), "--config", str(cfg), "--out", str(d / "cfg.csv"))
            a, b = innovation_rms(d / "def.csv"), innovation_rms(d / "cfg.csv")
            ratios.append(b / a)
            print(f"   seed {s}: {a:.4f} | {b:.4f}  ({b / a:.2f}x)")
        print(f"   median ratio {np.median(ratios):.2f}, worst {np.max(ratios):.2f}")
        if workflow_only:
            return           # part 1 alone
        print("2. atlas: identify on seed k, predict seed k+1 (cyclic) from depth alone; "
              "RMSE / peak, median (worst); the export is the snapshot that replays its own "
              "record best, fitted to that record")
        medians: dict[int, list[float]] = {2: [], 3: []}
        for preset in presets:
            for label, seeds in (("tuning 1-5", TUNING), ("held-out 101-110", HELD_OUT)):
                for model in (2, 3):
                    res = atlas(d, preset, seeds, model)
                    rel = [100.0 * e / p for e, p in res]
                    if seeds is HELD_OUT:
                        medians[model].append(float(np.median(rel)))
                    print(f"   {preset:15s} {label:17s} Model {'I' * model:3s}: RMSE "
                          f"{np.median([e for e, _ in res]):.3f} N, peak "
                          f"{np.median([p for _, p in res]):.3f} N, RMSE/peak "
                          f"{np.median(rel):.0f} % ({np.max(rel):.0f} %)")
        if len(presets) > 1:
            for model in (2, 3):
                print(f"   held-out, median over the {len(presets)} tissues, Model "
                      f"{'I' * model}: {np.median(medians[model]):.0f} % (worst tissue "
                      f"{np.max(medians[model]):.0f} %)")
        measured_like_atlas(d, range(11, 22))
        innovation_by_phase(d, presets)
        atlas_other_trial(d)
        innovation_by_scale(d)


if __name__ == "__main__":
    args = sys.argv[1:] or ["skin-on-muscle"]
    from reference_py.sim.calibration import PRESETS as TISSUES
    if args[0] == "--trials":
        trials_condition(args[1:])     # its own values, checked before anything runs
    unknown = [a for a in (args[:1] if args[0] == "--trials" else args)
               if a not in ("--phases", "--forms", "--trials", "--workflow", "--scaled")
               and a not in TISSUES]
    if unknown:
        print(f"usage: config_loop_figures.py [--workflow | --phases | --forms | --trials | "
              f"--scaled] "
              f"[PRESET...] "
              f"(presets: {', '.join(TISSUES)}); not one: {unknown[0]}", file=sys.stderr)
        raise SystemExit(2)
    main(args)
