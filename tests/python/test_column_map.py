"""The column map of the one CSV reader (csvio.ColumnMap, ``--columns``) and ``--time-unit us``:
a logger's CSV (time in microseconds, six force/torque columns, the stage's three axes) runs as
it is and gives the same estimate, byte for byte, as the same data in the standard t_s,
depth_mm, force_n form; a malformed map, or a mapped column the file lacks, is refused with
exit 2 and one line naming it; nte-discrepancy and nte-ref plot read through the same map."""
from __future__ import annotations

import csv
import json
import shlex
from pathlib import Path

import numpy as np
import pytest

from reference_py.tools.cli import main
from reference_py.tools.csvio import ColumnMap, CsvError, Units, read_trial

from estimate_run import estimate as run_estimate, refused

RIG_MAP = "t=time_us,depth=pz,force=fz"
RIG_HEADER = "time_us,fx,fy,fz,tx,ty,tz,px,py,pz"


def write_rig(path: Path, rows: list[tuple[float, float, float]], *, vel: bool = False) -> Path:
    """``rows`` (t_s, depth_mm, force_n) as a logger writes them: integer microseconds, the
    force among six force/torque channels, the depth as the stage's z among three axes."""
    with open(path, "w") as fh:
        fh.write(RIG_HEADER + (",vz\n" if vel else "\n"))
        for k, (t, d, f) in enumerate(rows):
            cells = [f"{round(t * 1e6)}", "0.012", "-0.03", repr(f), "1e-4", "0", "-2e-4", "12.5",
                     "-3", repr(d)]
            fh.write(",".join(cells) + (",0\n" if vel else "\n"))
    return path


def write_standard(path: Path, rows: list[tuple[float, float, float]]) -> Path:
    """The same samples as :func:`write_rig`, in t_s, depth_mm, force_n (the time converted
    as the reader converts microseconds: one product by 1e-6)."""
    with open(path, "w") as fh:
        fh.write("t_s,depth_mm,force_n\n")
        for t, d, f in rows:
            fh.write("%r,%r,%r\n" % (round(t * 1e6) * 1e-6, d, f))
    return path


@pytest.fixture(scope="module")
def rows(tmp_path_factory) -> list[tuple[float, float, float]]:
    d = tmp_path_factory.mktemp("colmap")
    sim = d / "sim.csv"
    assert main(["simulate", "--preset", "needleB-tissueB-10mms", "--depth", "20", "--dwell",
                 "0.5", "--seed", "4", "--rate", "50", "--out", str(sim)]) == 0
    return [(float(r["t_s"]), float(r["depth_mm"]), float(r["force_n"]))
            for r in csv.DictReader(open(sim))]


def estimate(src: Path, out: Path, *extra: str) -> int:
    return main(["estimate", str(src), "--model", "2", "--out", str(out), *extra])


def test_a_logger_file_through_the_map_estimates_as_the_standard_form(rows, tmp_path, capsys):
    rig = write_rig(tmp_path / "rig.csv", rows)
    std = write_standard(tmp_path / "std.csv", rows)
    assert estimate(std, tmp_path / "std_est.csv") == 0
    assert estimate(rig, tmp_path / "rig_est.csv", "--columns", RIG_MAP, "--time-unit",
                    "us") == 0
    assert (tmp_path / "rig_est.csv").read_bytes() == (tmp_path / "std_est.csv").read_bytes()
    # spaces around keys and names are the header's own rule (stripped), any order
    assert estimate(rig, tmp_path / "rig_est2.csv", "--columns",
                    " force = fz , depth=pz,t=time_us", "--time-unit", "us") == 0
    assert (tmp_path / "rig_est2.csv").read_bytes() == (tmp_path / "std_est.csv").read_bytes()


def test_the_map_reads_a_named_velocity_and_otherwise_computes_it(rows, tmp_path):
    rig = write_rig(tmp_path / "rig.csv", rows, vel=True)
    units = Units(time="us", columns=ColumnMap.parse(RIG_MAP))
    tr = read_trial(rig, units=units)
    assert not tr.velocity_given and tr.velocity_mm_s.max() > 1.0   # central differences
    with_v = read_trial(rig, units=Units(time="us",
                                         columns=ColumnMap.parse(RIG_MAP + ",velocity=vz")))
    assert with_v.velocity_given and not with_v.velocity_mm_s.any()
    # the columns read, under the file's own names (fx, fy and vz, not read, are not kept)
    assert list(tr.columns) == ["time_us", "fz", "pz"]
    assert list(with_v.columns) == ["time_us", "fz", "pz", "vz"]


