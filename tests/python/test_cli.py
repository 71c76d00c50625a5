"""nte-ref from the outside: simulate, estimate, plots, and every bad-input message."""
import csv
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
    ("nan", GOOD_HEADER + "\n0,0,0\n0.005,0.05,nan\n", "bad.csv:3: column 'force_n': not finite"),
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
                        "--model", "3", "--out", str(tmp_path / "o.csv")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "invalid choice" in r.stderr
