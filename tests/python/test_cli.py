"""nte-ref from the outside: simulate, estimate, plots, and every bad-input message."""
import csv
import math
import os
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from reference_py.tools.cli import main

GOOD_HEADER = "t_s,depth_mm,force_n"


@pytest.fixture(scope="module")
def sim_csv(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "sim.csv"
    assert main(["simulate", "--preset", "paper-10mms", "--depth", "20", "--dwell", "0.5",
                 "--seed", "4", "--out", str(out)]) == 0
    return out


def test_simulate_columns_and_noise(sim_csv):
    rows = list(csv.DictReader(open(sim_csv)))
    assert list(rows[0]) == ["t_s", "depth_mm", "velocity_mm_s", "force_n", "force_true_n"]
    noise = np.array([float(r["force_n"]) - float(r["force_true_n"]) for r in rows])
    assert 0.0015 < noise.std() < 0.0025
    assert max(float(r["depth_mm"]) for r in rows) == pytest.approx(20.0)


@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_estimate_writes_rows_and_plot(sim_csv, tmp_path, precision, capsys):
    out, png = tmp_path / "est.csv", tmp_path / "est.png"
    assert main(["estimate", str(sim_csv), "--model", "2", "--precision", precision,
                 "--out", str(out), "--plot", str(png)]) == 0
    rows = list(csv.DictReader(open(out)))
    assert list(rows[0]) == ["t_s", "force_hat_n", "z", "innovation_n", "status", "sigma0",
                             "sigma0_sd", "sigma1", "sigma1_sd", "sigma2", "sigma2_sd", "f1",
                             "f1_sd", "beta", "beta_sd"]
    assert len(rows) == len(list(csv.DictReader(open(sim_csv))))
    vals = np.array([[float(v) for v in r.values()] for r in rows])
    assert np.all(np.isfinite(vals))
    assert png.stat().st_size > 20000
    assert "sigma0" in capsys.readouterr().out


def test_model1_columns(sim_csv, tmp_path):
    out = tmp_path / "m1.csv"
    assert main(["estimate", str(sim_csv), "--model", "1", "--schedule", "rotate",
                 "--profile", "paper", "--init-seed", "3", "--out", str(out)]) == 0
    header = open(out).readline().strip().split(",")
    assert header[5::2] == ["sigma0", "sigma1", "sigma2", "f1", "f2", "alpha"]


def test_velocity_is_derived_when_absent(sim_csv, tmp_path):
    from reference_py.tools.csvio import read_trial
    src = list(csv.DictReader(open(sim_csv)))
    p = tmp_path / "novel.csv"
    p.write_text(GOOD_HEADER + "\n" + "\n".join(
        f"{r['t_s']},{r['depth_mm']},{r['force_n']}" for r in src) + "\n")
    trial = read_trial(p)
    assert not trial.velocity_given
    given = np.array([float(r["velocity_mm_s"]) for r in src])
    cruise = np.abs(given - 10.0) < 1e-9
    np.testing.assert_allclose(trial.velocity_mm_s[cruise][2:-2], 10.0, atol=1e-6)


def _write(tmp_path, text, name="bad.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


BAD_CASES = [
    ("missing column", "t_s,depth_mm\n0,0\n", "bad.csv:1: column 'force_n': missing"),
    ("non-numeric", GOOD_HEADER + "\n0,0,0\n0.005,abc,0.1\n",
     "bad.csv:3: column 'depth_mm': not a number: 'abc'"),
    ("non-monotonic", GOOD_HEADER + "\n0,0,0\n0.01,0.1,0\n0.005,0.2,0\n",
     "bad.csv:4: column 't_s': time 0.005 does not increase"),
    ("nan", GOOD_HEADER + "\n0,0,0\n0.005,0.05,inf\n", "bad.csv:3: column 'force_n': not finite"),
    ("ragged", GOOD_HEADER + "\n0,0,0\n0.005,0.05\n", "bad.csv:3: expected 3 cells, found 2"),
    ("empty", "", "bad.csv:1: no header line"),
]


@pytest.mark.parametrize("label,text,message", BAD_CASES, ids=[c[0] for c in BAD_CASES])
def test_bad_csv_is_refused_with_file_line_column(tmp_path, capsys, label, text, message):
    bad = _write(tmp_path, text)
    out = tmp_path / "never.csv"
    assert main(["estimate", str(bad), "--model", "2", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err, err
    assert not out.exists()
    assert not list(tmp_path.glob(".never.csv*"))   # no temporary file left behind


def test_unknown_preset(tmp_path, capsys):
    assert main(["simulate", "--preset", "nope", "--depth", "10", "--dwell", "1",
                 "--out", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err
    assert "unknown preset 'nope'" in err and "paper-10mms" in err


def test_missing_file(tmp_path, capsys):
    assert main(["estimate", str(tmp_path / "absent.csv"), "--model", "2",
                 "--out", str(tmp_path / "o.csv")]) == 2
    assert "absent.csv: cannot read" in capsys.readouterr().err


def test_console_script_and_module_entry_points(sim_csv, tmp_path):
    bindir = Path(sys.executable).parent
    r = subprocess.run([str(bindir / "nte-ref"), "--help"], capture_output=True, text=True)
    assert r.returncode == 0 and "simulate" in r.stdout and "estimate" in r.stdout
    r = subprocess.run([sys.executable, "-m", "reference_py", "estimate", "--help"],
                       capture_output=True, text=True)
    assert r.returncode == 0 and "--init-factor" in r.stdout
    r = subprocess.run([sys.executable, "-m", "reference_py", "estimate", str(sim_csv),
                        "--model", "4", "--out", str(tmp_path / "o.csv")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "invalid choice" in r.stderr


# -- every flag bounded: one line, exit status 2, nothing written ----------------------------

SIMULATE = ["simulate", "--preset", "paper-10mms", "--depth", "5", "--dwell", "0"]
FLAG_CASES = [
    (SIMULATE + ["--rate", "1e7"], "nte-ref simulate: error: argument --rate: must be >= 1 and "
                                   "<= 20000 Hz (got 1e7) (see nte-ref simulate --help)"),
    (SIMULATE + ["--depth", "1e6"], "argument --depth: must be > 0 and <= 500 mm (got 1e6)"),
    (SIMULATE + ["--speed", "0"], "argument --speed: must be > 0 and <= 200 mm/s (got 0)"),
    (SIMULATE + ["--rate", "nan"], "argument --rate: must be >= 1 and <= 20000 Hz (got nan)"),
    (SIMULATE + ["--noise", "-1"], "argument --noise: must be >= 0 and <= 50 N (got -1)"),
    (SIMULATE + ["--seed", "1.5"], "argument --seed: not an integer: '1.5'"),
    (SIMULATE + ["--cycles", "0"], "argument --cycles: must be >= 1 and <= 1000 (got 0)"),
    (SIMULATE + ["--rest", "-0.5"], "argument --rest: must be >= 0 and <= 3600 s (got -0.5)"),
    (SIMULATE + ["--dwell", "3600", "--rate", "20000"],
     "nte-ref: error: --rate 20000 Hz over 3601 s is 7.2e+07 samples, more than the "
     "10,000,000 allowed; lower --rate, --dwell, --rest or --cycles"),
    (["bench", "--samples", "0"], "nte-ref bench: error: argument --samples: must be >= 1 and "
                                  "<= 10000000 (got 0)"),
    (["evaluate", "--seeds", "0"], "argument --seeds: must be >= 1 and <= 100000 (got 0)"),
    (["evaluate", "--factor", "0.5"], "argument --factor: must be >= 1 and <= 100 (got 0.5)"),
    (["estimate", "x.csv", "--model", "2", "--init-factor", "inf"],
     "argument --init-factor: must be >= 1 and <= 100 (got inf)"),
    (["estimate", "x.csv", "--model", "2", "--init-seed", "-1"],
     "argument --init-seed: must be >= 0 and <= 9223372036854775807 (got -1)"),
    (["estimate", "x.csv", "--model", "3", "--presliding-mm", "0"],
     "argument --presliding-mm: must be > 0 and <= 1000 mm (got 0)"),
    (["estimate", "x.csv", "--model", "3", "--tau-fast", "nan"],
     "argument --tau-fast: must be > 0 and <= 3600 s (got nan)"),
    (["estimate", "x.csv", "--model", "3", "--tau-slow", "1e9"],
     "argument --tau-slow: must be > 0 and <= 3600 s (got 1e9)"),
]


@pytest.mark.parametrize("argv,message", FLAG_CASES, ids=[" ".join(c[0][-2:]) for c in FLAG_CASES])
def test_numeric_flags_are_bounded(tmp_path, capsys, argv, message):
    out = tmp_path / "x.csv"
    argv = list(argv) + (["--out", str(out)] if argv[0] in ("simulate", "estimate") else [])
    try:
        rc = main(argv)
    except SystemExit as exc:           # argparse's refusal: the console script's status
        rc = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and message in err[0], err
    assert "Traceback" not in err[0]
    assert list(tmp_path.iterdir()) == []


def test_estimate_into_a_directory_is_refused(sim_csv, tmp_path, capsys):
    assert main(["estimate", str(sim_csv), "--model", "2", "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err.strip() == (f"nte-ref: error: --out {tmp_path}: is a "
                                               f"directory, not a regular file; refusing to "
                                               f"replace it")


@pytest.mark.parametrize("cmd", ["simulate", "estimate", "evaluate", "bench"])
def test_help_lists_every_flag_and_its_default(cmd, capsys):
    from reference_py.tools.cli import build_parser
    with pytest.raises(SystemExit) as e:
        build_parser().parse_args([cmd, "--help"])
    assert e.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    sub = build_parser()._subparsers._group_actions[0].choices[cmd]   # type: ignore[union-attr]
    for act in sub._actions:
        if not act.option_strings or act.dest == "help":
            continue
        assert act.option_strings[0] in text, act.dest
        if act.default is not None and act.default is not False:
            assert f"(default: {act.default})" in text, act.dest
        else:
            assert act.required or act.const is not None or "default" in (act.help or ""), \
                act.dest


# -- the C programs: --help with every flag and default, one-line refusals, exit status 2 ----

C_BIN = Path(__file__).resolve().parents[2] / "build" / "host" / "bin"


def _c(name: str, *args: str) -> subprocess.CompletedProcess:
    exe = C_BIN / name
    if not exe.exists():
        pytest.skip(f"{exe} missing: build the firmware first (make build)")
    return subprocess.run([str(exe), *args], capture_output=True, text=True, timeout=60)


@pytest.mark.parametrize("prog", ["nte-run", "nte-run-double"])
def test_c_run_help_and_refusals(prog, tmp_path):
    for flag in ("-h", "--help"):
        r = _c(prog, flag)
        assert r.returncode == 0 and r.stderr == ""
        for text in ("--model 1|2|3", "--estimator bank|robust  (default: bank)",
                     "(default: paper-10mms)", "--profile default|paper  tuning (default: "
                     "default)", "(default: 0)", "1..100 (default: 5)", "(default: all)",
                     "--out EST.csv", "-h, --help"):
            assert text in r.stdout, (flag, text)
    out = tmp_path / "o.csv"
    cases = [
        (["x.csv", "-x"], "unrecognized arguments: -x"),
        (["x.csv", "--model", "4", "--out", str(out)], "argument --model: invalid choice: '4'"),
        (["x.csv", "--model", "3", "--out", str(out), "--presliding-mm", "0"],
         "argument --presliding-mm: must be > 0 and <= 1000 mm (got 0)"),
        (["x.csv", "--model", "3", "--out", str(out), "--tau-fast", "nan"],
         "argument --tau-fast: must be > 0 and <= 3600 s (got nan)"),
        (["x.csv", "--model", "3", "--out", str(out), "--tau-slow", "1e9"],
         "argument --tau-slow: must be > 0 and <= 3600 s (got 1e9)"),
        (["x.csv", "--model", "3", "--out", str(out), "--tau-slow", "x"],
         "argument --tau-slow: not a number: 'x'"),
        (["x.csv", "--model", "3", "--out", str(out), "--relax-branches", "3"],
         "argument --relax-branches: invalid choice: '3'"),
        (["x.csv", "--model", "2", "--out", str(out), "--init-factor", "0.5"],
         "argument --init-factor: must be >= 1 and <= 100 (got 0.5)"),
        (["x.csv", "--model", "2", "--out", str(out), "--init-factor", "nan"],
         "argument --init-factor: must be >= 1 and <= 100 (got nan)"),
        (["x.csv", "--model", "2", "--out", str(out), "--init-seed", "-1"],
         "argument --init-seed: must be >= 0 and <= 9223372036854775807 (got -1)"),
        (["x.csv", "--model", "2"], "the following arguments are required: --out"),
        (["a.csv", "b.csv"], "unrecognized arguments: b.csv (one input file)"),
    ]
    for argv, message in cases:
        r = _c(prog, *argv)
        assert r.returncode == 2, (argv, r.stderr)
        assert r.stderr.splitlines() == [f"{prog}: error: {message} (see {prog} --help)"]
        assert r.stdout == "" and not out.exists()


@pytest.mark.parametrize("prog", ["nte-bench-c", "nte-bench-c-double"])
def test_c_bench_help_and_refusal(prog):
    r = _c(prog, "--help")
    assert r.returncode == 0 and r.stdout.startswith(f"usage: {prog} [-h]")
    assert "No flags" in r.stdout
    r = _c(prog, "--samples", "5")
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.splitlines() == [f"{prog}: error: unrecognized arguments: --samples "
                                     f"(see {prog} --help)"]


@pytest.mark.parametrize("flags,message", [
    (["--stroke", "1e9"], "stroke_mm (--stroke) must be <= 500 (got 1000000000.0)"),
    (["--dwell", "1e9"], "dwell_s (--dwell) must be <= 3600 (got 1000000000.0)"),
    (["--gaps", "100000000"], "gaps (--gaps) must be <= 1000 (got 100000000)"),
    (["--rate", "5000", "--dwell", "3000"], "the record would hold 1.51e+07 samples, more than "
                                            "10,000,000: lower --rate, --stroke or --dwell")])
def test_phantom_sizes_are_bounded(tmp_path, capsys, flags, message):
    out = tmp_path / "p.csv"
    assert main(["phantom", "--out", str(out), *flags]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [f"nte-ref: error: {message}"]
    assert list(tmp_path.iterdir()) == []


def test_c_run_writes_by_the_safe_writer_rules(sim_csv, tmp_path):
    """nte-run refuses what nte-ref refuses (device, directory, missing parent, under a file),
    writes through a symlink, keeps a replaced file's mode, and ends with the counts line and
    the verdict."""
    sub = tmp_path / "sub"
    sub.mkdir()
    cases = [("/dev/null", "--out /dev/null: is a character device, not a regular file; "
                           "refusing to replace it"),
             (str(sub), f"--out {sub}: is a directory, not a regular file; refusing to "
                        f"replace it"),
             ("/nonexistent/x.csv", "--out /nonexistent/x.csv: directory /nonexistent does "
                                    "not exist (it is not created)"),
             (f"{sim_csv}/x.csv", f"--out {sim_csv}/x.csv: {sim_csv} is not a directory")]
    for out, message in cases:
        r = _c("nte-run", str(sim_csv), "--model", "2", "--out", out)
        assert r.returncode == 2 and r.stderr.splitlines() == [f"nte-run: error: {message}"]
    assert os.path.exists("/dev/null") and list(sub.iterdir()) == []
    real, link = tmp_path / "real.csv", tmp_path / "link.csv"
    real.write_text("old\n")
    os.chmod(real, 0o640)
    link.symlink_to("real.csv")                    # relative to the link's directory
    r = _c("nte-run", str(sim_csv), "--model", "2", "--out", str(link))
    assert r.returncode == 0, r.stderr
    assert link.is_symlink() and real.read_text().startswith("t_s,force_hat_n")
    assert stat.S_IMODE(os.stat(real).st_mode) == 0o640
    n = len(real.read_text().splitlines()) - 1
    lines = r.stdout.splitlines()
    assert lines[-2:-1] == [f"samples: {n}; rejected 0, gated 0, clipped 0"]
    assert lines[-1].startswith("verdict: ")    # the closing verdict (test_run_verdict.py)


def test_estimate_exports_what_it_identified(sim_csv, tmp_path, capsys):
    """--export-config: the identified parameters start from the estimate file's row at the
    snapshot that replayed best (the "replay" block's t_s; export_select.py) and are fitted to
    the record (export_refine.py: a replay no worse than the snapshot's; every value within a
    factor 7^20 of its start; run again from the first strengths after a poor fit); the fixed ones at the preset; Model III's constants and
    strengths."""
    import json
    from reference_py.params import PARAM_NAMES, PRESETS
    out, js = tmp_path / "e.csv", tmp_path / "cfg.json"
    assert main(["estimate", str(sim_csv), "--model", "3", "--tau-slow", "4", "--out", str(out),
                 "--export-config", str(js)]) == 0
    cfg = json.loads(js.read_text())
    assert cfg["schema"] == "nte-estimator-config/1" and cfg["model"] == 3
    assert list(cfg["params"]) == list(PARAM_NAMES)
    header, *rows = out.read_text().splitlines()
    chosen = [dict(zip(header.split(","), r.split(","))) for r in rows
              if float(r.split(",", 1)[0]) == cfg["replay"]["t_s"]]
    assert len(chosen) == 1
    rep = cfg["replay"]
    # a fit that missed by more than 10 % of the peak ran again from the first strengths (this
    # record's first fit did), 20 passes at most each
    again = "run again from the record's first relaxation strengths" in capsys.readouterr().out
    assert again or rep["fit_rmse_n"] <= 0.10 * rep["peak_n"]
    assert rep["fit_rmse_n"] <= rep["rmse_n"] and 1 <= rep["fit_passes"] <= (40 if again else 20)
    moved = 0
    for name in ("sigma0", "sigma1", "sigma2", "f1", "beta", "g_fast", "g_slow"):
        got = cfg["params"].get(name, cfg["model3"]["strengths"].get(name))
        start = float(chosen[0][name])
        assert got > 0 and abs(math.log(got / start)) <= 20 * math.log(7.0), name
        moved += got != start
    assert moved == 0 if rep["fit_rmse_n"] == rep["rmse_n"] else moved > 0
    assert cfg["params"]["alpha"] == PRESETS["paper-10mms"].params.alpha
    assert cfg["params_sd"]["f2"] == 0.0
    g = cfg["model3"]["strengths"]
    assert 0 < g["g_fast"] < 1 and 0 < g["g_slow"] < 1 and g["g_fast"] + g["g_slow"] < 1
    assert cfg["model3"]["tau_slow_s"] == 4.0 and cfg["model3"]["relax_branches"] == 2
    # an unwritable place is refused before anything is written
    assert main(["estimate", str(sim_csv), "--model", "2", "--out", str(tmp_path / "o.csv"),
                 "--export-config", str(tmp_path / "no" / "c.json")]) == 2
    assert not (tmp_path / "o.csv").exists()


def test_estimate_config_flags_override_the_file(sim_csv, tmp_path, capsys):
    """--config: the file's model and Model III constants apply unless a flag says otherwise;
    --model may come from the file alone; --help shows the new flags and their defaults."""
    import json
    cfg = tmp_path / "cfg.json"
    cfg.write_text(json.dumps({
        "schema": "nte-estimator-config/1", "model": 3,
        "params": {"sigma0": 7.9e-3, "sigma1": 2.46, "sigma2": 4.14e-3, "f1": 5.59e-2,
                   "f2": -2.11e-2, "alpha": 5.25e-2, "beta": 2.55e-2},
        "r_n2": 1e-5, "effects": {"dwell_relaxation": {"tau_slow_s": 5.0}},
        "model3": {"presliding_mm": 1.5}}))
    out, js = tmp_path / "e.csv", tmp_path / "x.json"
    assert main(["estimate", str(sim_csv), "--config", str(cfg), "--tau-fast", "0.2",
                 "--out", str(out), "--export-config", str(js)]) == 0
    x = json.loads(js.read_text())
    assert x["model"] == 3 and x["r_n2"] == 1e-5
    m3 = x["model3"]
    assert (m3["tau_slow_s"], m3["tau_fast_s"]) == (5.0, 0.2)
    # the file's presliding_mm is delta's start; the export holds the identified delta, the
    # estimate's last one
    rows = out.read_text().splitlines()
    col = rows[0].split(",").index("delta")
    assert float(rows[1].split(",")[col]) == 1.5
    assert m3["presliding_mm"] == float(rows[-1].split(",")[col])
    assert main(["estimate", str(sim_csv), "--config", str(cfg), "--model", "2",
                 "--tau-slow", "2", "--out", str(out), "--export-config", str(js)]) == 0
    assert json.loads(js.read_text())["model"] == 2
    # neither --model nor --config: one line, exit 2
    capsys.readouterr()
    assert main(["estimate", str(sim_csv), "--out", str(out)]) == 2
    assert "--model (or --config)" in capsys.readouterr().err
    from reference_py.tools.cli import build_parser
    text = build_parser()._subparsers._group_actions[0].choices["estimate"].format_help()
    for flag in ("--config", "--predict-only", "--export-config"):
        assert flag in text
    assert "(default: 2.5, or --config's)" in " ".join(text.split())


def test_c_run_help_shows_the_config_flags():
    r = _c("nte-run", "--help")
    assert r.returncode == 0
    for flag in ("--config FILE.json", "--predict-only", "--export-config FILE.json"):
        assert flag in r.stdout