def test_microseconds_read_as_seconds_name_the_unit(rows, tmp_path, capsys):
    rig = write_rig(tmp_path / "rig.csv", rows)
    assert refused(capsys, rig, tmp_path / "e.csv", "--model", "2", "--columns", RIG_MAP) == [
        f"nte-ref: error: {rig}: column 'time_us': median time step 2e+04 s (longer than the "
        f"0.5 s gap limit): probably microseconds: convert with --time-unit us"]


#: a robot middleware's export (ROS): the message's time in integer nanoseconds since 1970
ROS_MAP = "t=%time,depth=depth_mm,force=force_n"


def write_ros(path: Path, rows: list[tuple[float, float, float]], std: Path) -> Path:
    """``rows`` as a ROS export writes them (``%time`` in integer nanoseconds since 1970), and
    in ``std`` the same samples in the standard form, the time converted as the reader
    converts nanoseconds (one product by 1e-9)."""
    stamps = [1_764_540_000_000_000_000 + round(t * 1e9) for t, _, _ in rows]
    with open(path, "w") as ros, open(std, "w") as fh:
        ros.write("%time,depth_mm,force_n\n")
        fh.write("t_s,depth_mm,force_n\n")
        for ns, (_, d, f) in zip(stamps, rows):
            ros.write(f"{ns},{d!r},{f!r}\n")
            fh.write(f"{ns * 1e-9!r},{d!r},{f!r}\n")
    return path


def test_a_ros_export_in_nanoseconds_since_1970_is_read_as_the_advice_says(rows, tmp_path,
                                                                           capsys):
    """The refusal gives the map, the map's refusal the unit, and with both the estimate is the
    standard file's holding the same times in seconds, byte for byte."""
    std = tmp_path / "std.csv"
    ros = write_ros(tmp_path / "ros.csv", rows, std)
    assert refused(capsys, ros, tmp_path / "e.csv", "--model", "2") == [
        f"nte-ref: error: {ros}:1: column 't_s': missing from the header (have: %time, "
        f"depth_mm, force_n); read it with --columns {ROS_MAP}"]
    assert refused(capsys, ros, tmp_path / "e.csv", "--model", "2", "--columns", ROS_MAP) == [
        f"nte-ref: error: {ros}: column '%time': median time step 2e+07 s (longer than the "
        f"0.5 s gap limit): probably nanoseconds: convert with --time-unit ns"]
    assert estimate(std, tmp_path / "std_e.csv") == 0
    assert estimate(ros, tmp_path / "ros_e.csv", "--columns", ROS_MAP, "--time-unit", "ns") == 0
    assert (tmp_path / "ros_e.csv").read_bytes() == (tmp_path / "std_e.csv").read_bytes()


BAD_MAPS = [
    ("t=time_us,depth=pz", "key 'force' missing (t, depth, force are required, velocity is "
                           "optional)"),
    ("t=time_us,t=t2,depth=pz,force=fz", "key 't' given twice"),
    ("t=time_us,depth=pz,force=fz,torque=tz", "unknown key 'torque' (keys: t, depth, force, "
                                              "velocity)"),
    ("t=time_us,depth=pz,force", "'force' is not KEY=NAME (expected "
                                 "t=NAME,depth=NAME,force=NAME[,velocity=NAME])"),
    ("t=time_us,,depth=pz,force=fz", "'' is not KEY=NAME (expected "
                                     "t=NAME,depth=NAME,force=NAME[,velocity=NAME])"),
    ("t=time_us,depth=pz,force=", "key 'force' names no column"),
    ("t=time_us,depth=pz,force=pz", "column 'pz' given for both 'depth' and 'force'"),
]


@pytest.mark.parametrize("text,why", BAD_MAPS, ids=[w.split(" (")[0] for _, w in BAD_MAPS])
def test_a_malformed_map_is_refused_naming_the_problem(rows, tmp_path, capsys, text, why):
    rig = write_rig(tmp_path / "rig.csv", rows[:20])
    assert refused(capsys, rig, tmp_path / "e.csv", "--model", "2", "--columns", text,
                   "--time-unit", "us") == [f"nte-ref: error: --columns {text}: {why}"]
    with pytest.raises(CsvError, match="^--columns "):
        ColumnMap.parse(text)


def test_a_map_without_force_only_where_none_is_read():
    """--predict-only reads no force: its map may leave force= out (the standard name stands,
    absent or ignored); every other refusal of the map stands."""
    cmap = ColumnMap.parse("t=time_us,depth=pz", force_optional=True)
    assert (cmap.t, cmap.depth, cmap.force, cmap.velocity) == ("time_us", "pz", "force_n", None)
    assert ColumnMap.parse(RIG_MAP, force_optional=True) == ColumnMap.parse(RIG_MAP)
    with pytest.raises(CsvError, match="key 'force' missing"):
        ColumnMap.parse("t=time_us,depth=pz")
    with pytest.raises(CsvError, match="key 'depth' missing"):
        ColumnMap.parse("t=time_us,force=fz", force_optional=True)


