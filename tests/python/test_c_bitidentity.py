"""The C library equals the reference bit for bit.

Requires build/host/bin/nte-run and nte-run-double (``make build``; skipped with a reason when
they are missing).  On the paper scenarios of c_twin.py — Model I and II, 10 mm/s to 50 and
80 mm, 6 mm/s, both schedules, seed 0 and a factor-5 seed — the float build's estimate file
equals the float32 reference's and the double build's the float64 reference's, character for
character (every real is printed with enough digits to round-trip, so equal text is equal bits);
the largest ULP distance is printed and must be 0.  Two more runs compare whole files written
by both command-line programs (`nte-ref estimate` and nte-run), on an input without a velocity
column (central differences) and with the paper tuning profile; two more with the contact
front end on, on a measured-like phantom record that starts in the air.
"""
from __future__ import annotations

import json
import os
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pytest

from c_twin import (ALL_RUNS, DATA, EXE, ROOT, cli_pair, groups, reference_batch,
                    reference_key, run_c, ulp_distance)

pytestmark = pytest.mark.skipif(
    not all(p.exists() for p in EXE.values()),
    reason="build/host/bin/nte-run{,-double} missing: build the firmware first (make build)")

PRECISIONS = ("float32", "float64")


@pytest.fixture(scope="module")
def reference() -> dict[tuple[str, str], list[str]]:
    """Every run's reference estimate file, computed once (batched, on every core).

    The result is cached under build/host/c_twin_cache, keyed by a hash of every reference
    source and input file, so a rerun with an unchanged reference takes seconds.
    """
    key = reference_key()
    cache = ROOT / "build" / "host" / "c_twin_cache" / f"{key}.json"
    if cache.exists():
        raw = json.loads(cache.read_text())
        return {tuple(k.split("|", 1)): v for k, v in raw.items()}  # type: ignore[misc]
    jobs = [g for p in PRECISIONS for g in groups(p)]
    out: dict[tuple[str, str], list[str]] = {}
    with ProcessPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
        for (precision, _), res in zip(jobs, pool.map(reference_batch, *zip(*jobs))):
            for name, lines in res.items():
                out[(precision, name)] = lines
    cache.parent.mkdir(parents=True, exist_ok=True)
    cache.write_text(json.dumps({f"{p}|{n}": v for (p, n), v in out.items()}))
    return out


@pytest.mark.parametrize("precision", PRECISIONS)
def test_paper_scenarios_bit_identical(reference, precision, tmp_path):
    worst = 0
    failures = []
    for r in ALL_RUNS:
        c_lines = run_c(precision, r, tmp_path / f"{r.name}.csv")
        ref = reference[(precision, r.name)]
        ulp = 0 if c_lines == ref else ulp_distance(c_lines, ref, precision)
        worst = max(worst, ulp)
        if ulp != 0 or c_lines != ref:
            failures.append(f"{r.name}: max ULP {ulp}")
    print(f"\n{precision}: {len(ALL_RUNS)} runs, max ULP distance C vs reference = {worst}")
    assert not failures, "\n".join(failures)


@pytest.mark.parametrize("precision,extra", [
    ("float32", ["--model", "2", "--profile", "paper", "--schedule", "rotate",
                 "--init-seed", "7", "--init-factor", "1.25"]),
    ("float64", ["--model", "1", "--profile", "paper", "--init-seed", "3"]),
])
def test_whole_files_from_both_clis(precision, extra, tmp_path):
    # an input without the velocity column: both sides differentiate the depth themselves
    src = (DATA / "p10_d50.csv").read_text().split("\n")
    cols = src[0].split(",")
    keep = [i for i, c in enumerate(cols) if c != "velocity_mm_s"]
    lines = ["# no velocity column: central differences"]
    lines += [",".join(row.split(",")[i] for i in keep) for row in src if row]
    csv = tmp_path / "novel.csv"
    csv.write_text("\n".join(lines) + "\n")
    c_bytes, py_bytes = cli_pair(precision, csv, extra, tmp_path)
    if c_bytes != py_bytes:
        ulp = ulp_distance(c_bytes.decode().split("\n")[:-1], py_bytes.decode().split("\n")[:-1],
                           precision)
        pytest.fail(f"files differ, max ULP {ulp}")
    print(f"\n{precision} {' '.join(extra)}: identical files, max ULP 0")


@pytest.fixture(scope="module")
def model3_csv(tmp_path_factory) -> Path:
    """A Model III truth (relaxation and direction memory) along an insertion to 30 mm, a 3 s
    dwell and the retraction, 100 Hz, 2 mN noise (model3_truth.py)."""
    from model3_truth import model3_record
    path = tmp_path_factory.mktemp("m3") / "m3.csv"
    path.write_text("\n".join(model3_record()) + "\n")
    return path


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("extra", [
    [],
    ["--schedule", "rotate", "--relax-branches", "1", "--tau-fast", "0.5"],
    ["--no-direction-memory", "--init-seed", "3", "--init-factor", "1.5", "--presliding-mm", "2"],
    ["--no-relaxation", "--profile", "paper", "--tau-slow", "5"],
], ids=["defaults", "rotate-one-branch", "no-direction-memory", "no-relaxation-paper"])
def test_model3_whole_files_bit_identical(model3_csv, precision, extra, tmp_path):
    """Model III through both command-line programs: identical files (0 ULP) in both
    precisions, with every switch of the model."""
    c_bytes, py_bytes = cli_pair(precision, model3_csv, ["--model", "3"] + extra, tmp_path)
    header = py_bytes.split(b"\n", 1)[0].decode()
    assert header.startswith("t_s,force_hat_n,z,innovation_n,status,sigma0")
    if "--no-relaxation" not in extra:
        assert ",g_fast,g_fast_sd" in header
    if c_bytes != py_bytes:
        ulp = ulp_distance(c_bytes.decode().split("\n")[:-1], py_bytes.decode().split("\n")[:-1],
                           precision)
        pytest.fail(f"files differ, max ULP {ulp}")
    print(f"\nModel III {precision} {' '.join(extra)}: identical files, max ULP 0")


@pytest.mark.parametrize("precision,extra", [
    ("float32", ["--model", "2", "--contact", "on"]),
    ("float64", ["--model", "1", "--contact", "on", "--schedule", "rotate"]),
])
def test_whole_files_with_the_contact_front_end(precision, extra, tmp_path):
    # a measured-like record (phantom lab seed 11, 3 mm/s, 75 Hz): the stage starts in the
    # air 3 mm before its zero, a tare, noise; the front end finds the surface and the bank
    # runs on the depth below it (tests/python/test_contact.py checks what it finds)
    from reference_py.sim.calibration import LAB
    from reference_py.sim.phantom import simulate_phantom
    from reference_py.tools.phantom import write_phantom
    from dataclasses import replace
    rec = simulate_phantom(LAB, seed=11, rate_hz=75.0, speeds_mm_s=(3.0,))
    csv = tmp_path / "air.csv"
    write_phantom(csv, replace(rec, depth_mm=rec.depth_mm - 3.0))
    c_bytes, py_bytes = cli_pair(precision, csv, extra, tmp_path)
    assert c_bytes.split(b"\n")[0].endswith(b",surface_mm,tare_n,contact")
    if c_bytes != py_bytes:
        ulp = ulp_distance(c_bytes.decode().split("\n")[:-1], py_bytes.decode().split("\n")[:-1],
                           precision)
        pytest.fail(f"files differ, max ULP {ulp}")
    print(f"\n{precision} {' '.join(extra)} (front end on): identical files, max ULP 0")
