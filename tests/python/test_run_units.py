"""nte-run refuses what `nte-ref estimate` refuses: a file in the wrong unit or sign (issue 23).

Two correct records — the phantom `nte-ref phantom skin --seed 3` (velocity column given) and a
measured-like record (discrepancy_measured_like.make_trial, written without a velocity column
by config_loop_figures.write_record) — are spoiled the ways a rig's file goes wrong: time in
ms, depth in m, force in mN, depth measured the other way, the sensor's opposite sign, one
force a million times too large, the depth in micrometres (most samples out of range).  Each
spoiled file goes through `nte-ref estimate`, nte-run-double and nte-run: exit status 2, one
line on stderr, the same message after the program's "PROG: error: " prefix, no output file.
With the option that converts it (--no-units-check where none does) the reference
(float64) and nte-run-double write the same bytes, and nte-run runs too.  The correct records
are never refused.  The rules written inline in units_check.check_units, which
firmware/tools/gen_constants.py copies into firmware/host/nte_units.h, are probed on the
reference at each threshold and on both sides of it through the C programs.

Requires build/host/bin/nte-run{,-double} (``make build``).
"""
from __future__ import annotations

import ctypes
import math
import subprocess
import sys
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from c_twin import ROOT
from reference_py.config import EstimatorConfig
from run_records import NEEDS_C, PROGS, body, c_run, records_fixture, reference

pytestmark = NEEDS_C

Table = tuple[list[str], np.ndarray]
Spoil = Callable[[list[str], np.ndarray], None]


def _load(path: Path) -> Table:
    lines = [ln for ln in path.read_text().split("\n") if ln and not ln.startswith("#")]
    return lines[0].split(","), np.array([[float(c) for c in ln.split(",")] for ln in lines[1:]])


def _save(path: Path, table: Table) -> Path:
    header, rows = table
    path.write_text(",".join(header) + "\n" + "".join(
        ",".join("%.17g" % x for x in r) + "\n" for r in rows))
    return path


def _scale(*pairs: tuple[str, float]) -> Spoil:
    """Multiply columns (those the file has) by factors."""
    def spoil(header: list[str], rows: np.ndarray) -> None:
        for name, k in pairs:
            if name in header:
                rows[:, header.index(name)] *= k
    return spoil


