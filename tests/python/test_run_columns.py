"""nte-run reads a logger's CSV as it is: --columns t=NAME,depth=NAME,force=NAME[,velocity=NAME]
with --time-unit us (issue 23), as `nte-ref estimate` does (csvio.ColumnMap).

The logger's file (test_column_map.write_rig: time in integer microseconds, six force/torque
channels fx..tz, the stage's axes px, py, pz) estimates through the map to the same bytes as
the same samples in the standard t_s, depth_mm, force_n form, and the same bytes as the
reference's (float64 against nte-run-double).  A malformed map, a mapped column the file
lacks and microseconds read as seconds are refused by both programs with the same message,
naming the file's own column; a velocity column is read only when the map names it.

Requires build/host/bin/nte-run{,-double} (``make build``).
"""
from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from c_twin import ROOT
from run_records import NEEDS_C, PROGS, body, c_run, reference
from test_column_map import (BAD_MAPS, RIG_HEADER, RIG_MAP, ROS_MAP, UNIT_HEADERS, write_rig,
                             write_ros, write_standard)

pytestmark = NEEDS_C

US = ["--columns", RIG_MAP, "--time-unit", "us"]


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("columns")
    sim = d / "sim.csv"
    subprocess.run([sys.executable, "-m", "reference_py", "simulate", "--preset",
                    "needleB-tissueB-10mms", "--depth", "20", "--dwell", "0.5", "--seed", "4",
                    "--rate", "50", "--out", str(sim)], check=True, capture_output=True,
                   cwd=ROOT)
    rows = [(float(r["t_s"]), float(r["depth_mm"]), float(r["force_n"]))
            for r in csv.DictReader(open(sim))]
    return {"rig": write_rig(d / "rig.csv", rows), "rig_v": write_rig(d / "rig_v.csv", rows,
                                                                      vel=True),
            "std": write_standard(d / "std.csv", rows), "sim": sim}


def test_a_logger_file_runs_as_it_is(files, tmp_path):
    for prog in PROGS:
        std, rig = tmp_path / f"{prog}-std.csv", tmp_path / f"{prog}-rig.csv"
        assert c_run(prog, files["std"], std, "--model", "2").returncode == 0
        r = c_run(prog, files["rig"], rig, "--model", "2", *US)
        assert r.returncode == 0, r.stderr
        assert rig.read_bytes() == std.read_bytes(), prog
        assert r.stdout.splitlines()[-1].startswith("verdict: ")
    # spaces around keys and names, any order
    again = tmp_path / "again.csv"
    assert c_run("nte-run-double", files["rig"], again, "--model", "2", "--columns",
                 " force = fz , depth=pz,t=time_us", "--time-unit", "us").returncode == 0
    assert again.read_bytes() == (tmp_path / "nte-run-double-std.csv").read_bytes()


def test_a_logger_file_gives_the_references_bytes(files, tmp_path):
    flags = ["--model", "3", *US, "--start", "sigma1=3", "--noise", "0.002"]
    py, c = tmp_path / "py.csv", tmp_path / "c.csv"
    r = reference(files["rig"], py, "--precision", "float64", *flags)
    assert r.returncode == 0, r.stderr
    d = c_run("nte-run-double", files["rig"], c, *flags)
    assert d.returncode == 0, d.stderr
    assert c.read_bytes() == py.read_bytes()
    assert d.stdout.splitlines()[-1] == r.stdout.splitlines()[-1]


