"""The surface and tare front end (reference_py/contact.py, firmware/src/nte_contact.c).

On phantom records written as measured (the stage starts 2-15 mm above the tissue, a tare,
noise; `nte-ref phantom lab`): the surface it finds is within 0.5 mm of the truth and the tare
within a few mN — tuned on lab seeds 1-10, reported on held-out seeds 201-230 and on other
rates and speeds; each insertion of a record is found; pure noise in the air is never taken for
contact; a file that starts at a negative stage position loses no sample; and the C library
equals the reference bit for bit with the front end on (float and double, bank and robust).
The figures are printed (-s shows them).
"""
from __future__ import annotations

import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from c_twin import EXE, ROOT, cli_pair, ulp_distance
from reference_py.bank import REJECT_RANGE, FilterBank
from reference_py.config import ContactConfig, default_config
from reference_py.contact import CONTACT_AIR, CONTACT_TISSUE, ContactFrontEnd
from reference_py.fmath import F32, F64, Real
from reference_py.params import get_preset
from reference_py.sim.calibration import LAB
from reference_py.sim.phantom import PhantomResult, simulate_phantom
from reference_py.tools.phantom import write_phantom

TUNING_SEEDS = range(1, 11)
HELD_OUT_SEEDS = range(201, 231)
SURFACE_TOL_MM = 0.5
TARE_TOL_N = 0.010          # "within a few mN": the worst case seen is 7.3 mN (slow drift)
ON = ContactConfig(enabled=True)

needs_c = pytest.mark.skipif(not all(p.exists() for p in EXE.values()),
                             reason="build/host/bin/nte-run{,-double} missing: make build")


def onsets(records: list[PhantomResult], R: Real = F64, cfg: ContactConfig = ON,
           r_n2: float = 4e-6) -> list[list[tuple[float, float, float]]]:
    """Every AIR -> CONTACT transition of each record: (surface mm, tare N, time s).  The
    records run side by side on the front end's batch axis; a finished record is masked."""
    B = len(records)
    n = max(len(r.t_s) for r in records)
    fe = ContactFrontEnd(R, cfg, r_n2, 1e-3, B)
    cols = [np.zeros((B, n), dtype=R.dtype) for _ in range(3)]
    mask = np.zeros((B, n), dtype=bool)
    for b, r in enumerate(records):
        k = len(r.t_s)
        for c, a in zip(cols, (r.depth_mm, r.velocity_mm_s, r.force_n)):
            c[b, :k] = R.arr(a)
        mask[b, :k] = True
    out: list[list[tuple[float, float, float]]] = [[] for _ in records]
    before = fe.contact.copy()
    for k in range(n):
        fe.step(mask[:, k], cols[0][:, k], cols[1][:, k], cols[2][:, k])
        for b in np.nonzero(fe.contact & ~before)[0]:
            out[b].append((float(fe.surface[b]), float(fe.tare[b]), float(records[b].t_s[k])))
        before = fe.contact.copy()
    return out


def true_tare(rec: PhantomResult, t_s: float) -> float:
    """The sensor's offset and drift at a time (what a perfect tare would hold)."""
    j = min(int(np.searchsorted(rec.t_s, t_s)), len(rec.t_s) - 1)
    return rec.truth["spec"]["sensor"]["offset_n"] + float(rec.truth["samples"]["drift_n"][j])