def _one_force_times(k: float) -> Spoil:
    def spoil(header: list[str], rows: np.ndarray) -> None:
        rows[len(rows) // 2, header.index("force_n")] *= k
    return spoil


#: name: (how the file is spoiled, the flags that read it right)
SPOILED: dict[str, tuple[Spoil, list[str]]] = {
    "ms-read-as-s": (_scale(("t_s", 1e3), ("velocity_mm_s", 1e-3)), ["--time-unit", "ms"]),
    "m-read-as-mm": (_scale(("depth_mm", 1e-3), ("velocity_mm_s", 1e-3)), ["--depth-unit", "m"]),
    "mN-read-as-N": (_scale(("force_n", 1e3)), ["--force-unit", "mN"]),
    "gf-read-as-N": (_scale(("force_n", 1.0 / 9.80665e-3)), ["--force-unit", "gf"]),
    "um-read-as-mm": (_scale(("depth_mm", 1e3), ("velocity_mm_s", 1e3)), ["--depth-unit", "um"]),
    "in-read-as-mm": (_scale(("depth_mm", 1 / 25.4), ("velocity_mm_s", 1 / 25.4)),
                      ["--depth-unit", "in"]),
    "negated-depth": (_scale(("depth_mm", -1.0), ("velocity_mm_s", -1.0)),
                      ["--depth-sign", "-1"]),
    "negated-force": (_scale(("force_n", -1.0)), ["--force-sign", "-1"]),
    "one-force-x1e6": (_one_force_times(1e6), ["--no-units-check"]),
    # beyond what micrometres would explain: the rule of the estimator's ranges
    "most-out-of-range": (_scale(("depth_mm", 1e6), ("velocity_mm_s", 1e6)),
                          ["--no-units-check"]),
}


def _time_units() -> dict[str, float]:
    from reference_py.tools.csvio import TIME_UNITS
    return TIME_UNITS


if "us" in _time_units():   # microseconds: csvio.TIME_UNITS and nte_units.h hold them alike
    SPOILED["us-read-as-s"] = (_scale(("t_s", 1e6), ("velocity_mm_s", 1e-6)),
                               ["--time-unit", "us"])

#: the spoiled files whose converted run is compared byte for byte (one record each: the
#: reference's run takes seconds); the others' converted runs are checked in C only
COMPARED = {"ms-read-as-s": "ml", "m-read-as-mm": "ph", "mN-read-as-N": "ml",
            "gf-read-as-N": "ph", "um-read-as-mm": "ml",
            "negated-depth": "ml", "negated-force": "ph", "one-force-x1e6": "ml",
            "most-out-of-range": "ph", "us-read-as-s": "ph", "in-read-as-mm": "ml"}

#: units the values cannot tell from the tools' own (a 25 mm stroke is 2.5 cm; 5 N is 1.1 lbf
#: and 0.51 kgf): read right with their flag, alike in both readers
UNDETECTED: dict[str, tuple[Spoil, list[str]]] = {
    "cm": (_scale(("depth_mm", 0.1), ("velocity_mm_s", 0.1)), ["--depth-unit", "cm"]),
    "kgf": (_scale(("force_n", 1 / 9.80665)), ["--force-unit", "kgf"]),
    "lbf": (_scale(("force_n", 1 / 4.4482216152605)), ["--force-unit", "lbf"]),
}


def _spoiled(d: Path, good: dict[str, Path]) -> dict[str, Path]:
    """Every correct record spoiled every way."""
    out = {}
    for base in ("ph", "ml"):
        for name, (spoil, _) in SPOILED.items():
            header, rows = _load(good[base])
            spoil(header, rows)
            out[f"{base}-{name}"] = _save(d / f"{base}-{name}.csv", (header, rows))
    return out


records = records_fixture(_spoiled)


@pytest.mark.parametrize("base", ["ph", "ml"])
@pytest.mark.parametrize("name", list(SPOILED))
def test_spoiled_file_is_refused_alike(records, tmp_path, base, name):
    csv = records[f"{base}-{name}"]
    out = tmp_path / "est.csv"
    r = reference(csv, out, "--model", "2")
    assert r.returncode == 2, r.stderr
    want = body(r.stderr, "nte-ref")
    assert not out.exists()
    for prog in PROGS:
        c = c_run(prog, csv, out, "--model", "2")
        assert c.returncode == 2, (prog, c.stderr)
        assert body(c.stderr, prog) == want, prog
        assert c.stdout == "" and not out.exists()
    print(f"\n{base}-{name}: {want}")


@pytest.mark.parametrize("name", list(SPOILED))
def test_converted_file_runs_alike(records, tmp_path, name):
    """The right option reads the spoiled file: the reference (float64) and nte-run-double
    write the same bytes; nte-run runs too."""
    flags = SPOILED[name][1]
    csv = records[f"{COMPARED[name]}-{name}"]
    py, c = tmp_path / "py.csv", tmp_path / "c.csv"
    r = reference(csv, py, "--model", "2", "--precision", "float64", *flags)
    assert r.returncode == 0, r.stderr
    d = c_run("nte-run-double", csv, c, "--model", "2", *flags)
    assert d.returncode == 0, d.stderr
    assert c.read_bytes() == py.read_bytes()
    f = c_run("nte-run", csv, tmp_path / "f.csv", "--model", "2", *flags)
    assert f.returncode == 0, f.stderr
    other = "ml" if COMPARED[name] == "ph" else "ph"
    for prog in PROGS:
        o = c_run(prog, records[f"{other}-{name}"], tmp_path / "o.csv", "--model", "2", *flags)
        assert o.returncode == 0, (prog, o.stderr)


@pytest.mark.parametrize("name", list(UNDETECTED))
def test_units_read_with_their_flag_alike(records, tmp_path, name):
    """Centimetres, kilogram-force and pound-force: the flag converts them, nte-run-double
    writes the reference's bytes and the result is the record's own to a few ulp's worth of
    estimate (the file's values went through a division and back)."""
    spoil, flags = UNDETECTED[name]
    header, rows = _load(records["ph"])
    spoil(header, rows)
    csv = _save(tmp_path / f"{name}.csv", (header, rows))
    py, c, own = tmp_path / "py.csv", tmp_path / "c.csv", tmp_path / "own.csv"
    r = reference(csv, py, "--model", "2", "--precision", "float64", *flags)
    assert r.returncode == 0, r.stderr
    d = c_run("nte-run-double", csv, c, "--model", "2", *flags)
    assert d.returncode == 0, d.stderr
    assert c.read_bytes() == py.read_bytes()
    assert c_run("nte-run-double", records["ph"], own, "--model", "2").returncode == 0
    a = np.genfromtxt(py, delimiter=",", names=True)["force_hat_n"]
    b = np.genfromtxt(own, delimiter=",", names=True)["force_hat_n"]
    assert np.max(np.abs(a - b)) <= 1e-6 * max(1.0, float(np.max(np.abs(b))))


def test_a_shallow_indentation_at_a_needles_speed_is_read(tmp_path):
    """A relaxation test's ramp of 0.6 mm at 1 mm/s, then a 20 s hold (phantom skin, seed 2161,
    the surface at the start): under the 1 mm stroke, but moving at a needle's speed, so no unit
    question -- both readers read it (it was refused as "probably metres"), and nte-run-double
    writes the reference's bytes.  The same record in metres (and at a thousandth of the
    speed) is still refused alike."""
    shallow = tmp_path / "shallow.csv"
    subprocess.run([sys.executable, "-m", "reference_py", "phantom", "skin", "--stroke", "0.6",
                    "--speed", "1", "--dwell", "20", "--surface", "0", "--seed", "2161",
                    "--out", str(shallow)], check=True, capture_output=True, cwd=ROOT)
    py, c = tmp_path / "py.csv", tmp_path / "c.csv"
    r = reference(shallow, py, "--model", "3", "--precision", "float64")
    assert r.returncode == 0, r.stderr
    d = c_run("nte-run-double", shallow, c, "--model", "3")
    assert d.returncode == 0, d.stderr
    assert c.read_bytes() == py.read_bytes()
    header, rows = _load(shallow)
    _scale(("depth_mm", 1e-3), ("velocity_mm_s", 1e-3))(header, rows)
    metres = _save(tmp_path / "metres.csv", (header, rows))
    r = reference(metres, py, "--model", "3")
    assert r.returncode == 2 and "probably metres: convert with --depth-unit m" in r.stderr
    for prog in PROGS:
        c = c_run(prog, metres, tmp_path / "o.csv", "--model", "3")
        assert c.returncode == 2 and body(c.stderr, prog) == body(r.stderr, "nte-ref"), prog


@pytest.mark.parametrize("base", ["ph", "ml"])
def test_correct_records_are_never_refused(records, tmp_path, base):
    from reference_py.tools.csvio import Limits, Units, read_trial
    from dataclasses import replace
    read_trial(records[base], units=Units())
    # a stage position (the contact front end) may go down to -depth_max_mm
    read_trial(records[base], units=Units(),
               limits=replace(Limits(), depth_min_mm=-EstimatorConfig.depth_max_mm))
    for prog in PROGS:
        for flags in (["--model", "2"], ["--model", "3"], ["--model", "1", "--contact", "on"]):
            c = c_run(prog, records[base], tmp_path / "est.csv", *flags)
            assert c.returncode == 0, (prog, flags, c.stderr)


def test_converted_nothing_without_flags(records, tmp_path):
    """The default units convert nothing: the same bytes as --no-units-check, and as the
    units spelled out."""
    outs = []
    for flags in ([], ["--no-units-check"],
                  ["--force-unit", "N", "--time-unit", "s", "--depth-unit", "mm",
                   "--force-sign", "+1", "--depth-sign", "1"]):
        out = tmp_path / f"e{len(outs)}.csv"
        assert c_run("nte-run-double", records["ph"], out, "--model", "2", *flags).returncode == 0
        outs.append(out.read_bytes())
    assert outs[0] == outs[1] == outs[2]


@pytest.mark.parametrize("flags", [
    ["--force-unit", "daN"], ["--time-unit", "min"], ["--depth-unit", "ft"],
    ["--force-sign", "2"], ["--depth-sign", "+2"], ["--force-sign", "-"],
    ["--depth-unit"], ["--depth-offset", "x"], ["--depth-offset", "1000.5"],
    ["--depth-offset", "inf"], ["--depth-offset", "nan"], ["--depth-offset"],
])
def test_unit_flag_refusals_alike(records, tmp_path, flags):
    out = tmp_path / "est.csv"
    r = reference(records["ph"], out, "--model", "2", *flags)
    assert r.returncode == 2
    want = body(r.stderr, "nte-ref estimate")
    for prog in PROGS:
        c = c_run(prog, records["ph"], out, "--model", "2", *flags)
        assert c.returncode == 2, c.stderr
        assert body(c.stderr, prog) == want
        assert not out.exists()


def test_help_names_the_unit_flags():
    for prog, exe in PROGS.items():
        r = subprocess.run([str(exe), "--help"], capture_output=True, text=True)
        assert r.returncode == 0
        units = "|".join(_time_units())
        for text in ("--force-unit N|mN", f"--time-unit {units}", "--depth-unit mm|m",
                     "--force-sign +1|-1", "--depth-sign +1|-1", "--depth-offset MM",
                     "--no-units-check"):
            assert text in r.stdout, (prog, text)
    source = (ROOT / "firmware" / "host" / "nte_run.c").read_text().split("*/", 1)[0]
    assert f"[--time-unit {units}]" in source and "[--no-units-check]" in source


# -- the rules units_check.check_units writes inline, probed at their thresholds --------------------

def _inline() -> dict[str, float]:
    sys.path.insert(0, str(ROOT / "firmware" / "tools"))
    try:
        import gen_constants
    finally:
        sys.path.pop(0)
    return dict(gen_constants.CHECK_INLINE)


def _probe(n: int, depth: np.ndarray, vel: np.ndarray, force: np.ndarray) -> Table:
    t = np.arange(n) * 0.01
    return ["t_s", "depth_mm", "velocity_mm_s", "force_n"], np.column_stack([t, depth, vel,
                                                                             force])


def _probes(k: dict[str, float]) -> dict[str, tuple[Table, bool]]:
    """name: (a file, refused?) on each side of every inline threshold."""
    n = 100
    ramp = np.linspace(0.0, 20.0, n)
    flat = np.full(n, 1.0)
    fmax = EstimatorConfig.force_max_n
    out: dict[str, tuple[Table, bool]] = {}
    for side, f in (("at", k["FORCE_IMPLAUSIBLE_FACTOR"] * fmax),
                    ("above", math.nextafter(k["FORCE_IMPLAUSIBLE_FACTOR"] * fmax, math.inf))):
        force = flat.copy()
        force[n // 2] = f
        out[f"force-{side}-limit"] = (_probe(n, ramp, flat, force), side == "above")
    share = k["NEGATIVE_DEPTH_SHARE"]
    for side, m in (("at", int(share * n)), ("above", int(share * n) + 1)):
        depth = np.where(np.arange(n) < m, -5.0, 5.0) + ramp * 1e-3
        out[f"negative-depths-{side}-share"] = (_probe(n, depth, np.zeros(n), flat),
                                                side == "above")
    v0 = k["INSERTING_SPEED_MM_S"]
    mins = int(k["INSERTING_MIN_SAMPLES"])
    for side, v, m in (("at-speed", v0, mins), ("above-speed", math.nextafter(v0, math.inf), mins),
                       ("fewer-samples", 2.0 * v0 + 1.0, mins - 1)):
        vel = np.where(np.arange(n) < m, v, 0.0)
        force = np.where(np.arange(n) < m, -1.0, 0.0)
        out[f"inserting-{side}"] = (_probe(n, ramp + 1.0, vel, force), side == "above-speed")
    # the direction rule: a stage going down 6 mm while the force rises from a tare of 0 whose
    # samples deviate by 1 (so its MAD is 1) and comes back to it; refused above DEPARTURE_MADS
    mads = k["DEPARTURE_MADS"]
    quiet = np.where(np.arange(20) % 2 == 0, -1.0, 1.0)
    for side, top in (("at", mads), ("above", math.nextafter(mads, math.inf))):
        force = np.concatenate([quiet, np.full(60, top), quiet])
        vel = np.concatenate([np.zeros(20), np.full(60, -10.0), np.zeros(20)])
        depth = np.concatenate([np.full(20, 50.0), 50.0 - 0.1 * np.arange(1, 61),
                                np.full(20, 44.0)])
        out[f"departure-{side}-mads"] = (_probe(n, depth, vel, force), side == "above")
    return out


def test_inline_rules_agree_with_the_reference(tmp_path):
    """gen_constants.CHECK_INLINE (nte_units.h) holds check_units's inline thresholds: the
    reference refuses exactly the probes above them, and both C programs do the same with the
    same message."""
    from reference_py.tools.csvio import UnitsError, Units, read_trial
    k = _inline()
    header = (ROOT / "firmware" / "host" / "nte_units.h").read_text()
    for name, v in k.items():
        lit = f"{v}U" if isinstance(v, int) else f"({float(v).hex()})"
        assert f"#define NTE_UNITS_{name} {lit}\n" in header, name
    out = tmp_path / "est.csv"
    for name, (table, refused) in _probes(k).items():
        csv = _save(tmp_path / f"{name}.csv", table)
        try:
            read_trial(csv, units=Units())
            message = None
        except UnitsError as exc:
            message = str(exc)
        assert (message is not None) == refused, (name, message)
        for prog in PROGS:
            c = c_run(prog, csv, out, "--model", "2")
            if refused:
                assert c.returncode == 2 and body(c.stderr, prog) == message, (prog, name)
            else:
                assert c.returncode == 0, (prog, name, c.stderr)


@pytest.mark.parametrize("spec", [".4g", "g", ".0f", ".1f", ".3g"])
def test_c_formats_numbers_as_python(spec):
    """The refusals print numbers with C's %.4g, %g and %.0f: glibc writes what Python's
    format() does (halves, exponents, large and small values)."""
    libc = ctypes.CDLL(None)
    rng = np.random.default_rng(23)
    values = [0.0, -0.0, 0.5, 1.5, 2.5, 12345.5, 99.95, 0.025, 1e-5, 1.23456e-7, 2.714e6,
              5.585e5, 1e16, 1e100, 4372.0, 10.48, 99.5, 100.0 * 0.745, 100.0 * 0.125]
    values += list(rng.normal(0.0, 1.0, 200) * 10.0 ** rng.integers(-8, 12, 200))
    buf = ctypes.create_string_buffer(128)
    for x in values:
        libc.snprintf(buf, 128, f"%{spec}".encode(), ctypes.c_double(x))
        assert buf.value.decode() == format(x, spec), (spec, x)


@pytest.mark.parametrize("seed", [3, 4, 7])
def test_negative_tare_over_a_long_air_gap_is_no_sign(tmp_path, seed):
    """Measured-like records whose tare is negative and whose stage crosses 4-16 mm of air: most
    samples taken while inserting read the tare, yet the sign is right (the force is judged
    less its tare).  Accepted by all three programs; negated, refused by all three alike."""
    from config_loop_figures import write_record
    from discrepancy_measured_like import make_trial
    tr, truth = make_trial(seed)[:2]
    inserting = np.gradient(tr.depth_mm, tr.t_s) > 0.5
    assert truth[0] < 0.0 and np.mean(tr.force_n[inserting] < 0.0) > 0.5
    good, bad = tmp_path / "good.csv", tmp_path / "negated.csv"
    write_record(good, tr.t_s, tr.depth_mm, tr.force_n)
    write_record(bad, tr.t_s, tr.depth_mm, -tr.force_n)
    out = tmp_path / "est.csv"
    r = reference(good, out, "--model", "2")
    assert r.returncode == 0, r.stderr
    r = reference(bad, out, "--model", "2")
    assert r.returncode == 2 and "convert with --force-sign -1" in r.stderr, r.stderr
    want = body(r.stderr, "nte-ref")
    for prog in PROGS:
        assert c_run(prog, good, out, "--model", "2").returncode == 0, prog
        c = c_run(prog, bad, out, "--model", "2")
        assert c.returncode == 2 and body(c.stderr, prog) == want, (prog, c.stderr)


@pytest.mark.parametrize("seed", [26, 29])
def test_a_stage_counting_down_is_named_alike(tmp_path, seed):
    """A measured-like record whose stage counts down to the tissue from 120 mm (positive depths
    that fall as the needle goes in): the force's sign used to be blamed; now the depth is
    named, and with --depth-sign -1 the origin (the depths are then negative).  Records that
    start in the tissue (a node restarted mid-retraction) or in the air after the exit,
    where the force also rises while the depth falls, are accepted.  All three programs
    alike.  (Seed 26 from 0.6 has a first "tare" the friction pulls below 0 and never comes
    back to; seed 29 from 0.8 is the air alone, its departures noise.)"""
    from config_loop_figures import write_record
    from discrepancy_measured_like import make_trial
    tr = make_trial(seed)[0]
    down = tmp_path / "down.csv"
    write_record(down, tr.t_s, 120.0 - tr.depth_mm, tr.force_n)
    out = tmp_path / "est.csv"
    for flags, says in (([], "the force first rises from its tare while the depth decreases"),
                        (["--depth-sign", "-1"], "with --depth-sign -1 (down to -120 mm): the "
                                                 "stage counts from an origin beyond the tissue")):
        r = reference(down, out, "--model", "2", *flags)
        assert r.returncode == 2 and says in r.stderr, r.stderr
        want = body(r.stderr, "nte-ref")
        if not flags:
            assert want.endswith("probably measured the other way: convert with --depth-sign -1")
        for prog in PROGS:
            c = c_run(prog, down, out, "--model", "2", *flags)
            assert c.returncode == 2 and body(c.stderr, prog) == want, (prog, c.stderr)
    # correct records that start past the reversal (0.6: retracting, 0.8: out of the tissue)
    for frac in (0.6, 0.8):
        k = int(frac * len(tr.t_s))
        cut = tmp_path / f"from{frac}.csv"
        write_record(cut, tr.t_s[k:], tr.depth_mm[k:], tr.force_n[k:])
        assert np.any(np.diff(tr.depth_mm[k:]) < 0.0)
        assert reference(cut, out, "--model", "2").returncode == 0, frac
        for prog in PROGS:
            assert c_run(prog, cut, out, "--model", "2").returncode == 0, (prog, frac)


@pytest.mark.parametrize("seed", [26, 29])
def test_both_columns_the_other_way_are_named_at_once(tmp_path, seed):
    """A measured-like record with the sensor inverted as well as the depth: the stage counting
    down from 120 mm (the force first *falls* while the depth decreases) or the depth negative.
    Both signs are named in one message, the advice follows the options given (a sign given is
    dropped, not added twice), and with both options the record reads as the correct one: the
    same estimates, byte for byte.  All three programs alike."""
    from config_loop_figures import write_record
    from discrepancy_measured_like import make_trial
    tr = make_trial(seed)[0]
    good, down, negative = (tmp_path / f"{n}.csv" for n in ("good", "down", "negative"))
    write_record(good, tr.t_s, tr.depth_mm, tr.force_n)
    write_record(down, tr.t_s, 120.0 - tr.depth_mm, -tr.force_n)
    write_record(negative, tr.t_s, -tr.depth_mm, -tr.force_n)
    out = tmp_path / "est.csv"
    both = "probably both the depth and the force measured the other way: "
    cases = [
        (down, [], "the force first falls from its tare while the depth decreases",
         both + "convert with --depth-sign -1 --force-sign -1"),
        (down, ["--force-sign", "-1"], "the force first rises from its tare",
         "measured the other way: convert with --depth-sign -1"),
        (down, ["--depth-sign", "-1", "--force-sign", "-1"], "with --depth-sign -1 (down to "
         "-120 mm): the stage counts from an origin beyond the tissue",
         "convert with --depth-offset 120 (the needle then starts at 0 mm)"),
        (negative, [], "and the force with it (read that way, the force less its tare is "
         "negative in", "convert with --depth-sign -1 --force-sign -1"),
        (negative, ["--force-sign", "-1"], "of the depths are negative (down to -",
         "probably measured the other way: convert with --depth-sign -1"),
        (good, ["--force-sign", "-1"], "probably the sensor's opposite sign",
         "read it without --force-sign -1"),
    ]
    for path, flags, says, ends in cases:
        r = reference(path, out, "--model", "2", *flags)
        assert r.returncode == 2 and says in r.stderr, (path.name, flags, r.stderr)
        want = body(r.stderr, "nte-ref")
        assert want.endswith(ends), (path.name, flags, want)
        for prog in PROGS:
            c = c_run(prog, path, out, "--model", "2", *flags)
            assert c.returncode == 2 and body(c.stderr, prog) == want, (prog, c.stderr)
    expected = tmp_path / "good_est.csv"
    assert reference(good, expected, "--model", "2").returncode == 0
    r = reference(negative, out, "--model", "2", "--depth-sign", "-1", "--force-sign", "-1")
    assert r.returncode == 0, r.stderr
    assert out.read_bytes() == expected.read_bytes()


def test_correct_records_that_first_fall_while_retracting_are_read(tmp_path):
    """What the inverted-stage rule must not take: a `lab` phantom record read from its
    reversal on (the force first falls while the depth decreases, and it leaves the tissue the
    same way), and a blind case inserted slower than the readers' moving speed whose largest
    departure is the retraction's pull.  Accepted by all three programs."""
    import discrepancy_generator as dg
    from config_loop_figures import write_record
    from discrepancy_measured_like import phantom_trial
    lab = phantom_trial("lab", 2102)[0]
    k = int(0.6 * len(lab.t_s))
    slow = dg.make_case("dwell_relaxation/maxwell_total", 1).trials[0]
    out = tmp_path / "est.csv"
    for name, t, x, f in (("lab-from-reversal", lab.t_s[k:], lab.depth_mm[k:], lab.force_n[k:]),
                          ("slow", slow.t_s, slow.depth_mm, slow.force_n)):
        path = tmp_path / f"{name}.csv"
        write_record(path, t, x, f)
        rel = f - np.median(f[:20])
        first = np.flatnonzero(np.abs(rel) > 0.1 * np.max(np.abs(rel)))[0]
        assert rel[first] < 0.0 and x[first + 1] < x[first], name   # it does first fall so
        r = reference(path, out, "--model", "2")
        assert r.returncode == 0, (name, r.stderr)
        for prog in PROGS:
            assert c_run(prog, path, out, "--model", "2").returncode == 0, (prog, name)


def test_a_stage_counting_from_another_origin_is_read_with_depth_offset(tmp_path):
    """A measured-like record in a stage's own coordinates: counting up from 37.25 mm before
    the needle's start (negative depths growing into the tissue), with the sensor inverted too,
    and counting down from 120 mm.  The messages name --depth-offset (and the force's sign
    where it is inverted) rather than the depth's sign, alike in the three programs; with the
    options they give, the record is read, nte-run-double writes the reference's bytes, and
    its estimates are those of the record starting at 0 to within rounding of the depth."""
    from config_loop_figures import write_record
    from discrepancy_measured_like import make_trial
    tr = make_trial(31)[0]
    good = tmp_path / "good.csv"
    write_record(good, tr.t_s, tr.depth_mm, tr.force_n)
    cases = {"up": (tr.depth_mm - 37.25, tr.force_n, "rises", "--depth-offset 37.25",
                    ["--depth-offset", "37.25"]),
             "up-inverted": (tr.depth_mm - 37.25, -tr.force_n, "falls",
                             "--depth-offset 37.25 --force-sign -1",
                             ["--depth-offset", "37.25", "--force-sign", "-1"])}
    out = tmp_path / "est.csv"
    expected = tmp_path / "good_est.csv"
    assert reference(good, expected, "--model", "3", "--precision", "float64").returncode == 0
    want_est = np.loadtxt(expected, delimiter=",", skiprows=1)
    for name, (x, f, first, advice, flags) in cases.items():
        path = tmp_path / f"{name}.csv"
        write_record(path, tr.t_s, x, f)
        r = reference(path, out, "--model", "3")
        assert r.returncode == 2, r.stderr
        want = body(r.stderr, "nte-ref")
        assert f"although the depth grows where the force first {first} from its tare" in want
        assert want.endswith(f"convert with {advice} (the needle then starts at 0 mm)"), want
        for prog in PROGS:
            c = c_run(prog, path, out, "--model", "3")
            assert c.returncode == 2 and body(c.stderr, prog) == want, (prog, c.stderr)
        py, c = tmp_path / f"{name}_py.csv", tmp_path / f"{name}_c.csv"
        r = reference(path, py, "--model", "3", "--precision", "float64", *flags)
        assert r.returncode == 0, r.stderr
        d = c_run("nte-run-double", path, c, "--model", "3", *flags)
        assert d.returncode == 0, d.stderr
        assert py.read_bytes() == c.read_bytes(), name
        got = np.loadtxt(py, delimiter=",", skiprows=1)
        assert got.shape == want_est.shape
        # the force estimate follows the record read from 0 (the depth differs by rounding)
        scale = float(np.max(np.abs(want_est[:, 1])))
        assert float(np.max(np.abs(got[:, 1] - want_est[:, 1]))) <= 1e-3 * scale, name


@pytest.mark.parametrize("seed", [4, 9])
def test_a_record_that_starts_in_the_tissue_is_judged_from_the_air(tmp_path, seed):
    """A measured-like record cut to start at 30 % of its samples, mid-insertion (a logger
    started late): its first forces are the tissue's, and judged from them the force later
    reads "negative while inserting" (the tears drop it below its start).  It ends shallower
    than it starts, so its sign is judged from the force of its end, in the air: read by all
    three programs; with the sensor inverted it is still refused, alike, with the air's tare."""
    from config_loop_figures import write_record
    from discrepancy_measured_like import make_trial
    from reference_py.tools.units_check import TARE_SAMPLES
    tr = make_trial(seed)[0]
    k = int(0.3 * len(tr.t_s))
    t, x, f = tr.t_s[k:], tr.depth_mm[k:], tr.force_n[k:]
    assert x[0] > 1.0 and np.gradient(x, t)[0] > 0.5          # inside, going in
    start, air = float(np.median(f[:TARE_SAMPLES])), float(np.median(f[-TARE_SAMPLES:]))
    assert start - air > 0.5                                    # its first forces: tissue's
    good, bad = tmp_path / "late.csv", tmp_path / "late-inverted.csv"
    write_record(good, t, x, f)
    write_record(bad, t, x, -f)
    out = tmp_path / "est.csv"
    r = reference(good, out, "--model", "2")
    assert r.returncode == 0, r.stderr
    r = reference(bad, out, "--model", "2")
    assert r.returncode == 2, r.stderr
    want = body(r.stderr, "nte-ref")
    assert f"the force less its tare ({-air:.4g} N) is negative" in want, want
    for prog in PROGS:
        assert c_run(prog, good, out, "--model", "2").returncode == 0, prog
        c = c_run(prog, bad, out, "--model", "2")
        assert c.returncode == 2 and body(c.stderr, prog) == want, (prog, c.stderr)


@pytest.mark.parametrize("peak,unit", [(5000.0, "gf"), (5100.0, "mN"), (60000.0, "none")])
def test_forces_over_the_range_name_the_same_units(tmp_path, peak, unit):
    """Grams-force and millinewtons (a factor 9.8 apart) named together while both bring the
    forces in, millinewtons alone above 50 N in gf, neither beyond: the same words in C."""
    src = tmp_path / "over.csv"
    src.write_text("t_s,depth_mm,force_n\n" + "".join(
        f"{k * 0.01!r},{k * 0.1!r},{peak * min(k, 20) / 20!r}\n" for k in range(60)))
    r = reference(src, tmp_path / "e.csv", "--model", "2")
    assert r.returncode == 2, r.stderr
    want = body(r.stderr, "nte-ref")
    assert ("--force-unit gf" in want) == (unit == "gf")
    assert ("--force-unit mN" in want) == (unit != "none")
    for prog in PROGS:
        c = c_run(prog, src, tmp_path / "e.csv", "--model", "2")
        assert c.returncode == 2 and body(c.stderr, prog) == want, (prog, c.stderr)