@pytest.mark.parametrize("text,missing", [("t=time_us,depth=pz,force=f_z", "f_z"),
                                          (RIG_MAP + ",velocity=vz", "vz")])
def test_a_mapped_column_the_file_lacks_is_named(rows, tmp_path, capsys, text, missing):
    rig = write_rig(tmp_path / "rig.csv", rows[:20])
    assert refused(capsys, rig, tmp_path / "e.csv", "--model", "2", "--columns", text,
                   "--time-unit", "us") == [
        f"nte-ref: error: {rig}:1: column '{missing}': missing from the header (have: "
        f"{RIG_HEADER.replace(',', ', ')})"]


#: headers that carry a unit in a column's name, the advice the refusal gives ("" none) and
#: the factors (time, depth, force) that turn the standard file's values into this file's
UNIT_HEADERS = [
    ("t_s,depth_mm,force_mN", "read it with --columns t=t_s,depth=depth_mm,force=force_mN "
     "--force-unit mN", (1.0, 1.0, 1e3)),
    ("t_ms,depth_mm,force_n", "read it with --columns t=t_ms,depth=depth_mm,force=force_n "
     "--time-unit ms", (1e3, 1.0, 1.0)),
    ("t_s,depth_m,force_N", "read it with --columns t=t_s,depth=depth_m,force=force_N "
     "--depth-unit m", (1.0, 1e-3, 1.0)),
    ("T_US,Depth_mm,Force_mN", "read it with --columns t=T_US,depth=Depth_mm,force=Force_mN "
     "--time-unit us --force-unit mN", (1e6, 1.0, 1e3)),
    # a spreadsheet's and a logger's names: the map quoted for the shell
    ("Time [s],Position [mm],Force [N]",
     "read it with --columns 't=Time [s],depth=Position [mm],force=Force [N]'", (1.0, 1.0, 1.0)),
    ("time (ms),displacement (m),Load (mN)", "read it with --columns "
     "'t=time (ms),depth=displacement (m),force=Load (mN)' --time-unit ms --depth-unit m "
     "--force-unit mN", (1e3, 1e-3, 1e3)),
    ("T/us,z/mm,Fz [N],Fx [N]", "read it with --columns 't=T/us,depth=z/mm,force=Fz [N]' "
     "--time-unit us", (1e6, 1.0, 1.0, 1.0)),
    ("Time in s,Insertion Depth [mm],Axial Force [mN]", "read it with --columns "
     "'t=Time in s,depth=Insertion Depth [mm],force=Axial Force [mN]' --force-unit mN",
     (1.0, 1.0, 1e3)),
    ("Timestamp (\u00b5s),Position [\u03bcm],Force [mN]", "read it with --columns "
     "'t=Timestamp (\u00b5s),depth=Position [\u03bcm],force=Force [mN]' --time-unit us "
     "--depth-unit um --force-unit mN", (1e6, 1e3, 1e3)),
    ("Timestamp (ns),Insertion depth [mm],Fz [N]", "read it with --columns "
     "'t=Timestamp (ns),depth=Insertion depth [mm],force=Fz [N]' --time-unit ns",
     (1e9, 1.0, 1.0)),
    # a word alone: the tools' own unit (the units check judges the values)
    ("time,depth_mm,force_mN", "read it with --columns t=time,depth=depth_mm,force=force_mN "
     "--force-unit mN", (1.0, 1.0, 1e3)),
    ("Time,Depth,Force", "read it with --columns t=Time,depth=Depth,force=Force",
     (1.0, 1.0, 1.0)),
    ("%time,Position,Load [N]", "read it with --columns 't=%time,depth=Position,force=Load [N]'",
     (1.0, 1.0, 1.0)),
    # two force columns, two times, or a quantity named otherwise: nothing sure enough to advise
    ("t_s,depth_mm,force_N,force_mN", "", (1.0, 1.0, 1.0, 1e3)),
    ("time,timestamp,depth,force", "", (1.0, 1.0, 1.0, 1.0)),
    ("t,d,f", "", (1.0, 1.0, 1.0)),
    ("Time [s],Position [mm],Force [N],Force [mN]", "", (1.0, 1.0, 1.0, 1e3)),
    ("Time [s],Position [mm],Fx [N]", "", (1.0, 1.0, 1.0)),
    # case is set aside in ASCII only (as the C twin compares): a capital Greek mu is no "us"
    ("TIME [\u039cS],Position [mm],Force [N]", "", (1.0, 1.0, 1.0)),
]


