"""nte-ref estimate --engine c (reference_py/tools/c_engine.py): the same estimate through the C
host program gives the reference's estimate file byte for byte (Models II and III, float64 and
float32, a phantom record; a logger's file through the column map; --start and --noise), and
the same verdict line; what the program lacks is converted by the reference's reader (the
input flags) or refused in one line (the others); a missing program is refused saying how to
build it.  The flag handling is also checked on a stand-in program whose --help lists fewer
flags (the C side gains flags in its own time)."""
from __future__ import annotations

import json
import os
import stat
import sys
from pathlib import Path

import pytest

from reference_py.tools.c_engine import C_BIN, C_EXE
from reference_py.tools.cli import main

from estimate_run import estimate, refused


def need_c() -> None:
    for exe in C_EXE.values():
        if not os.access(C_BIN / exe, os.X_OK):
            pytest.skip(f"{C_BIN / exe} missing: make build")


@pytest.fixture(scope="module")
def lab(tmp_path_factory) -> Path:
    """nte-ref phantom lab --seed 3 at 50 Hz with a 1 s dwell (1411 samples)."""
    d = tmp_path_factory.mktemp("engine_lab")
    assert main(["phantom", "lab", "--seed", "3", "--rate", "50", "--dwell", "1", "--out",
                 str(d / "lab.csv")]) == 0
    return d / "lab.csv"


@pytest.mark.parametrize("precision", ["float64", "float32"])
@pytest.mark.parametrize("model", ["2", "3"])
def test_c_engine_writes_the_reference_bytes(lab, tmp_path, capsys, model, precision):
    need_c()
    ref, c = tmp_path / "ref.csv", tmp_path / "c.csv"
    rc, ref_out, _ = estimate(capsys, lab, ref, "--model", model, "--precision", precision)
    assert rc == 0
    rc, c_out, _ = estimate(capsys, lab, c, "--model", model, "--precision", precision,
                            "--engine", "c")
    assert rc == 0
    assert c.read_bytes() == ref.read_bytes()
    assert c_out[-1] == ref_out[-1] and c_out[-1].startswith("verdict: ")


def test_c_engine_with_the_column_map_start_and_noise(lab, tmp_path, capsys):
    """A logger's file (time in us, the force among six channels, the stage's z): the program
    reads it through its own --columns, or through the reference's reader when it has none."""
    need_c()
    import csv
    rig = tmp_path / "rig.csv"
    with open(rig, "w") as fh:
        fh.write("time_us,fx,fy,fz,tx,ty,tz,px,py,pz\n")
        for r in csv.DictReader(open(lab)):
            fh.write(f"{round(float(r['t_s']) * 1e6)},0,0,{r['force_n']},0,0,0,1,2,"
                     f"{r['depth_mm']}\n")
    flags = ["--model", "2", "--columns", "t=time_us,depth=pz,force=fz", "--time-unit", "us",
             "--start", "sigma1=3,f1=0.1", "--noise", "0.01"]
    rc, ref_out, _ = estimate(capsys, rig, tmp_path / "ref.csv", *flags)
    assert rc == 0
    rc, c_out, err = estimate(capsys, rig, tmp_path / "c.csv", *flags, "--engine", "c")
    assert rc == 0, err
    assert (tmp_path / "c.csv").read_bytes() == (tmp_path / "ref.csv").read_bytes()
    assert c_out[-1] == ref_out[-1]


def test_a_missing_program_is_refused(lab, tmp_path, capsys):
    out = tmp_path / "e.csv"
    nowhere = tmp_path / "no-build"
    for precision, exe in C_EXE.items():
        assert refused(capsys, lab, out, "--model", "2", "--precision", precision, "--engine",
                       "c", "--c-bin", str(nowhere)) == [
            f"nte-ref: error: --engine c: {nowhere / exe} is missing (make build builds it; "
            f"--c-bin DIR points at another build)"]


# -- the flag handling, on a stand-in program ---------------------------------------------------

STAND_IN = '''#!{python}
"""A stand-in host program: --help lists {flags}; a run records its arguments and its input
file's text, and writes --out."""
import json, sys
args = sys.argv[1:]
if args == ["--help"]:
    print("usage: stand-in FILE.csv " + " ".join({flags!r}))
    sys.exit(0)
out = args[args.index("--out") + 1]
record = {{"args": args, "input": open(args[0]).read()}}
open({record!r}, "w").write(json.dumps(record))
open(out, "w").write("t_s\\n")
print("stand-in ran")
'''

