"""Units sanity of the one CSV reader (reference_py/tools/csvio.py) through nte-ref estimate:
force in mN, time in ms, depth in m, depth or force with the opposite sign, force beyond any
plausible value and most samples out of range are refused, one line naming the probable unit
and the converting option; with that option the estimates equal those of the file in N, s, mm.
The estimating tools end with the counts of rejected, gated and clipped samples."""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from reference_py.config import EstimatorConfig
from reference_py.tools.cli import main
from reference_py.tools.csvio import Units, UnitsError, check_units, read_trial


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> tuple[Path, list[tuple[float, float, float]]]:
    d = tmp_path_factory.mktemp("units")
    sim = d / "sim.csv"
    assert main(["simulate", "--preset", "needleB-tissueB-10mms", "--depth", "20", "--dwell",
                 "0.5", "--seed", "3", "--rate", "50", "--out", str(sim)]) == 0
    rows = [(float(r["t_s"]), float(r["depth_mm"]), float(r["force_n"]))
            for r in csv.DictReader(open(sim))]
    return d, rows


def write(path: Path, rows, f) -> Path:
    with open(path, "w") as fh:
        fh.write("t_s,depth_mm,force_n\n")
        for t, d, fo in rows:
            fh.write("%r,%r,%r\n" % f(t, d, fo))
    return path


CASES = [
    ("mN", lambda t, d, f: (t, d, f * 1000.0), ["--force-unit", "mN"],
     "column 'force_n': 29 % of the forces exceed the configured range ±50 N (up to 82.29): "
     "probably millinewtons, or grams-force (a load cell read in grams): convert with "
     "--force-unit mN or --force-unit gf"),
    # (grams-force read as N: the same rule, test_run_units; this record's 82 mN is 8.4 gf)
    ("um", lambda t, d, f: (t, d * 1000.0, f), ["--depth-unit", "um"],
     "column 'depth_mm': 91 % of the depths are outside the accepted range -1..500 mm "
     "(from 0 to 2e+04): probably micrometres: convert with --depth-unit um"),
    ("ms", lambda t, d, f: (t * 1000.0, d, f), ["--time-unit", "ms"],
     "column 't_s': median time step 20 s (longer than the 0.5 s gap limit): probably "
     "milliseconds: convert with --time-unit ms"),
    ("m", lambda t, d, f: (t, d / 1000.0, f), ["--depth-unit", "m"],
     "column 'depth_mm': the depth spans only 0.02 mm at 0.01 mm/s (less than 1 mm, slower than "
     "0.2 mm/s): probably metres: convert with --depth-unit m"),
    ("depth mirrored", lambda t, d, f: (t, -d, f), ["--depth-sign", "-1"],
     "column 'depth_mm': 95 % of the depths are negative (down to -20 mm): probably measured "
     "the other way: convert with --depth-sign -1"),
    ("force inverted", lambda t, d, f: (t, d, -f), ["--force-sign", "-1"],
     "column 'force_n': the force less its tare (-0.004931 N) is negative in 99 % of the "
     "samples taken while inserting: probably the sensor's opposite sign: convert with "
     "--force-sign -1"),
]


def estimate(src: Path, out: Path, extra=()) -> int:
    return main(["estimate", str(src), "--model", "2", "--out", str(out), *extra])


@pytest.mark.parametrize("label,convert,option,message", CASES, ids=[c[0] for c in CASES])
def test_refused_with_the_probable_unit_then_converted(base, tmp_path, capsys, label, convert,
                                                       option, message):
    d, rows = base
    ref_out = d / "ref_est.csv"
    if not ref_out.exists():
        assert estimate(write(d / "ref.csv", rows, lambda *r: r), ref_out) == 0
    src = write(tmp_path / "in.csv", rows, convert)
    out = tmp_path / "est.csv"
    capsys.readouterr()
    assert estimate(src, out) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"nte-ref: error: {src}: {message}"]
    assert not out.exists()
    assert estimate(src, out, option) == 0
    # the counts, then the verdict (the last line)
    assert capsys.readouterr().out.strip().splitlines()[-2] == \
        f"samples: {len(rows)}; rejected 0, gated 0, clipped 0"
    ref = np.loadtxt(ref_out, delimiter=",", skiprows=1)
    got = np.loadtxt(out, delimiter=",", skiprows=1)
    # a sign flip is exact; a unit factor rounds once per value (1e-3 is not a binary fraction)
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-12)