def test_a_ros_export_in_nanoseconds_is_refused_and_read_alike(files, tmp_path):
    """test_column_map's ROS export (%time in nanoseconds since 1970): both programs refuse it
    without the map and without the unit with the same words, and read with both nte-run-double
    writes the reference's bytes, which are those of the same times in seconds."""
    rows = [(float(r["t_s"]), float(r["depth_mm"]), float(r["force_n"]))
            for r in csv.DictReader(open(files["sim"]))]
    std = tmp_path / "std.csv"
    ros = write_ros(tmp_path / "ros.csv", rows, std)
    assert _refused_alike(ros, tmp_path).endswith(f"; read it with --columns {ROS_MAP}")
    assert _refused_alike(ros, tmp_path, "--columns", ROS_MAP).endswith(
        "probably nanoseconds: convert with --time-unit ns")
    flags = ["--model", "3", "--columns", ROS_MAP, "--time-unit", "ns"]
    py, c, c_std = tmp_path / "py.csv", tmp_path / "c.csv", tmp_path / "c_std.csv"
    assert reference(ros, py, "--precision", "float64", *flags).returncode == 0
    assert c_run("nte-run-double", ros, c, *flags).returncode == 0
    assert c_run("nte-run-double", std, c_std, "--model", "3").returncode == 0
    assert c.read_bytes() == py.read_bytes() == c_std.read_bytes()


def test_a_materials_testers_export_reads_with_the_advice(files, tmp_path):
    """A materials tester's export: quoted names without units, a units row, the load in kN.
    Refused without the map (advised), then for the units row's kN (advised), and read with
    both as the same samples in N: nte-run-double writes the reference's bytes, and the
    estimate follows the standard file's to the rounding of the conversion."""
    rows = [(float(r["t_s"]), float(r["depth_mm"]), float(r["force_n"]))
            for r in csv.DictReader(open(files["sim"]))]
    src = tmp_path / "tester.csv"
    src.write_text('"Time","Extension","Load"\n"(s)","(mm)","(kN)"\n' + "".join(
        f'"{t!r}","{d!r}","{f / 1e3!r}"\n' for t, d, f in rows))
    tester_map = "t=Time,depth=Extension,force=Load"
    assert _refused_alike(src, tmp_path).endswith(f"; read it with --columns {tester_map}")
    assert _refused_alike(src, tmp_path, "--columns", tester_map) == (
        f"{src}:2: column 'Load': the units row gives '(kN)': convert with --force-unit kN")
    flags = ["--model", "2", "--columns", tester_map, "--force-unit", "kN"]
    py, c, std = tmp_path / "py.csv", tmp_path / "c.csv", tmp_path / "std.csv"
    assert reference(src, py, "--precision", "float64", *flags).returncode == 0
    assert c_run("nte-run-double", src, c, *flags).returncode == 0
    assert c.read_bytes() == py.read_bytes()
    assert c_run("nte-run-double", files["std"], std, "--model", "2").returncode == 0
    a = np.loadtxt(std, delimiter=",", skiprows=1)
    b = np.loadtxt(c, delimiter=",", skiprows=1)
    np.testing.assert_allclose(b[:, 1], a[:, 1], rtol=1e-9, atol=1e-9)   # force_hat_n


@pytest.mark.parametrize("units_row,column,message", [
    ('"(s)","(mm)","(V)"', "Load", "'(V)' is not a unit of force the tools read "
                                   "(N, mN, gf, kgf, lbf, kN)"),
    ('"(s)","(mm)","kip"', "Load", "'kip' is not a unit of force the tools read "
                                   "(N, mN, gf, kgf, lbf, kN)"),
    ('"(min)","(mm)","(N)"', "Time", "'(min)' is not a unit of time the tools read "
                                     "(s, ms, us, ns)"),
    ('"(s)","(N)","(N)"', "Extension", "'(N)' is not a unit of depth the tools read "
                                       "(mm, m, um, cm, in)")])
def test_a_units_row_with_a_unit_not_read_names_the_units_that_are(tmp_path, units_row, column,
                                                                  message):
    """A units row whose unit the tools do not read (a load cell in volts, kips, minutes) or
    of another quantity is refused by both programs for that cell, with the units that read,
    not as "not a number"; the same row with a unit read is read."""
    tester_map = "t=Time,depth=Extension,force=Load"
    src = tmp_path / "tester.csv"
    src.write_text(f'"Time","Extension","Load"\n{units_row}\n0,0,0\n0.01,0.01,0\n')
    assert _refused_alike(src, tmp_path, "--columns", tester_map) == (
        f"{src}:2: column '{column}': the units row's {message}: convert the column to one of "
        f"them")
    src.write_text('"Time","Extension","Load"\n"(sec)","(mm)","(N)"\n0,0,0\n0.01,0.01,0\n')
    assert c_run("nte-run", src, tmp_path / "c.csv", "--model", "2", "--columns", tester_map,
                 "--no-units-check").returncode == 0


