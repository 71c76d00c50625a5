"""nte-ref: simulate needle insertions and run the force estimator on them (numpy reference).

    nte-ref simulate --preset NAME --depth MM --dwell S [--speed MM_S] [--rate HZ] [--noise N]
                     [--seed K] [--cycles C] [--accel MM_S2] --out FILE.csv
    nte-ref estimate FILE.csv --model 1|2|3 [--estimator bank|robust] [--preset NAME]
                     [--start NAME=VALUE,...] [--noise N] [--engine reference|c [--c-bin DIR]]
                     [--init-seed K] [--init-factor F] [--precision float64|float32]
                     [--schedule all|rotate] [--profile default|paper] [--presliding-mm MM]
                     [--tau-fast S] [--tau-slow S] [--relax-branches 1|2] [--no-relaxation] [--no-layers]
                     [--no-layer-sets]
                     [--no-direction-memory] --out EST.csv [--plot EST.png]
    nte-ref plot EST.csv [EST.csv ...] [--label TEXT ...] [--input IN.csv]
                 [--truth TRUTH.json | --truth-preset NAME] [--title TEXT] --out FIG.png
    nte-ref evaluate [--preset NAME] [--model 1|2] [--factor F] [--seeds N] [--precision P]
                     [--profile P] [--schedule S] [--estimator E] [--cycles C]
                     [--matrix | --robust-matrix]
    nte-ref bench [--samples N]
    nte-ref phantom [NAME|lab] --out FILE.csv [--seed K] [--rate HZ] [--speed MM_S,...] [...]
    nte-ref phantom --stats [--trials N] [--first-seed K]
    nte-ref fixedpoint [--model 1|2] [--seeds N] [--random N] [--sig-bits B]
    nte-ref plausible [--scenarios N] [--first-seed K] [--jobs J] [--engine c|reference] [...]

Exit status: 0 on success, 2 on bad input (the message on stderr names the file, line and column).
"""
from __future__ import annotations

import argparse
import math
import sys
from typing import TYPE_CHECKING, Sequence

import numpy as np

from . import fixedpoint, phantom, plausible
from .arguments import EXIT_BAD_INPUT, OneLineParser, add_unit_arguments, bounded, units_from
from .csvio import CsvError, left_out_note, read_trial, write_atomic
from .safe_write import Outputs
from ..config import EstimatorConfig
from ..params import PRESETS, get_preset

#: the envelope (EstimatorConfig's accepted ranges) bounds what the commands take
DEPTH_MAX_MM = EstimatorConfig.depth_max_mm
FORCE_MAX_N = EstimatorConfig.force_max_n

if TYPE_CHECKING:
    from .csvio import Trial
    from .estconfig import FileConfig
    from ..config import ContactConfig
    from ..params import Preset

MAX_SIMULATED_SAMPLES = 10_000_000    #: simulate refuses longer records (≈ 0.4 GB of CSV)