def errors(records: list[PhantomResult], found: list[list[tuple[float, float, float]]]
           ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Surface and tare errors of the first contact of each cycle, and the records whose count
    of contacts is not their count of cycles."""
    surf, tare, wrong = [], [], []
    for rec, fd in zip(records, found):
        cycles = len(rec.truth["cycles"])
        if len(fd) != cycles:
            wrong.append(f"{rec.truth['name']}: {len(fd)} contacts for {cycles} insertions")
        for s, ta, t in fd[:cycles]:
            surf.append(s - rec.truth["surface_mm"])
            tare.append(ta - true_tare(rec, t))
    return np.abs(surf), np.abs(tare), wrong


def report(label: str, surf: np.ndarray, tare: np.ndarray) -> str:
    p = lambda a, s: " / ".join(f"{v * s:.3g}" for v in np.percentile(a, [50, 90, 100]))
    return (f"{label}: {len(surf)} contacts; surface error p50/p90/max {p(surf, 1)} mm, "
            f"tare error {p(tare, 1e3)} mN")


def check(label: str, records: list[PhantomResult], R: Real = F64) -> None:
    surf, tare, wrong = errors(records, onsets(records, R))
    print("\n" + report(label, surf, tare))
    assert not wrong, "\n".join(wrong)
    assert surf.max() <= SURFACE_TOL_MM, report(label, surf, tare)
    assert tare.max() <= TARE_TOL_N, report(label, surf, tare)


# -- accuracy on the phantom ------------------------------------------------------------------

@pytest.mark.parametrize("R", [F64, F32], ids=["float64", "float32"])
def test_surface_and_tare_on_the_tuning_seeds(R):
    check(f"lab seeds 1-10 (tuning), {R.name}", [simulate_phantom(LAB, seed=s)
                                                 for s in TUNING_SEEDS], R)


def test_surface_and_tare_on_held_out_seeds():
    check("lab seeds 201-230 (held out)", [simulate_phantom(LAB, seed=s)
                                           for s in HELD_OUT_SEEDS])


@pytest.mark.parametrize("rate", [75.0, 100.0, 200.0])
def test_surface_at_other_rates(rate):
    check(f"lab seeds 201-215 at {rate:g} Hz",
          [simulate_phantom(LAB, rate_hz=rate, seed=s) for s in range(201, 216)])


@pytest.mark.parametrize("speed", [1.0, 2.0, 3.0])
def test_surface_at_each_speed(speed):
    check(f"lab seeds 201-215 at {speed:g} mm/s",
          [simulate_phantom(LAB, seed=s, speeds_mm_s=(speed,)) for s in range(201, 216)])


@pytest.mark.parametrize("label,overrides", [
    ("50 mN noise at 1 mm/s", {"noise_n": 0.05, "speeds_mm_s": (1.0,)}),
    ("timestamp jitter 0.2 and two gaps", {"jitter": 0.2, "gaps": 2}),
])
def test_surface_on_harder_sensors(label, overrides):
    check(f"lab seeds 201-215, {label}",
          [simulate_phantom(LAB, seed=s, **overrides) for s in range(201, 216)])


def test_two_insertions_in_one_file_are_each_found():
    # two cycles (1 and 3 mm/s) per record, each entering from the air: two surfaces, two tares
    records = [simulate_phantom(LAB, seed=s, speeds_mm_s=(1.0, 3.0)) for s in range(201, 211)]
    found = onsets(records)
    assert all(len(fd) == 2 for fd in found), [len(fd) for fd in found]
    # the second tare is learned afresh: it follows the sensor's drift, not the first contact
    check("lab seeds 201-210, two insertions (1 and 3 mm/s)", records)


def test_no_false_contact_in_pure_noise():
    """Air only: the stage travels 25 mm inward at 2 mm/s with the measured tare (-17..+3 mN),
    white noise (7-55 mN), a linear drift and a random walk like the phantom's sensor."""
    rng = np.random.default_rng(20)
    B, rate = 60, 100.0
    t = np.arange(int(15.0 * rate)) / rate
    x = np.clip((t - 1.0) * 2.0, 0.0, 25.0)
    v = np.where((t > 1.0) & (x < 25.0), 2.0, 0.0)
    sigma = rng.uniform(0.007, 0.055, B)[:, None]
    f = (rng.uniform(-0.017, 0.003, B)[:, None] + rng.normal(0.0, 3e-4, B)[:, None] * t
         + np.cumsum(rng.normal(0.0, 1.0, (B, t.size)), axis=1) * np.sqrt(1.0 / rate)
         * rng.uniform(0.0, 1e-3, B)[:, None] + rng.normal(0.0, 1.0, (B, t.size)) * sigma)
    fe = ContactFrontEnd(F64, ON, 4e-6, 1e-3, B)
    ever = np.zeros(B, dtype=bool)
    for k in range(t.size):
        fe.step(np.ones(B, dtype=bool), np.full(B, x[k]), np.full(B, v[k]), f[:, k])
        ever |= fe.contact
    print(f"\npure noise: {int(ever.sum())} false contacts in {B} records of {t[-1]:.0f} s")
    assert not ever.any()
    # the noise it learned is the noise there is
    learned = np.sqrt(fe.ms)
    assert np.all(np.abs(learned / sigma[:, 0] - 1.0) < 0.35)


def test_known_surface_is_used_as_given():
    rec = simulate_phantom(LAB, seed=3)
    truth = rec.truth["surface_mm"]
    cfg = replace(ON, surface_mm=truth)
    (fd,) = onsets([rec], cfg=cfg)
    assert len(fd) == 1 and fd[0][0] == float(np.float64(truth))
    fe = ContactFrontEnd(F64, cfg, 4e-6, 1e-3, 1)
    for x in (truth - 1.0, truth + 2.5):
        depth, _ = fe.step(np.ones(1, dtype=bool), np.array([x]), np.array([1.0]),
                           np.array([0.5]))
        assert depth[0] == max(0.0, x - truth)
        assert fe.published()[2][0] == (CONTACT_TISSUE if x > truth else CONTACT_AIR)


# -- the bank behind it -----------------------------------------------------------------------

def _bank_run(rec: PhantomResult, contact: bool, shift_mm: float = 0.0):
    cfg = default_config(2)
    if contact:
        cfg = replace(cfg, contact=ON)
    bank = FilterBank(F64, cfg, [get_preset("paper-10mms").params.as_list()])
    t_us = np.round(rec.t_s * 1e6).astype(np.int64)
    depth = []
    for k in range(len(rec.t_s)):
        bank.step(t_us[k:k + 1], np.array([rec.depth_mm[k] + shift_mm]),
                  rec.velocity_mm_s[k:k + 1], rec.force_n[k:k + 1])
        depth.append(float(bank.l_prev[0]))
    return bank, np.array(depth)


def test_air_samples_are_not_rejected_and_the_air_gap_is_no_tissue():
    # the stage starts 10 mm below its zero: every sample before the tissue has a negative depth
    rec = simulate_phantom(LAB, seed=5, rate_hz=75.0, speeds_mm_s=(3.0,))
    off, _ = _bank_run(rec, contact=False, shift_mm=-10.0)
    on, depth = _bank_run(rec, contact=True, shift_mm=-10.0)
    assert off.rejects[REJECT_RANGE][0] > 0          # without the front end: rejected
    assert int(on.rejects.sum()) == 0
    # the bank saw depth 0 over the whole air gap, and the tissue depth below the surface
    surface = rec.truth["surface_mm"]
    stage = rec.depth_mm
    assert np.all(depth[stage < surface - 0.5] == 0.0)
    deep = stage > surface + 2.0
    assert np.all(np.abs(depth[deep] - (stage[deep] - surface)) < SURFACE_TOL_MM)


def test_the_front_end_off_publishes_zeros():
    rec = simulate_phantom(LAB, seed=5, rate_hz=75.0, speeds_mm_s=(3.0,))
    bank = FilterBank(F64, default_config(2), [get_preset("paper-10mms").params.as_list()])
    o = bank.step(np.array([0]), rec.depth_mm[:1], rec.velocity_mm_s[:1], rec.force_n[:1])
    assert bank.contact is None
    assert o.surface_mm[0] == 0.0 and o.tare_n[0] == 0.0 and o.contact[0] == CONTACT_AIR


@pytest.mark.parametrize("field,value", [
    ("k_sigma", 0.0), ("k_sigma", 101.0), ("floor_n", -1e-3), ("floor_n", 51.0),
    ("run_samples", 0), ("tare_samples", 100_001), ("learn_samples", 300),
    ("learn_gate_sigma", math.inf), ("cusum_drift_sigma", math.nan), ("surface_mm", 501.0),
    ("surface_mm", math.inf)])
def test_bad_contact_config_is_refused(field, value):
    cfg = replace(default_config(2), contact=replace(ON, **{field: value}))
    with pytest.raises(ValueError, match=f"contact.{field}"):
        cfg.validate()
    # off, the front end's fields are not looked at (as nte_config_check)
    replace(cfg, contact=replace(cfg.contact, enabled=False)).validate()


# -- the command-line programs and the C library ----------------------------------------------

@pytest.fixture(scope="module")
def air_file(tmp_path_factory) -> Path:
    """A short phantom record (3 mm/s, 75 Hz) whose stage starts at -4 mm: negative depths in
    the air, a tare, noise."""
    rec = simulate_phantom(LAB, seed=7, rate_hz=75.0, speeds_mm_s=(3.0,))
    rec = replace(rec, depth_mm=rec.depth_mm - 4.0)
    path = tmp_path_factory.mktemp("contact") / "air.csv"
    write_phantom(path, rec)
    return path


def _both(precision: str, csv: Path, extra: list[str], tmp: Path) -> tuple[str, str]:
    c_bytes, py_bytes = cli_pair(precision, csv, extra, tmp)
    return c_bytes.decode(), py_bytes.decode()


@needs_c
@pytest.mark.parametrize("precision,extra", [
    ("float32", ["--model", "2", "--contact", "on"]),
    ("float64", ["--model", "2", "--contact", "on"]),
    ("float32", ["--model", "1", "--contact", "on", "--estimator", "robust",
                 "--init-seed", "3"]),
    ("float64", ["--model", "2", "--surface", "1.5", "--schedule", "rotate"]),
    ("float32", ["--model", "3", "--contact", "on"]),
    ("float64", ["--model", "3", "--contact", "on", "--relax-branches", "1"]),
])
def test_c_equals_the_reference_with_the_front_end_on(air_file, precision, extra, tmp_path):
    c_text, py_text = _both(precision, air_file, extra, tmp_path)
    lines = c_text.split("\n")
    # Model III adds its layer index after the front end's columns
    tail = ",surface_mm,tare_n,contact" + (",layer" if extra[1] == "3" else "")
    assert lines[0].endswith(tail)
    contact = lines[0].split(",").index("contact")
    rows = [ln.split(",") for ln in lines[1:] if ln]
    assert not any(int(r[4]) & 2 for r in rows), "a sample was rejected"
    assert {r[contact] for r in rows} == {"0", "1"}     # air, then tissue, then air again
    if c_text != py_text:
        ulp = ulp_distance(c_text.split("\n")[:-1], py_text.split("\n")[:-1], precision)
        pytest.fail(f"files differ, max ULP {ulp}")
    print(f"\n{precision} {' '.join(extra)}: identical files, max ULP 0")


@needs_c
@pytest.mark.parametrize("extra,on", [(["--model", "3"], True),
                                      (["--model", "3", "--contact", "off"], False),
                                      (["--model", "2"], False), (["--model", "1"], False)])
def test_the_front_end_is_part_of_model_three(air_file, tmp_path, extra, on):
    """Model III turns the front end on unless told otherwise (a record as a rig writes it starts
    in the air); Models I and II leave it off: both twins, the same bytes."""
    c_text, py_text = _both("float64", air_file, extra, tmp_path)
    assert c_text == py_text
    assert ("surface_mm" in c_text.split("\n")[0]) == on


@needs_c
def test_the_front_end_off_leaves_the_columns_out(air_file, tmp_path):
    c_text, py_text = _both("float32", air_file, ["--model", "2", "--contact", "off"], tmp_path)
    assert c_text == py_text
    assert "surface_mm" not in c_text.split("\n")[0]


@needs_c
@pytest.mark.parametrize("prog", ["c", "py"])
def test_a_known_surface_needs_the_front_end(air_file, tmp_path, prog):
    args = [str(air_file), "--model", "2", "--contact", "off", "--surface", "3",
            "--out", str(tmp_path / "x.csv")]
    cmd = ([str(EXE["float32"])] if prog == "c" else [sys.executable, "-m", "reference_py",
                                                       "estimate"]) + args
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 2
    assert "--surface" in r.stderr and len(r.stderr.strip().split("\n")) == 1
    assert not (tmp_path / "x.csv").exists()