@pytest.mark.parametrize("delimiter", [" ", ",", "\t"])
def test_numpy_savetxt_files_read_as_the_standard_file(files, tmp_path, delimiter):
    """A trial saved by numpy.savetxt as a researcher's script does (its header in a comment,
    '%.18e', spaces by default): read by both programs and the reference, to the standard
    file's estimates byte for byte (the digits round-trip float64)."""
    data = np.loadtxt(files["std"], delimiter=",", skiprows=1)
    src = tmp_path / "saved.txt"
    np.savetxt(src, data, delimiter=delimiter, header=delimiter.join(("t_s", "depth_mm",
                                                                      "force_n")))
    assert src.read_text().startswith("# t_s")
    py, want = tmp_path / "py.csv", tmp_path / "want.csv"
    assert reference(files["std"], want, "--model", "2", "--precision", "float64").returncode == 0
    r = reference(src, py, "--model", "2", "--precision", "float64")
    assert r.returncode == 0, r.stderr
    assert py.read_bytes() == want.read_bytes()
    for prog in PROGS:
        c, std = tmp_path / f"{prog}.csv", tmp_path / f"{prog}-std.csv"
        assert c_run(prog, files["std"], std, "--model", "2").returncode == 0
        r = c_run(prog, src, c, "--model", "2")
        assert r.returncode == 0, (prog, r.stderr)
        assert c.read_bytes() == std.read_bytes(), prog


def test_a_numpy_savetxt_file_under_its_own_names_reads_with_the_advice(files, tmp_path):
    """numpy.savetxt under the script's own names ("# time depth force"): refused by both
    programs with the map that reads it, naming the comment's line; read with it as the
    standard file."""
    src = tmp_path / "saved.txt"
    np.savetxt(src, np.loadtxt(files["std"], delimiter=",", skiprows=1),
               header="time depth force")
    advised = "t=time,depth=depth,force=force"
    assert _refused_alike(src, tmp_path) == (
        f"{src}:1: column 't_s': missing from the header (have: time, depth, force); read it "
        f"with --columns {advised}")
    std, c = tmp_path / "std.csv", tmp_path / "c.csv"
    assert c_run("nte-run-double", files["std"], std, "--model", "2").returncode == 0
    assert c_run("nte-run-double", src, c, "--model", "2", "--columns", advised).returncode == 0
    assert c.read_bytes() == std.read_bytes()


def _read_as_the_standard_file(files, tmp_path: Path, sources, flags: list[str]) -> None:
    """Each of ``sources`` read with ``flags`` gives the standard file's estimates: the
    reference's float64 bytes are nte-run-double's of the standard file, and each program's
    its own of the standard file."""
    want = tmp_path / "want.csv"
    assert c_run("nte-run-double", files["std"], want, "--model", "2").returncode == 0
    for src in sources:
        py, c = tmp_path / "py.csv", tmp_path / "c.csv"
        r = reference(src, py, "--model", "2", "--precision", "float64", *flags)
        assert r.returncode == 0, r.stderr
        assert py.read_bytes() == want.read_bytes(), src.name
        for prog in PROGS:
            std = tmp_path / f"{prog}-std.csv"
            assert c_run(prog, files["std"], std, "--model", "2").returncode == 0
            r = c_run(prog, src, c, "--model", "2", *flags)
            assert r.returncode == 0, (prog, r.stderr)
            assert c.read_bytes() == std.read_bytes(), (prog, src.name)


