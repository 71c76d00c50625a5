"""nte-ref estimate --noise N (the sensor noise in N: the filters' r_n2 = N^2 and the verdict's
yardstick) and --start NAME=VALUE,... (starting values by name, on top of --preset's or
--config's): what they set, their precedence, and their refusals (exit 2, one line, nothing
written)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from reference_py.params import PARAM_NAMES, PRESETS
from reference_py.tools.cli import main

from estimate_run import estimate, refused

PAPER = dict(zip(PARAM_NAMES, PRESETS["paper-10mms"].params.as_list()))


@pytest.fixture(scope="module")
def sim(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("start_noise")
    out = d / "sim.csv"
    assert main(["simulate", "--preset", "paper-10mms", "--depth", "15", "--dwell", "0.3",
                 "--rate", "50", "--out", str(out)]) == 0
    return out


def config(path: Path, model: int = 2, **extra: object) -> Path:
    params = dict(PAPER)
    params.update(extra.pop("params", {}))  # type: ignore[arg-type]
    path.write_text(json.dumps({"schema": "nte-estimator-config/1", "model": model,
                                "params": params, **extra}))
    return path


def first_row(est: Path) -> dict[str, float]:
    """The estimate file's first sample: the filters' starting values (nothing updated yet)."""
    e = np.genfromtxt(est, delimiter=",", names=True, max_rows=1)
    return {n: float(e[n]) for n in e.dtype.names}


# -- --noise ----------------------------------------------------------------------------------

def test_noise_sets_the_measurement_noise_and_the_verdict(sim, tmp_path, capsys):
    rc, so, _ = estimate(capsys, sim, tmp_path / "n.csv", "--model", "2", "--noise", "0.01")
    assert rc == 0
    assert "x the noise (10 mN, given by --noise); gated " in so[-1]
    # the filters: as a configuration whose r_n2 is 0.01^2 (and no other change)
    cfg = config(tmp_path / "c.json", r_n2=0.01 * 0.01)
    assert estimate(capsys, sim, tmp_path / "c.csv", "--config", str(cfg))[0] == 0
    assert (tmp_path / "n.csv").read_bytes() == (tmp_path / "c.csv").read_bytes()
    assert estimate(capsys, sim, tmp_path / "d.csv", "--model", "2")[0] == 0
    assert (tmp_path / "d.csv").read_bytes() != (tmp_path / "n.csv").read_bytes()
    # --noise wins over the configuration's r_n2
    loud = config(tmp_path / "loud.json", r_n2=0.5)
    assert estimate(capsys, sim, tmp_path / "l.csv", "--config", str(loud), "--noise",
                    "0.01")[0] == 0
    assert (tmp_path / "l.csv").read_bytes() == (tmp_path / "n.csv").read_bytes()


@pytest.mark.parametrize("value,message", [
    ("5", "argument --noise: 5 N is not a plausible sensor noise: probably millinewtons, give "
          "it in N"),
    ("1", "argument --noise: 1 N is not a plausible sensor noise: probably millinewtons, give "
          "it in N"),
    ("0", "argument --noise: must be > 0 and < 1 N (got 0)"),
    ("-0.002", "argument --noise: must be > 0 and < 1 N (got -0.002)"),
    ("nan", "argument --noise: must be > 0 and < 1 N (got nan)"),
    ("inf", "argument --noise: must be > 0 and < 1 N (got inf)"),
    ("2mN", "argument --noise: not a number: '2mN'"),
])
def test_noise_refusals(sim, tmp_path, capsys, value, message):
    assert refused(capsys, sim, tmp_path / "e.csv", "--model", "2", "--noise", value) == [
        f"nte-ref estimate: error: {message} (see nte-ref estimate --help)"]


# -- --start ----------------------------------------------------------------------------------

def test_start_overrides_the_preset_then_the_config(sim, tmp_path, capsys):
    out = tmp_path / "e.csv"
    assert estimate(capsys, sim, out, "--model", "2", "--start", "sigma1=3.5, f1=0.07")[0] == 0
    row = first_row(out)
    assert row["sigma1"] == 3.5 and row["f1"] == 0.07 and row["sigma0"] == PAPER["sigma0"]
    # a preset, then --start
    assert estimate(capsys, sim, out, "--model", "2", "--preset", "paper-6mms", "--start",
                    "beta=0.03")[0] == 0
    row = first_row(out)
    assert row["beta"] == 0.03
    assert row["sigma1"] == PRESETS["paper-6mms"].params.sigma1
    # --config's params, then --start
    cfg = config(tmp_path / "c.json", params={"sigma1": 1.25, "sigma2": 5e-3})
    assert estimate(capsys, sim, out, "--config", str(cfg), "--start", "sigma2=6e-3")[0] == 0
    row = first_row(out)
    assert (row["sigma1"], row["sigma2"]) == (1.25, 6e-3)
    # the same start given through a configuration file gives the same bytes
    both = config(tmp_path / "b.json", params={"sigma1": 1.25, "sigma2": 6e-3})
    assert estimate(capsys, sim, tmp_path / "b.csv", "--config", str(both))[0] == 0
    assert (tmp_path / "b.csv").read_bytes() == out.read_bytes()


def test_start_sets_the_fixed_values_and_model3_strengths(sim, tmp_path, capsys):
    # Model II's fixed f2 and alpha come from the starting values too
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert estimate(capsys, sim, a, "--model", "2")[0] == 0
    assert estimate(capsys, sim, b, "--model", "2", "--start", "alpha=0.08")[0] == 0
    assert a.read_bytes() != b.read_bytes()
    out = tmp_path / "m3.csv"
    assert estimate(capsys, sim, out, "--model", "3", "--contact", "off", "--start",
                    "g_fast=0.3")[0] == 0
    row = first_row(out)
    assert row["g_fast"] == pytest.approx(0.3, rel=1e-12)
    assert row["g_slow"] == pytest.approx(0.25, rel=1e-12)      # the bank's nominal


@pytest.mark.parametrize("flags,message", [
    (["--start", "sigma3=1"], "nte-ref estimate: error: argument --start: unknown parameter "
     "'sigma3' (valid: sigma0, sigma1, sigma2, f1, f2, alpha, beta, g_fast, g_slow) (see "
     "nte-ref estimate --help)"),
    (["--start", "f1"], "nte-ref estimate: error: argument --start: 'f1' is not NAME=VALUE "
     "(see nte-ref estimate --help)"),
    (["--start", "f1=0.1,f1=0.2"], "nte-ref estimate: error: argument --start: 'f1' given "
     "twice (see nte-ref estimate --help)"),
    (["--start", "f1=nan"], "nte-ref estimate: error: argument --start: f1=nan: not a finite "
     "number (see nte-ref estimate --help)"),
    (["--start", "beta=x"], "nte-ref estimate: error: argument --start: beta=x: not a finite "
     "number (see nte-ref estimate --help)"),
    (["--start", "sigma0=-1"], "nte-ref estimate: error: argument --start: sigma0=-1: must be "
     "> 0 and <= 1000 (see nte-ref estimate --help)"),
    (["--start", "f2=-2000"], "nte-ref estimate: error: argument --start: f2=-2000: must be "
     "within ±1000 (see nte-ref estimate --help)"),
    (["--start", "g_slow=1"], "nte-ref estimate: error: argument --start: g_slow=1: must be "
     "> 0 and < 1 (a fraction of the elastic force) (see nte-ref estimate --help)"),
    # combinations: the bank's own messages
    (["--start", "f1=0.01,f2=-0.02"], "nte-ref: error: nominal f1 must exceed -f2 (g(0) = "
     "f1 + f2 must be positive)"),
    (["--model", "3", "--contact", "off", "--start", "g_fast=0.8"], "nte-ref: error: nominal "
     "relaxation strengths g_fast, g_slow must be > 0 with a sum < 1"),
    (["--start", "g_fast=0.1"], "nte-ref: error: argument --start: g_fast is a relaxation "
     "strength of Model III (not of Model II)"),
])
def test_start_refusals(sim, tmp_path, capsys, flags, message):
    model = [] if "--model" in flags else ["--model", "2"]
    assert refused(capsys, sim, tmp_path / "e.csv", *model, *flags) == [message]