def sensor_noise(text: str) -> float:
    """An argparse type: the sensor's noise standard deviation in N, finite, > 0 and < 1 (a
    value of 1 or more is taken for millinewtons and refused saying so)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if math.isfinite(value) and value >= 1.0:
        raise argparse.ArgumentTypeError(f"{text} N is not a plausible sensor noise: probably "
                                         f"millinewtons, give it in N")
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f"must be > 0 and < 1 N (got {text})")
    return value


def start_values(text: str) -> dict[str, float]:
    """An argparse type: ``NAME=VALUE[,NAME=VALUE...]``, starting (nominal) values of the
    parameters by name (params.PARAM_NAMES and RELAX_NAMES: Model III's delta starts at
    --presliding-mm), each finite and in the range a configuration file
    allows it (estconfig.py: the physical ones positive but f2, |x| <= 1000; the strengths in
    (0, 1)).  Combinations (g(0) = f1 + f2 > 0, strengths summing below 1) are the bank's to
    refuse, with its own message."""
    from ..params import PARAM_NAMES, RELAX_NAMES
    from .estconfig import PARAM_MAX, POSITIVE_PARAMS
    names = PARAM_NAMES + RELAX_NAMES
    out: dict[str, float] = {}
    for item in text.split(","):
        name, eq, value = (part.strip() for part in item.partition("="))
        if not eq or not name:
            raise argparse.ArgumentTypeError(f"{item.strip()!r} is not NAME=VALUE")
        if name not in names:
            raise argparse.ArgumentTypeError(f"unknown parameter {name!r} (valid: "
                                             f"{', '.join(names)})")
        if name in out:
            raise argparse.ArgumentTypeError(f"{name!r} given twice")
        try:
            x = float(value)
        except ValueError:
            x = math.nan
        if not math.isfinite(x):
            raise argparse.ArgumentTypeError(f"{name}={value}: not a finite number")
        if name in RELAX_NAMES:
            ok, rule = 0.0 < x < 1.0, "must be > 0 and < 1 (a fraction of the elastic force)"
        elif name in POSITIVE_PARAMS:
            ok, rule = 0.0 < x <= PARAM_MAX, f"must be > 0 and <= {PARAM_MAX:g}"
        else:
            ok, rule = abs(x) <= PARAM_MAX, f"must be within ±{PARAM_MAX:g}"
        if not ok:
            raise argparse.ArgumentTypeError(f"{name}={value}: {rule}")
        out[name] = x
    return out


_Parser = OneLineParser


def build_parser() -> argparse.ArgumentParser:
    presets = ", ".join(PRESETS)
    p = _Parser(prog="nte-ref", description=__doc__.split("\n\n")[0],
                epilog=f"presets: {presets}\nunits: depth mm, speed mm/s, time s, force N")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    s = sub.add_parser("simulate", help="simulate an insertion-dwell-retraction to CSV",
                       description="Simulate the force of a preset tissue along an LSPB "
                                   "insertion, dwell and retraction; write "
                                   "t_s,depth_mm,velocity_mm_s,force_n,force_true_n.")
    s.add_argument("--preset", required=True, help=f"parameter set, one of {presets}")
    s.add_argument("--depth", type=bounded(0.0, DEPTH_MAX_MM, " mm", lo_open=True), required=True,
                   metavar="MM", help="insertion depth, mm (no default)")
    s.add_argument("--dwell", type=bounded(0.0, 3600.0, " s"), required=True, metavar="S",
                   help="dwell at depth, s (no default)")
    s.add_argument("--speed", type=bounded(0.0, 200.0, " mm/s", lo_open=True), metavar="MM_S",
                   help="cruise speed, mm/s (default: the preset's)")
    s.add_argument("--accel", type=bounded(0.0, 1e5, " mm/s^2", lo_open=True), default=100.0,
                   metavar="MM_S2", help="blend acceleration, mm/s^2")
    s.add_argument("--rate", type=bounded(1.0, 20_000.0, " Hz"), default=200.0, metavar="HZ",
                   help="sample rate, Hz")
    s.add_argument("--noise", type=bounded(0.0, FORCE_MAX_N, " N"), default=2e-3, metavar="N",
                   help="white force noise standard deviation, N")
    s.add_argument("--seed", type=bounded(0, 2**32 - 1, integer=True), default=1, metavar="K",
                   help="noise seed")
    s.add_argument("--cycles", type=bounded(1, 1000, integer=True), default=1,
                   help="identical insertion cycles")
    s.add_argument("--rest", type=bounded(0.0, 3600.0, " s"), default=0.1, metavar="S",
                   help="rest at the surface before the first cycle and after each, s (the "
                        "robust estimator adopts an insertion's refinement 1 710 samples "
                        "after it: 8.55 s at 200 Hz)")
    s.add_argument("--out", required=True, metavar="FILE.csv", help="the CSV to write")

    e = sub.add_parser("estimate", help="run the estimator on a CSV",
                       description="Run the estimator over a CSV of t_s, depth_mm, force_n "
                                   "(velocity_mm_s optional, else central differences of "
                                   "depth); write one row per sample: t_s, force_hat_n, z, "
                                   "innovation_n, status, then every identified parameter and "
                                   "its standard deviation.")
    e.add_argument("csv", metavar="FILE.csv", help="the insertion to estimate from")
    e.add_argument("--model", type=int, choices=(1, 2, 3),
                   help="force model I, II or III (Model II with direction memory and "
                        "relaxation; no default: this flag or --config's model)")
    e.add_argument("--estimator", default="bank", choices=("bank", "robust"),
                   help="bank: the paper's three filters in switching mode; robust: the bank "
                        "plus a batch refinement after every insertion (converges from "
                        "factor-5 starts; adds a 'confidence' column)")
    e.add_argument("--preset",
                   help="starting (nominal) parameters; Model II also takes its fixed f2 and "
                        "alpha from it, Model I its beta0 (default: paper-10mms, or --config's "
                        "params)")
    e.add_argument("--start", type=start_values, metavar="NAME=VALUE,...",
                   help="starting (nominal) values of named parameters, on top of --preset's "
                        "or --config's: sigma0, sigma1, sigma2, f1, f2, alpha, beta, and Model "
                        "III's strengths g_fast, g_slow (default: none)")
    e.add_argument("--noise", type=sensor_noise, metavar="N",
                   help="the force sensor's noise standard deviation, N (0 < N < 1): the "
                        "filters' measurement noise (r_n2 = N^2, over --config's) and the "
                        "verdict's yardstick (default: r_n2 of the profile or --config; the "
                        "verdict measures the noise at rest before the stage moves)")
    e.add_argument("--init-seed", type=bounded(0, 2**63 - 1, integer=True), default=0,
                   metavar="K",
                   help="0: start at the preset; K > 0: multiply each identified parameter by "
                        "a factor drawn log-uniformly from [1/F, F] with seed K")
    e.add_argument("--init-factor", type=bounded(1.0, 100.0), default=5.0, metavar="F",
                   help="spread of the starting factors")
    e.add_argument("--precision", default="float64", choices=("float64", "float32"),
                   help="arithmetic of the filters")
    e.add_argument("--schedule", default="all", choices=("all", "rotate"),
                   help="all: three filters every sample; rotate: one filter per sample")
    e.add_argument("--profile", default="default", choices=("default", "paper"),
                   help="tuning: ours, or the paper's Table I mapped to scaled parameters")
    m3 = e.add_argument_group("Model III (ignored by Models I and II)")
    # no argparse defaults here: a flag given overrides --config, one not given does not
    m3.add_argument("--presliding-mm", type=bounded(0.0, 1000.0, " mm", lo_open=True),
                    metavar="MM",
                    help="turn-over length of the direction state, mm (default: 2.5, or "
                         "--config's)")
    m3.add_argument("--tau-fast", type=bounded(0.0, 3600.0, " s", lo_open=True),
                    metavar="S", help="time constant of the fast relaxation branch, s "
                                      "(default: 0.3, or --config's)")
    m3.add_argument("--tau-slow", type=bounded(0.0, 3600.0, " s", lo_open=True),
                    metavar="S", help="time constant of the slow relaxation branch, s "
                                      "(default: 3, or --config's)")
    m3.add_argument("--relax-branches", type=int, choices=(1, 2),
                    help="relaxation branches: 1 fast only, 2 fast and slow (default: 2, or "
                         "--config's)")
    m3.add_argument("--no-relaxation", action="store_true",
                    help="no relaxation branches (default: on)")
    m3.add_argument("--no-direction-memory", action="store_true",
                    help="tanh(v/eps) instead of the direction state (default: on)")
    m3.add_argument("--no-layers", action="store_true",
                    help="no layer index (default: on: a rupture detector on the "
                         "innovations; adds the column layer)")
    m3.add_argument("--no-layer-sets", action="store_true",
                    help="--export-config writes one parameter set, no layer sets "
                         "(default: a set at each tear of the first insertion)")
    add_unit_arguments(e)
    e.add_argument("--contact", choices=("on", "off"), default=None,
                   help="the surface and tare front end (default: on for --model 3 unless "
                        "--predict-only, off for Models I and II): the depth column is "
                        "the stage position, the needle starts in the air; the tare is learned "
                        "there, contact is found from the force onset and the bank gets the "
                        "depth below the surface found; adds the columns surface_mm, tare_n, "
                        "contact (0 air, 1 tissue)")
    e.add_argument("--surface", type=bounded(-DEPTH_MAX_MM, DEPTH_MAX_MM, " mm"), metavar="MM",
                   help=f"a known surface (stage position, -{DEPTH_MAX_MM:g}..{DEPTH_MAX_MM:g} "
                        "mm) instead of finding it; "
                        "turns the front end on (default: none, found from the force)")
    e.add_argument("--out", required=True, metavar="EST.csv", help="the estimates to write")
    e.add_argument("--plot", metavar="EST.png", help="also draw force and parameters (PNG; default: no plot)")
    e.add_argument("--config", metavar="FILE.json",
                   help="read an estimator configuration (schema nte-estimator-config/1: the "
                        "discrepancy workflow's estimator_config.json or an --export-config "
                        "file): model, nominal parameters, r_n2, Model III's constants, the "
                        "surface; flags given override it (default: none)")
    e.add_argument("--predict-only", action="store_true",
                   help="with --config: the model alone on the depth, parameters held at the "
                        "config's, no filter update, the force column ignored; force_hat_n is "
                        "the prediction; the surface is --surface or the config's (default: off)")
    e.add_argument("--engine", choices=("reference", "c"), default="reference",
                   help="reference: this numpy reference; c: the C library's host program "
                        "(nte-run-double, or nte-run for float32, in --c-bin; make build "
                        "builds them) with the same flags: the same estimate file, byte for "
                        "byte, and the program's own output (reference_py/tools/c_engine.py)")
    e.add_argument("--c-bin", metavar="DIR",
                   help="with --engine c: where nte-run and nte-run-double are (default: "
                        "build/host/bin of the repository)")
    e.add_argument("--export-config", metavar="FILE.json",
                   help="also write what the estimator identified (the final parameters, "
                        "their sd, Model III's constants) as an estimator configuration, "
                        "schema nte-estimator-config/1 (default: none)")

    pt = sub.add_parser("plot", help="draw estimate files (nte-ref estimate's or nte-run's) "
                        "against time and depth, overlaid",
                        description="Draw one or more estimate files of one insertion (the "
                                    "reference's or nte-run's): force, prediction and error "
                                    "against time (dwell shaded, reversals marked) and, with "
                                    "--input, against depth; every parameter with its +-3 sigma "
                                    "band against time, the true value as a line with a truth. "
                                    "Prints the innovation RMS per phase of every file.")
    pt.add_argument("estimates", nargs="+", metavar="EST.csv",
                    help="estimate files (t_s, force_hat_n, innovation_n, status, NAME, "
                         "NAME_sd, ...), one colour each")
    pt.add_argument("--label", action="append", metavar="TEXT",
                    help="legend name of each file, once per file in order (default: the "
                         "model, from the parameter columns)")
    pt.add_argument("--input", metavar="IN.csv",
                    help="the insertion the estimates were made from: adds the measured force, "
                         "the true force (its force_true_n column), the depth panels and the "
                         "phases from its motion (default: none)")
    truth = pt.add_mutually_exclusive_group()
    truth.add_argument("--truth", metavar="TRUTH.json",
                       help="a phantom's truth (nte-ref phantom's FILE.truth.json: phases, "
                            "ruptures, the Maxwell shares, the noise) or an estimator "
                            "configuration (its params as lines) (default: none)")
    truth.add_argument("--truth-preset", metavar="NAME",
                       help=f"the true parameters of a simulated record, one of {presets} "
                            f"(default: none)")
    pt.add_argument("--title", default="", metavar="TEXT", help="figure title (default: none)")
    pt.add_argument("--out", required=True, metavar="FIG.png",
                    help="the figure to write (format from the suffix: .png, .pdf or .svg)")
    add_unit_arguments(pt)

    v = sub.add_parser("evaluate", help="estimation quality over many seeds (printed table)",
                       description="Simulate the quality scenario (LSPB to 50 mm, 1 s dwell, "
                                   "200 Hz, 2 mN noise) for N seeds and print the metrics.")
    v.add_argument("--preset", default="paper-10mms", help="the true and nominal parameters")
    v.add_argument("--model", type=int, choices=(1, 2), default=2, help="force model")
    v.add_argument("--factor", type=bounded(1.0, 100.0), default=1.25,
                   help="start within this factor")
    v.add_argument("--seeds", type=bounded(1, 100_000, integer=True), default=100,
                   help="number of seeds (scenarios)")
    v.add_argument("--precision", default="float64", choices=("float64", "float32"),
                   help="arithmetic of the filters")
    v.add_argument("--profile", default="default", choices=("default", "paper"),
                   help="tuning profile")
    v.add_argument("--schedule", default="all", choices=("all", "rotate"),
                   help="filters per sample")
    v.add_argument("--cycles", type=bounded(1, 100, integer=True), default=1,
                   help="insertion cycles per scenario (more than one: they rest at the "
                        "surface between them until the robust estimator's refinement is "
                        "adopted, 8.6 s at 200 Hz, whichever the estimator)")
    v.add_argument("--estimator", default="bank", choices=("bank", "robust"),
                   help="the estimator")
    v.add_argument("--matrix", action="store_true",
                   help="run the README's standard set of bank cases instead (about 2 minutes)")
    v.add_argument("--robust-matrix", action="store_true",
                   help="run the README's robust-estimator cases (three cycles; about 10 minutes)")

    b = sub.add_parser("bench", help="samples per second of the reference (and of filterpy)")
    b.add_argument("--samples", type=bounded(1, 10_000_000, integer=True), default=10000,
                   help="samples per timed run")

    ph = sub.add_parser("phantom", help="a measured-like insertion (layers, relaxation, "
                        "pre-sliding, sensor) to CSV and its truth to JSON",
                        description="Simulate the realistic phantom (reference_py/tools/"
                                    "PHANTOM.md); write t_s,depth_mm,velocity_mm_s,force_n,"
                                    "force_true_n and FILE.truth.json.")
    phantom.add_arguments(ph)

    fx = sub.add_parser("fixedpoint", help="range and Q-format of every variable of the bank",
                        description=fixedpoint.__doc__.split("\n\n")[0],
                        epilog=fixedpoint.__doc__.split("\n\n", 1)[1],
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    fixedpoint.add_arguments(fx)

    pl = sub.add_parser("plausible", help="random plausible scenarios: outputs finite and "
                        "within 10x the input's force",
                        description=plausible.__doc__.split("\n\n")[0],
                        epilog=plausible.__doc__.split("\n\n", 1)[1],
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    plausible.add_arguments(pl)
    return p


def subcommand(name: str) -> argparse.ArgumentParser:
    """The parser of one nte-ref command (its options: ``._actions``)."""
    sub = next(act for act in build_parser()._actions
               if isinstance(act, argparse._SubParsersAction))
    return sub.choices[name]


def _simulate(a: argparse.Namespace) -> int:
    from ..sim.simulate import simulate_force
    from ..sim.trajectory import TrajectorySpec, lspb_profile

    preset = get_preset(a.preset)
    speed = preset.speed_mm_s if a.speed is None else a.speed
    spec = TrajectorySpec(depth_mm=a.depth, speed_mm_s=speed,
                          accel_mm_s2=a.accel, dwell_s=a.dwell, rate_hz=a.rate, cycles=a.cycles,
                          rest_s=a.rest)
    # each cycle: in and out (blends included: at most depth/speed + speed/accel each way),
    # dwell and the rest after it; one rest before the first
    duration = a.cycles * (2.0 * (a.depth / speed + speed / a.accel) + a.dwell + a.rest) + a.rest
    if duration * a.rate > MAX_SIMULATED_SAMPLES:
        raise ValueError(f"--rate {a.rate:g} Hz over {duration:.4g} s is {duration * a.rate:.3g} "
                         f"samples, more than the {MAX_SIMULATED_SAMPLES:,} allowed; lower "
                         f"--rate, --dwell, --rest or --cycles")
    with Outputs() as outs:
        out = outs.add(a.out, "--out")
        t, l, vel, _ = lspb_profile(spec)
        truth = simulate_force(preset.params, t, l, vel)[0][0]
        noisy = truth + np.random.default_rng(a.seed).normal(0.0, a.noise, len(t))
        lines = ["t_s,depth_mm,velocity_mm_s,force_n,force_true_n"]
        lines += ["%.17g,%.17g,%.17g,%.17g,%.17g" % row for row in zip(t, l, vel, noisy, truth)]
        outs.write_lines(out, lines)
        outs.commit()
    print(f"wrote {len(t)} samples ({t[-1]:.2f} s) to {a.out}")
    return 0


def _contact_config(a: argparse.Namespace) -> "ContactConfig | None":
    """The front end asked for by --contact / --surface (None: off)."""
    from ..config import ContactConfig
    if a.surface is not None and a.contact == "off":
        raise ValueError("argument --surface: a known surface needs the front end (--contact on)")
    if a.contact != "on" and a.surface is None:
        return None
    return ContactConfig(enabled=True,
                         surface_mm=math.nan if a.surface is None else float(a.surface))


_Setup = "tuple[FileConfig | None, Preset, dict[str, float] | None, dict[str, object]]"


def _estimate_setup(a: argparse.Namespace) -> _Setup:
    """--config read and merged into the flags, --start on top of the starting values: the
    file's configuration, the preset that starts the filters, Model III's starting strengths
    and the configuration fields the flags set."""
    fc, preset = _file_config(a)
    preset, strengths = _started(a, preset, fc.strengths if fc is not None else {})
    return fc, preset, strengths, model3_overrides(a, fc)


def read_estimate_input(a: argparse.Namespace, cfg: "EstimatorConfig"
                        ) -> "tuple[Trial, ContactConfig | None]":
    """The insertion to estimate from, by the one reader (mapped, converted and checked against
    ``cfg``'s ranges), and the front end the flags ask for."""
    from dataclasses import replace
    from .csvio import Limits
    contact = _contact_config(a)
    limits = Limits.from_config(cfg)
    if contact is not None:
        # the stage position may lie anywhere in +-depth_max_mm (the air gap is no error)
        limits = replace(limits, depth_min_mm=-limits.depth_max_mm)
    return (read_trial(a.csv, units=units_from(a), limits=limits,
                       force_ignored=bool(getattr(a, "predict_only", False))), contact)


def _estimate_trial(a: argparse.Namespace) -> "Trial":
    """The insertion ``nte-ref estimate a`` would estimate from, as its reader reads it."""
    from .estimate import make_config
    fc, preset, strengths, overrides = _estimate_setup(a)
    cfg = make_config(preset, a.model, a.profile, a.schedule, overrides)
    return read_estimate_input(a, cfg)[0]


def _estimate(a: argparse.Namespace) -> int:
    from .estimate import estimate_csv_lines, make_config, run_estimate

    if a.engine == "c":
        from .c_engine import run_c_estimate
        return run_c_estimate(a, subcommand("estimate")._actions, _estimate_trial)
    fc, preset, strengths, overrides = _estimate_setup(a)
    with Outputs() as outs:
        out = outs.add(a.out, "--out")
        png = outs.add(a.plot, "--plot") if a.plot else None
        exported = outs.add(a.export_config, "--export-config") if a.export_config else None
        cfg = make_config(preset, a.model, a.profile, a.schedule, overrides)
        from dataclasses import replace
        trial, contact = read_estimate_input(a, cfg)
        note = left_out_note(trial)
        if note is not None:
            print(note, file=sys.stderr)
        force_read = trial.force_n        # the verdict measures the noise on the force read
        if a.predict_only:
            # the force is ignored: the bank is fed 0 N (never rejected, never learned)
            trial = replace(trial, force_n=np.zeros_like(trial.force_n))
        run = run_estimate(trial, preset, a.model, a.estimator, a.precision, a.profile,
                           a.schedule, a.init_seed, a.init_factor, progress=True,
                           overrides=overrides, contact=contact,
                           strengths=strengths)
        outs.write_lines(out, estimate_csv_lines(run))
        if png is not None:
            from .plotting import plot_estimate
            plot_estimate(run, png)
        choice = None
        if exported is not None:
            import json
            from .estimate import export_config
            from .export_select import choose_export
            choice = choose_export(run, run.config, preset, trial,
                                   layer_sets=not a.no_layer_sets)
            outs.write_text(exported, json.dumps(export_config(run, choice), indent=2) + "\n")
        outs.commit()
    from .estimate import final_estimates_lines
    from .verdict import verdict
    for line in final_estimates_lines(run):
        print(line)
    print(f"wrote {a.out}" + (f" and {a.plot}" if a.plot else "")
          + (f" and {a.export_config}" if a.export_config else ""))
    print(status_counts(run.status))
    if choice is not None:
        from .export_select import replay_summary, replay_warning
        print(replay_summary(choice))
        warning = replay_warning(choice)
        if warning is not None:
            print(warning, file=sys.stderr)
    judged = verdict(run.t_s, run.depth_mm, force_read, run.innovation_n, run.status,
                     predict_only=a.predict_only, noise_n=a.noise,
                     confidence=None if run.confidence is None else float(run.confidence[-1]))
    print(judged.line)
    if judged.warning is not None:
        print(judged.warning, file=sys.stderr)
    return 0


def _plot(a: argparse.Namespace) -> int:
    import os
    from pathlib import Path

    from . import plotting as pl

    if a.label is not None and len(a.label) != len(a.estimates):
        raise ValueError(f"argument --label: {len(a.label)} label(s) for {len(a.estimates)} "
                         f"estimate file(s): give one per file, in order, or none")
    fmt = Path(a.out).suffix.lstrip(".").lower()
    if fmt not in pl.FORMATS:
        raise ValueError(f"argument --out: {a.out}: the format is taken from the suffix: "
                         f"{', '.join('.' + f for f in pl.FORMATS)}")
    inputs = [*a.estimates, *(p for p in (a.input, a.truth) if p)]
    for path in inputs:
        if os.path.exists(path) and os.path.realpath(path) == os.path.realpath(a.out):
            raise ValueError(f"argument --out: {a.out} is also an input")
    with Outputs() as outs:
        out = outs.add(a.out, "--out")
        labels = a.label or [None] * len(a.estimates)
        series = [pl.read_estimate(p, lb) for p, lb in zip(a.estimates, labels)]
        trial = pl.read_input(a.input, units_from(a)) if a.input else None
        if trial is not None:
            for s in series:
                pl.check_same_record(s, trial)
        truth = pl.read_truth(a.truth) if a.truth else None
        if a.truth_preset:
            try:
                truth = pl.truth_from_preset(a.truth_preset)
            except (KeyError, ValueError) as exc:
                raise ValueError(f"argument --truth-preset: {exc}") from None
        if truth is not None:
            n, what = ((len(trial.t_s), a.input) if trial is not None
                       else (len(series[0].t_s), a.estimates[0]))
            pl.check_truth(truth, n, what)
        data = pl.FigureData(series, trial, truth)
        pl.save_figure(pl.build_figure(data, a.title), out)
        outs.commit()
    for line in pl.phase_summary(data):
        print(line)
    print(f"wrote {a.out} ({len(series)} estimate file(s)"
          + (f", input {a.input}" if a.input else "")
          + (f", truth {truth.source}" if truth is not None else "") + ")")
    return 0


def model3_overrides(a: argparse.Namespace, fc: "FileConfig | None" = None) -> dict[str, object]:
    """Model III's configuration fields (and r_n2, predict_only) from the configuration file
    ``fc`` and the estimate flags: the defaults, then the file, then the flags given."""
    out: dict[str, object] = {"presliding_mm": 2.5, "tau_fast_s": 0.3, "tau_slow_s": 3.0,
                              "relax_branches": 2, "relaxation": True, "direction_memory": True}
    if fc is not None:
        out.update(fc.m3)
        if fc.r_n2 is not None:
            out["r_n2"] = fc.r_n2
    if getattr(a, "noise", None) is not None:
        out["r_n2"] = a.noise * a.noise
    for key, flag in (("presliding_mm", a.presliding_mm), ("tau_fast_s", a.tau_fast),
                      ("tau_slow_s", a.tau_slow), ("relax_branches", a.relax_branches)):
        if flag is not None:
            out[key] = flag
    if a.no_relaxation:
        out["relaxation"] = False
    if a.no_direction_memory:
        out["direction_memory"] = False
    if getattr(a, "no_layers", False):
        out["layers"] = False
    if getattr(a, "predict_only", False):
        out["predict_only"] = True
    if a.model != 3:
        # the layer sets are Model III's, as the rest of the file's Model III fields
        out.pop("layer_sets", None)
    return out


def _file_config(a: argparse.Namespace) -> "tuple[FileConfig | None, Preset]":
    """--config read and merged into the flags (a.model, a.surface, a.contact); the preset
    whose values start the filters (the config's params unless --preset is given)."""
    from ..params import ParamSet, Preset
    from .estconfig import read_config_file
    fc = read_config_file(a.config) if a.config else None
    if a.predict_only and fc is None:
        raise ValueError("argument --predict-only: needs --config FILE (the parameters to "
                         "predict with)")
    if a.predict_only and a.estimator == "robust":
        raise ValueError("argument --predict-only: the bank only (the robust estimator's "
                         "refinement would move the parameters)")
    if a.model is None:
        if fc is None:
            raise ValueError("the following arguments are required: --model (or --config)")
        a.model = fc.model
    if fc is not None and a.surface is None and a.contact != "off":
        if fc.surface_mm is not None:
            a.surface = fc.surface_mm
        elif fc.surface_list:
            if a.predict_only:
                raise ValueError(f"{a.config}: key 'surface_mm': per-trial surfaces give no "
                                 f"surface to predict with; give --surface MM")
            a.contact = "on"
    if a.contact is None and a.surface is None and a.model == 3 and not a.predict_only:
        # the front end is part of Model III: a record as a rig writes it starts in the air
        a.contact = "on"
    if a.predict_only and a.contact == "on" and a.surface is None:
        raise ValueError("argument --predict-only: the front end finds the surface from the "
                         "force; give --surface MM")
    if a.preset is not None or fc is None:
        return fc, get_preset(a.preset or "paper-10mms")
    return fc, Preset(f"config {a.config}", ParamSet(*fc.params), 0.0, "from --config")


def _started(a: argparse.Namespace, preset: "Preset", strengths: dict[str, float]
             ) -> "tuple[Preset, dict[str, float] | None]":
    """The starting values with --start on top: the preset (--preset's or --config's params)
    and Model III's strengths (--config's or, for the ones --start gives, the bank's nominal
    for the other); None: the bank's own nominal strengths."""
    from dataclasses import replace
    from ..params import PARAM_NAMES, RELAX_NAMES, RELAX_NOMINAL
    start = a.start or {}
    given = [nm for nm in RELAX_NAMES if nm in start]
    if given and a.model != 3:
        raise ValueError(f"argument --start: {given[0]} is a relaxation strength of Model III "
                         f"(not of Model {'I' * a.model})")
    physical = {nm: v for nm, v in start.items() if nm in PARAM_NAMES}
    if physical:
        preset = replace(preset, name=f"{preset.name} with --start",
                         params=preset.params.with_values(**physical))
    if given:
        strengths = {nm: start.get(nm, strengths.get(nm, RELAX_NOMINAL[nm]))
                     for nm in RELAX_NAMES}
    return preset, strengths or None


def status_counts(status: np.ndarray) -> str:
    """The closing line of every estimating tool: samples rejected (invalid input, ignored),
    gated (an update skipped by the innovation gate) and clipped (a parameter at its bound)."""
    from ..bank import STATUS_CLIPPED, STATUS_GATED, STATUS_REJECTED
    st = np.asarray(status, dtype=np.uint32)
    n = {k: int(np.count_nonzero(st & np.uint32(bit)))
         for k, bit in (("rejected", STATUS_REJECTED), ("gated", STATUS_GATED),
                        ("clipped", STATUS_CLIPPED))}
    return (f"samples: {len(st)}; rejected {n['rejected']}, gated {n['gated']}, "
            f"clipped {n['clipped']}")


def _evaluate(a: argparse.Namespace) -> int:
    from dataclasses import replace

    from .quality import (ROBUST_MATRIX, STANDARD_MATRIX, QualityCase, format_summary,
                          run_quality)

    if a.matrix or a.robust_matrix:
        cases = [replace(c, seeds=a.seeds)
                 for c in (STANDARD_MATRIX if a.matrix else ROBUST_MATRIX)]
    else:
        cases = [QualityCase(a.preset, a.model, a.factor, a.precision, a.profile, a.schedule,
                             a.seeds, a.cycles, a.estimator)]
    print(format_summary([run_quality(c, progress=True) for c in cases]))
    return 0


def _bench(a: argparse.Namespace) -> int:
    from .bench import run_bench
    run_bench(a.samples)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    handlers = {"simulate": _simulate, "estimate": _estimate, "plot": _plot,
                "evaluate": _evaluate,
                "bench": _bench, "phantom": phantom.run,
                "fixedpoint": fixedpoint.run, "plausible": plausible.main_run}
    try:
        return handlers[args.command](args)
    except (CsvError, ValueError) as exc:
        print(f"nte-ref: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT


if __name__ == "__main__":
    sys.exit(main())