def test_a_file_without_a_header_reads_by_column_positions(files, tmp_path):
    """MATLAB's writematrix and many loggers write no header: refused with the advice, then
    read with the columns' positions (from 1) by both programs and the reference, to the
    standard file's bytes -- also with the columns in another order, after a preamble line
    (the separator is still the first line's: here a comma), and with a header the positions
    pass over."""
    rows = np.loadtxt(files["std"], delimiter=",", skiprows=1)
    bare = tmp_path / "bare.csv"
    np.savetxt(bare, rows[:, [2, 0, 1]], delimiter=";", fmt="%.17g")   # force, time, depth
    assert _refused_alike(bare, tmp_path).endswith(
        "missing from the header (have: " + ", ".join(
            bare.read_text().splitlines()[0].split(";")) + "); no header line: name the "
        "columns by their positions, from 1: --columns t=N,depth=N,force=N")
    positions = ["--columns", "t=2,depth=3,force=1"]
    preamble = tmp_path / "preamble.csv"
    preamble.write_text("Rig 3\n" + bare.read_text().replace(";", ","))
    # the preamble before the samples is refused with the same advice (its line, its names)
    assert _refused_alike(preamble, tmp_path) == (
        f"{preamble}:1: column 't_s': missing from the header (have: Rig 3); no header line: "
        "name the columns by their positions, from 1: --columns t=N,depth=N,force=N")
    headed = tmp_path / "headed.csv"
    headed.write_text("force_n;t_s;depth_mm\n" + bare.read_text())
    _read_as_the_standard_file(files, tmp_path, (bare, preamble, headed), positions)
    assert _refused_alike(bare, tmp_path, "--columns", "t=2,depth=3,force=4") == (
        f"{bare}:1: column '4': no such position: the first sample has 3 cells")
    # a position written otherwise ("01") is a name, as before: no column is found by position
    assert "column '2': missing from the header" in _refused_alike(
        bare, tmp_path, "--columns", "t=2,depth=3,force=01")


def test_a_file_without_a_header_and_a_text_column_reads_by_positions(files, tmp_path):
    """A logger without a header that writes its state word beside the numbers
    (``0.01,0.1,0.5,INSERT``): the columns not read may hold anything, so read by positions
    it gives the standard file's bytes in both programs and the reference -- after a preamble
    line too, and with a line of the state word alone (nothing in the columns read: skipped).
    A text word at a position read is refused alike."""
    rows = np.loadtxt(files["std"], delimiter=",", skiprows=1)
    lines = [f"{t!r},{d!r},{f!r},{'INSERT' if k % 3 else 'HOLD'},note {k}"
             for k, (t, d, f) in enumerate(rows.tolist())]
    logger = tmp_path / "logger.csv"
    logger.write_text("\n".join(lines[:5] + [",,,PAUSE,"] + lines[5:]) + "\n")
    preamble = tmp_path / "preamble.csv"
    preamble.write_text("Rig 3 run 7\n,,,IDLE,\n" + logger.read_text())
    positions = ["--columns", "t=1,depth=2,force=3"]
    _read_as_the_standard_file(files, tmp_path, (logger, preamble), positions)
    # the state word at a position read: no line is a sample, so none is the header
    assert _refused_alike(logger, tmp_path, "--columns", "t=1,depth=2,force=4").startswith(
        f"{logger}:1: column '1': missing from the header (have: {lines[0].replace(',', ', ')}")


def test_velocity_only_when_the_map_names_it(files, tmp_path):
    """rig_v has a velocity column vz of zeros: without velocity= it is not read (central
    differences, the same as the file without it), with velocity=vz it is."""
    plain, mapped, no_vz = (tmp_path / n for n in ("plain.csv", "mapped.csv", "no_vz.csv"))
    assert c_run("nte-run-double", files["rig_v"], plain, "--model", "2", *US).returncode == 0
    assert c_run("nte-run-double", files["rig"], no_vz, "--model", "2", *US).returncode == 0
    assert plain.read_bytes() == no_vz.read_bytes()
    py = tmp_path / "py.csv"
    flags = ["--model", "2", "--columns", RIG_MAP + ",velocity=vz", "--time-unit", "us",
             "--no-units-check"]
    assert c_run("nte-run-double", files["rig_v"], mapped, *flags).returncode == 0
    assert reference(files["rig_v"], py, "--precision", "float64", *flags).returncode == 0
    assert mapped.read_bytes() == py.read_bytes() != plain.read_bytes()


