"""Model III works in units of its sensor's own noise (contact.ContactFrontEnd.unit,
bank.FilterBank._scale_to_sensor; nte_contact.c nte_contact_unit, nte_bank.c
nte_bank_set_unit): the same insertions recorded by a quieter sensor on a smaller force range
read the same in units of their noise, and a sensor of 8 mN or more is read as before.
Phantom records, seeds 340-341 (never used to choose anything), force and noise scaled
together (config_loop_figures.FORCE_SCALES)."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import model3_batch_figures as mbf
from reference_py import contact

ROOT = Path(__file__).resolve().parents[2]
SEEDS = (340, 341)
PRESETS = ("skin-on-muscle", "artery-filled")


def _figures(tmp_path: Path, scale: float) -> np.ndarray:
    recs = [mbf.record(tmp_path, p, s, scale) for p in PRESETS for s in SEEDS]
    return mbf.run_batch(recs, {})


@pytest.fixture(scope="module")
def quiet(tmp_path_factory: pytest.TempPathFactory) -> dict[float, np.ndarray]:
    d = tmp_path_factory.mktemp("quiet")
    return {scale: _figures(d, scale) for scale in (0.03, 0.01)}


def test_two_quiet_sensors_read_the_same(quiet: dict[float, np.ndarray]) -> None:
    # 12 mN x 0.03 and x 0.01: 0.36 and 0.12 mN, both read in units of 8 mN; the bank's
    # inputs agree to rounding, so every figure within 1 %
    np.testing.assert_allclose(quiet[0.03], quiet[0.01], rtol=0.01)


def test_a_quiet_sensor_meets_the_targets(quiet: dict[float, np.ndarray]) -> None:
    # insertion <= 5, dwell and retraction <= 3 (issue 21's targets); before the unit,
    # x 0.03 read a dwell of 5.4 and a retraction of 8.6 on such records (held set)
    for scale in (0.03, 0.01):
        ins, dwell, retr = (np.median(quiet[scale][:, k]) for k in range(3))
        assert ins <= 5.0 and dwell <= 3.0 and retr <= 3.0, (scale, ins, dwell, retr)


def test_a_sensor_of_8_mN_or_more_is_read_as_before(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # the phantom's 12 mN: unit 1, so the run is bit for bit the one without the unit
    with_unit = _figures(tmp_path, 1.0)
    monkeypatch.setattr(contact, "NOISE_REF_N", 0.0)
    without = _figures(tmp_path, 1.0)
    assert np.array_equal(with_unit, without)


def test_the_c_library_reads_a_quiet_sensor_bit_for_bit(tmp_path: Path) -> None:
    f, _, _ = mbf.record(tmp_path, "skin-on-muscle", SEEDS[0], 0.03)
    ref, c = tmp_path / "ref.csv", tmp_path / "c.csv"
    subprocess.run([sys.executable, "-m", "reference_py", "estimate", str(f), "--model", "3",
                    "--out", str(ref)], check=True, capture_output=True, cwd=ROOT)
    subprocess.run([str(ROOT / "build" / "host" / "bin" / "nte-run-double"), str(f),
                    "--model", "3", "--out", str(c)], check=True, capture_output=True)
    assert ref.read_bytes() == c.read_bytes()