BASE_FLAGS = ["--model", "--out", "--precision", "--preset"]


def stand_in(folder: Path, flags: list[str]) -> Path:
    folder.mkdir()
    exe = folder / C_EXE["float64"]
    exe.write_text(STAND_IN.format(python=sys.executable, flags=flags,
                                   record=str(folder / "record.json")))
    exe.chmod(exe.stat().st_mode | stat.S_IXUSR)
    return folder


def test_flags_the_program_has_are_handed_over(tmp_path, capsys):
    src = tmp_path / "in.csv"
    src.write_text("t_s,depth_mm,force_n\n0,0,0\n0.01,0.1,0.01\n")
    bin_dir = stand_in(tmp_path / "bin", BASE_FLAGS + ["--noise", "--start", "--columns",
                                                      "--time-unit"])
    out = tmp_path / "e.csv"
    rc, so, _ = estimate(capsys, src, out, "--model", "2", "--preset", "paper-6mms",
                         "--noise", "0.002", "--start", "f1=0.05,beta=0.02", "--columns",
                         "t=t_s,depth=depth_mm,force=force_n", "--time-unit", "ms",
                         "--engine", "c", "--c-bin", str(bin_dir))
    assert rc == 0 and so == ["stand-in ran"]
    rec = json.loads((bin_dir / "record.json").read_text())
    assert rec["args"] == [str(src), "--model", "2", "--preset", "paper-6mms", "--start",
                           "f1=0.05,beta=0.02", "--noise", "0.002", "--time-unit", "ms",
                           "--columns", "t=t_s,depth=depth_mm,force=force_n", "--out",
                           str(out)]
    assert rec["input"] == src.read_text()                 # the file itself


def test_input_flags_the_program_lacks_are_applied_by_the_reader(tmp_path, capsys):
    rig = tmp_path / "rig.csv"
    rig.write_text("time_us,fz,pz\n" + "".join(f"{k * 10000},{0.001 * k},{0.2 * k}\n"
                                               for k in range(60)))
    bin_dir = stand_in(tmp_path / "bin", BASE_FLAGS + ["--no-units-check"])
    rc, _, _ = estimate(capsys, rig, tmp_path / "e.csv", "--model", "2", "--columns",
                        "t=time_us,depth=pz,force=fz", "--time-unit", "us", "--no-units-check",
                        "--engine", "c", "--c-bin", str(bin_dir))
    assert rc == 0
    rec = json.loads((bin_dir / "record.json").read_text())
    assert rec["args"][1:] == ["--model", "2", "--out", str(tmp_path / "e.csv"),
                               "--no-units-check"]
    assert Path(rec["args"][0]).name == "rig.csv" and rec["args"][0] != str(rig)
    lines = rec["input"].splitlines()
    assert lines[0] == "t_s,depth_mm,force_n"
    assert lines[3] == "%.17g,%.17g,%.17g" % (20000 * 1e-6, 0.2 * 2, 0.001 * 2)
    assert len(lines) == 61
    assert not Path(rec["args"][0]).exists()                # the temporary input is gone


@pytest.mark.parametrize("flags,message", [
    (["--noise", "0.002"], "nte-ref: error: --engine c: nte-run-double has no --noise (this "
     "build; run with --engine reference, or rebuild it with make build)"),
    (["--plot", "x.png"], "nte-ref: error: --engine c: --plot: nte-run-double draws nothing "
     "(draw its estimate file with nte-ref plot)"),
])
def test_other_flags_the_program_lacks_are_refused(tmp_path, capsys, flags, message):
    src = tmp_path / "in.csv"
    src.write_text("t_s,depth_mm,force_n\n0,0,0\n0.01,0.1,0.01\n")
    bin_dir = stand_in(tmp_path / "bin", BASE_FLAGS)
    assert refused(capsys, src, tmp_path / "e.csv", "--model", "2", *flags, "--engine", "c",
                   "--c-bin", str(bin_dir)) == [message]
    assert not (bin_dir / "record.json").exists()