def test_no_units_check_accepts_and_counts_the_rejected(base, tmp_path, capsys):
    d, rows = base
    src = write(tmp_path / "in.csv", rows, lambda t, dd, f: (t, dd, f * 1000.0))
    capsys.readouterr()
    assert estimate(src, tmp_path / "e.csv", ["--no-units-check"]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-2]
    n_out = sum(1 for _, _, f in rows if abs(f * 1000.0) > EstimatorConfig.force_max_n)
    assert last.startswith(f"samples: {len(rows)}; rejected {n_out}, ")


def _trial(tmp_path, text):
    p = tmp_path / "t.csv"
    p.write_text(text)
    return read_trial(p)


def test_implausible_force_and_mostly_out_of_range(tmp_path):
    rows = [(k * 0.01, k * 0.1, 0.1) for k in range(100)]
    text = "t_s,depth_mm,force_n\n" + "".join("%r,%r,%r\n" % r for r in rows)
    check_units(_trial(tmp_path, text))                       # plausible: accepted
    one = text.replace("\n0.5,5.0,0.1\n", "\n0.5,5.0,1e300\n")
    assert one != text
    with pytest.raises(UnitsError, match=r"t.csv:52: column 'force_n': 1e\+300 N is not a "
                                         r"plausible force \(the configured range is ±50 N\)"):
        check_units(_trial(tmp_path, one))
    fast = "t_s,depth_mm,force_n\n" + "".join("%r,%r,0.1\n" % (k * 0.001, k * 1.0)
                                              for k in range(100))
    with pytest.raises(UnitsError, match=r"100 of 100 samples \(100 %\) are outside the "
                                         r"estimator's accepted ranges"):
        check_units(_trial(tmp_path, fast))                   # 1000 mm/s: faster than 500


def test_unknown_unit_and_sign_flags(tmp_path, capsys):
    for flags, msg in ((["--force-unit", "daN"], "argument --force-unit: invalid choice: 'daN'"),
                       (["--depth-sign", "2"], "argument --depth-sign: must be +1 or -1")):
        with pytest.raises(SystemExit) as e:
            main(["estimate", "x.csv", "--model", "2", "--out", str(tmp_path / "o"), *flags])
        assert e.value.code == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and msg in err[0]


def test_reader_without_units_converts_and_checks_nothing(tmp_path):
    tr = _trial(tmp_path, "t_s,depth_mm,force_n\n0,0,0\n1000,0.01,500\n")
    assert list(tr.t_s) == [0.0, 1000.0] and list(tr.force_n) == [0.0, 500.0]
    with pytest.raises(UnitsError):
        check_units(tr, Units())


def test_discrepancy_refuses_an_implausible_force(tmp_path, capsys):
    from reference_py.discrepancy.cli import main as discrepancy
    p = tmp_path / "t.csv"
    p.write_text("t_s,depth_mm,force_n\n" + "".join(
        "%r,%r,%s\n" % (k * 0.01, k * 0.1, "1e300" if k == 30 else "0.1") for k in range(100)))
    assert discrepancy([str(p), "--out", str(tmp_path / "rep")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"nte-discrepancy: {p}:32: column 'force_n': 1e+300 N is not a plausible "
                   f"force (the configured range is ±50 N)"]
    assert not (tmp_path / "rep").exists()


def test_discrepancy_flags_refused_in_one_line(tmp_path, capsys):
    from reference_py.discrepancy.cli import main as discrepancy
    with pytest.raises(SystemExit) as e:
        discrepancy(["a.csv", "--out", str(tmp_path / "r"), "--time-unit", "min"])
    assert e.value.code == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "nte-discrepancy: error: argument --time-unit: invalid choice: 'min' (choose from 's', "
        "'ms', 'us', 'ns') (see nte-discrepancy --help)"]


@pytest.mark.parametrize("peak,advice", [
    (5000.0, "probably millinewtons, or grams-force (a load cell read in grams): convert with "
             "--force-unit mN or --force-unit gf"),
    (5100.0, "probably millinewtons: convert with --force-unit mN"),   # 50 N over 9.80665 mN
    (60000.0, "not a force in N")])
def test_forces_over_the_range_name_the_units_that_bring_them_in(tmp_path, peak, advice):
    rows = "".join(f"{k * 0.01!r},{k * 0.1!r},{peak * min(k, 20) / 20!r}\n" for k in range(60))
    with pytest.raises(UnitsError) as e:
        check_units(_trial(tmp_path, "t_s,depth_mm,force_n\n" + rows))
    assert str(e.value).endswith(f"(up to {peak:.4g}): {advice}"), str(e.value)
