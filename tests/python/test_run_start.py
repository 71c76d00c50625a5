"""nte-run's --start NAME=VALUE,... and --noise N mean what `nte-ref estimate`'s mean (issue 23).

--start sets the starting (nominal) values of named parameters on top of --preset's or
--config's; --noise N (newtons) sets the filters' measurement noise r_n2 = N^2 over the
profile's and --config's, and is the verdict's yardstick.  Both programs refuse the same
values with the same message (a noise of 1 N or more is taken for millinewtons; an unknown
name is named beside the valid ones; g(0) = f1 + f2 > 0 and the strengths' sum below 1 are the
estimator's to refuse), and, given the same flags, write the same bytes (float64 against
nte-run-double), the same exported configuration (but for its "source") and the same verdict.

Requires build/host/bin/nte-run{,-double} (``make build``).
"""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from run_records import NEEDS_C, PROGS, body, c_run, records_fixture, reference

pytestmark = NEEDS_C


def _model3(d: Path, _: dict[str, Path]) -> dict[str, Path]:
    """A Model III truth (model3_truth.py): to 30 mm at 10 mm/s, 3 s dwell, 100 Hz."""
    from model3_truth import model3_record
    (d / "m3.csv").write_text("\n".join(model3_record()) + "\n")
    return {"m3": d / "m3.csv"}


records = records_fixture(_model3)


@pytest.mark.parametrize("flags", [
    ["--model", "3", "--start", "f1=0.001,f2=-0.5"],
    ["--model", "3", "--start", "g_fast=0.6,g_slow=0.5"],
    ["--model", "2", "--start", "g_fast=0.2"],
    ["--model", "1", "--start", "beta=0.1,g_slow=0.2"],
    ["--model", "2", "--start", "sigma0=2000"],
    ["--model", "2", "--start", "f2=-2000"],
    ["--model", "2", "--start", "sigma1=0"],
    ["--model", "2", "--start", "foo=1"],
    ["--model", "2", "--start", "sigma0"],
    ["--model", "2", "--start", "=3"],
    ["--model", "2", "--start", "a'b"],
    ["--model", "2", "--start", "sigma0=1,"],
    ["--model", "2", "--start", "sigma0=1,sigma0=2"],
    ["--model", "2", "--start", "alpha=nan"],
    ["--model", "2", "--start", "beta=0x10"],
    ["--model", "3", "--start", "g_fast=1"],
    ["--model", "2", "--noise", "1"],
    ["--model", "2", "--noise", "2.5"],
    ["--model", "2", "--noise", "0"],
    ["--model", "2", "--noise", "-1"],
    ["--model", "2", "--noise", "nan"],
    ["--model", "2", "--noise", "inf"],
    ["--model", "2", "--noise", "x"],
    ["--model", "2", "--noise"],
], ids=lambda f: " ".join(f[2:]))
def test_refused_alike(records, tmp_path, flags):
    out = tmp_path / "est.csv"
    r = reference(records["ml"], out, *flags)
    assert r.returncode == 2, r.stderr
    prog = r.stderr.split(": error: ", 1)[0]
    want = body(r.stderr, prog)
    assert not out.exists()
    for prog in PROGS:
        c = c_run(prog, records["ml"], out, *flags)
        assert c.returncode == 2, (prog, c.stderr)
        assert body(c.stderr, prog) == want
        assert c.stdout == "" and not out.exists()
    if "--noise" in flags and flags[-1] in ("1", "2.5"):
        assert "probably millinewtons, give it in N" in want


@pytest.mark.parametrize("case", ["m2-start-noise", "m3-strengths"])
def test_same_bytes_and_verdict(records, tmp_path, case):
    csv, flags = {
        "m2-start-noise": (records["ml"], ["--model", "2", "--start",
                                           "sigma0=0.3, f2=0.2,beta=0.05", "--noise", "0.005"]),
        "m3-strengths": (records["m3"], ["--model", "3", "--start", "g_fast=0.1,alpha=0.4",
                                         "--init-seed", "3"]),
    }[case]
    py, c = tmp_path / "py.csv", tmp_path / "c.csv"
    r = reference(csv, py, "--precision", "float64", *flags)
    assert r.returncode == 0, r.stderr
    d = c_run("nte-run-double", csv, c, *flags)
    assert d.returncode == 0, d.stderr
    assert c.read_bytes() == py.read_bytes()
    assert d.stdout.splitlines()[-1] == r.stdout.splitlines()[-1]
    if "--noise" in flags:
        assert "(5 mN, given by --noise)" in d.stdout.splitlines()[-1]
    f = c_run("nte-run", csv, tmp_path / "f.csv", *flags)
    assert f.returncode == 0, f.stderr


def _first(est: Path, name: str) -> float:
    lines = est.read_text().split("\n")
    return float(lines[1].split(",")[lines[0].split(",").index(name)])


def test_start_over_config_over_preset(records, tmp_path):
    """The starting values: the preset's, --config's params over them (unless --preset is
    given), --start's over either; the first row publishes them (seed 0)."""
    cfg = tmp_path / "cfg.json"
    c = c_run("nte-run-double", records["ml"], tmp_path / "id.csv", "--model", "2",
              "--export-config", str(cfg))
    assert c.returncode == 0, c.stderr
    from_config = json.loads(cfg.read_text())["params"]["sigma0"]
    for flags, want in ((["--model", "2"], 7.9e-3),
                        (["--config", str(cfg)], from_config),
                        (["--config", str(cfg), "--start", "sigma0=0.25"], 0.25),
                        (["--config", str(cfg), "--preset", "paper-6mms", "--start",
                          "sigma0=0.5"], 0.5)):
        est = tmp_path / "e.csv"
        assert c_run("nte-run-double", records["ml"], est, *flags).returncode == 0
        assert _first(est, "sigma0") == pytest.approx(want, rel=1e-12), flags


def test_config_start_noise_export_alike(records, tmp_path):
    """--config, --start and --noise together: the same estimates and the same exported
    configuration (r_n2 = N^2 from --noise over the file's) from both programs."""
    cfg = tmp_path / "cfg.json"
    assert c_run("nte-run-double", records["m3"], tmp_path / "id.csv", "--model", "2",
                 "--export-config", str(cfg)).returncode == 0
    flags = ["--config", str(cfg), "--start", "sigma1=3", "--noise", "0.004"]
    py_json, c_json = tmp_path / "py.json", tmp_path / "c.json"
    r = reference(records["m3"], tmp_path / "py.csv", *flags, "--export-config", str(py_json))
    assert r.returncode == 0, r.stderr
    d = c_run("nte-run-double", records["m3"], tmp_path / "c.csv", *flags, "--export-config",
              str(c_json))
    assert d.returncode == 0, d.stderr
    assert (tmp_path / "c.csv").read_bytes() == (tmp_path / "py.csv").read_bytes()
    py_cfg, c_cfg = json.loads(py_json.read_text()), json.loads(c_json.read_text())
    assert c_cfg.pop("source") == "nte-run" and py_cfg.pop("source") == "nte-ref estimate"
    assert c_cfg == py_cfg and c_cfg["r_n2"] == 0.004 * 0.004
    assert d.stdout.splitlines()[-1] == r.stdout.splitlines()[-1]


def test_help_names_start_and_noise():
    import subprocess
    for exe in PROGS.values():
        r = subprocess.run([str(exe), "--help"], capture_output=True, text=True)
        for text in ("--start NAME=VALUE,...", "--noise N", "g_fast, g_slow",
                     "r_n2 = N^2", "The last line on stdout is the verdict"):
            assert text in r.stdout, text