@pytest.mark.parametrize("header,advice,factors", UNIT_HEADERS,
                         ids=[h for h, _, _ in UNIT_HEADERS])
def test_a_unit_in_a_column_name_is_refused_with_the_options_that_read_it(
        rows, tmp_path, capsys, header, advice, factors):
    """A header such as force_mN is not guessed at (a column so named may hold anything), but
    the refusal gives the options that read the file, and with them it estimates as the
    standard file does (to the rounding of the unit conversion)."""
    src = tmp_path / "units.csv"
    with open(src, "w", encoding="utf-8") as fh:
        fh.write(header + "\n")
        for r in rows:
            cells = list(r) + [r[-1]] * (len(factors) - 3)
            fh.write(",".join(repr(v * k) for v, k in zip(cells, factors)) + "\n")
    first = header.split(",")
    missing = next(c for c in ("t_s", "depth_mm", "force_n") if c not in first)
    want = (f"nte-ref: error: {src}:1: column '{missing}': missing from the header (have: "
            f"{header.replace(',', ', ')})" + (f"; {advice}" if advice else ""))
    assert refused(capsys, src, tmp_path / "e.csv", "--model", "2") == [want]
    if not advice:
        return
    std = write_standard(tmp_path / "std.csv", rows)
    options = shlex.split(advice.removeprefix("read it with "))
    assert run_estimate(capsys, std, tmp_path / "std_e.csv", "--model", "2")[0] == 0
    assert run_estimate(capsys, src, tmp_path / "u_e.csv", "--model", "2", *options)[0] == 0
    a = np.loadtxt(tmp_path / "std_e.csv", delimiter=",", skiprows=1)
    b = np.loadtxt(tmp_path / "u_e.csv", delimiter=",", skiprows=1)
    assert a.shape == b.shape
    np.testing.assert_allclose(b[:, 1], a[:, 1], rtol=1e-9, atol=1e-9)   # force_hat_n


def test_the_mapped_time_must_increase(tmp_path, capsys):
    rig = tmp_path / "rig.csv"
    rig.write_text("time_us,pz,fz\n0,0,0\n10000,0.1,0\n9999,0.2,0\n")
    with pytest.raises(CsvError, match=r"rig.csv:4: column 'time_us': time 9999.0 does not "
                                       r"increase \(previous 10000.0\)"):
        read_trial(rig, units=Units(time="us", columns=ColumnMap.parse(RIG_MAP),
                                    check=False))


def test_discrepancy_runs_a_mapped_file(tmp_path, capsys):
    from discrepancy_generator import make_case
    from reference_py.discrepancy.cli import main as discrepancy
    case = make_case(("dwell_relaxation",), 5)
    std, rig = [], []
    for i, tr in enumerate(case.trials):
        rows = [(float(t), float(d), float(f)) for t, d, f in zip(tr.t_s, tr.depth_mm, tr.force_n)]
        rig.append(str(write_rig(tmp_path / f"rig{i}.csv", rows)))
        std.append(str(write_standard(tmp_path / f"std{i}.csv", rows)))
    assert discrepancy(std + ["--out", str(tmp_path / "std"), "--no-figures"]) == 0
    assert discrepancy(rig + ["--out", str(tmp_path / "rig"), "--no-figures", "--columns",
                              RIG_MAP, "--time-unit", "us"]) == 0
    got = json.loads((tmp_path / "rig" / "report.json").read_text())
    ref = json.loads((tmp_path / "std" / "report.json").read_text())
    assert got["named"] == ref["named"] and got["verdict"] == ref["verdict"]
    capsys.readouterr()
    assert discrepancy(rig + ["--out", str(tmp_path / "bad"), "--columns", "t=time_us"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["nte-discrepancy: --columns t=time_us: key 'depth' missing (t, depth, force "
                   "are required, velocity is optional)"]
    assert not (tmp_path / "bad").exists()


def test_plot_reads_its_input_through_the_map(rows, tmp_path, capsys):
    rig = write_rig(tmp_path / "rig.csv", rows)
    est = tmp_path / "e.csv"
    assert estimate(rig, est, "--columns", RIG_MAP, "--time-unit", "us") == 0
    assert main(["plot", str(est), "--input", str(rig), "--columns", RIG_MAP, "--time-unit",
                 "us", "--out", str(tmp_path / "f.png")]) == 0
    assert (tmp_path / "f.png").stat().st_size > 1000