def _refused_alike(csv_path: Path, tmp_path: Path, *flags: str) -> str:
    out = tmp_path / "e.csv"
    r = reference(csv_path, out, "--model", "2", *flags)
    assert r.returncode == 2, r.stderr
    want = body(r.stderr, "nte-ref")
    for prog in PROGS:
        c = c_run(prog, csv_path, out, "--model", "2", *flags)
        assert c.returncode == 2, (prog, c.stderr)
        assert body(c.stderr, prog) == want, prog
        assert c.stdout == "" and not out.exists()
    return want


@pytest.mark.parametrize("text,why", BAD_MAPS, ids=[w.split(" (")[0] for _, w in BAD_MAPS])
def test_a_malformed_map_is_refused_alike(files, tmp_path, text, why):
    want = _refused_alike(files["rig"], tmp_path, "--columns", text, "--time-unit", "us")
    assert want == f"--columns {text}: {why}"


@pytest.mark.parametrize("text,missing", [("t=time_us,depth=pz,force=f_z", "f_z"),
                                          (RIG_MAP + ",velocity=vz", "vz")])
def test_a_mapped_column_the_file_lacks_is_named_alike(files, tmp_path, text, missing):
    want = _refused_alike(files["rig"], tmp_path, "--columns", text, "--time-unit", "us")
    assert want == (f"{files['rig']}:1: column '{missing}': missing from the header (have: "
                    f"{RIG_HEADER.replace(',', ', ')})")


def test_microseconds_read_as_seconds_name_the_column(files, tmp_path):
    want = _refused_alike(files["rig"], tmp_path, "--columns", RIG_MAP)
    assert "column 'time_us'" in want and "probably microseconds: convert with --time-unit us" \
        in want


def test_the_mapped_time_and_duplicates_are_named_alike(tmp_path):
    rig = tmp_path / "rig.csv"
    rig.write_text("time_us,pz,fz\n0,0,0\n10000,0.1,0\n9000,0.2,0\n")
    want = _refused_alike(rig, tmp_path, "--columns", RIG_MAP, "--time-unit", "us")
    assert want == f"{rig}:4: column 'time_us': time 9000.0 does not increase (previous 10000.0)"
    dup = tmp_path / "dup.csv"
    dup.write_text("time_us,pz,fz,fz\n0,0,0,0\n")
    want = _refused_alike(dup, tmp_path, "--columns", RIG_MAP, "--time-unit", "us")
    assert want == f"{dup}:1: column 'fz': duplicate column name in the header"


def test_help_names_the_map():
    for exe in PROGS.values():
        r = subprocess.run([str(exe), "--help"], capture_output=True, text=True)
        assert "--columns MAP" in r.stdout and "t=time_us,depth=pz,force=fz" in r.stdout


@pytest.mark.parametrize("header,advice", [(h, a) for h, a, _ in UNIT_HEADERS],
                         ids=[h for h, _, _ in UNIT_HEADERS])
def test_a_unit_in_a_column_name_gets_the_same_advice(tmp_path, header, advice):
    """nte-run's reader gives the refusal of test_column_map's table word for word (its twin
    of csvio.unit_suffix_hint in csv_in.c), and none when a --columns map was given."""
    src = tmp_path / "units.csv"
    src.write_text(header + "\n" + ",".join(["0"] * header.count(",")) + ",0\n",
                   encoding="utf-8")
    want = _refused_alike(src, tmp_path)
    assert want.endswith(f"; {advice}") == bool(advice), want
    if advice:
        # a map that misses: the map's column is named, with no advice
        mapped = _refused_alike(src, tmp_path, "--columns", "t=x,depth=y,force=z")
        assert "read it with" not in mapped
