"""E2E error-detection figures for every 8-byte frame of the DBC (tests/crc/crc_coverage.c).

Exhaustive over the 64 transmitted bits of each frame type: every 1-bit and 2-bit error must be
detected by nte_e2e_check (CRC-8 SAE J1850 + alive counter); every burst of length <= 8 inside
the data bytes 1..7 too.  3-bit errors are printed, not required: the polynomial 0x1D is
primitive without the factor (x + 1), so its Hamming distance is 3.  10**6 random error patterns
per frame type measure the residual acceptance: about 1/256 x 14/16 = 3.4e-3 for any accept
(the CRC passes and the corrupted counter is one of the 14 accepted deltas), about
1/256 x 1/16 = 2.4e-4 for an accept as the next in-sequence frame.
"""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DBC = ROOT / "firmware" / "can" / "nte.dbc"
N_RANDOM = 1_000_000


def _frames() -> list[tuple[str, int]]:
    cantools = pytest.importorskip("cantools")
    db = cantools.database.load_file(str(DBC))
    out = []
    for msg in db.messages:
        if msg.length != 8:
            continue
        out.append((msg.name, int(msg.dbc.attributes["NteE2EDataId"].value)))
    return out


@pytest.fixture(scope="module")
def figures(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict[str, float]]:
    cc = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if cc is None:
        pytest.skip("no C compiler (apt-get install -y gcc)")
    exe = tmp_path_factory.mktemp("crc") / "crc_coverage"
    subprocess.run(
        [cc, "-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-ffp-contract=off",
         "-I", str(ROOT / "firmware" / "can"), str(ROOT / "tests" / "crc" / "crc_coverage.c"),
         str(ROOT / "firmware" / "can" / "nte_e2e.c"), "-o", str(exe)],
        check=True)
    frames = _frames()
    # Depth, Force, Command, Setting, Estimate, Params, Heartbeat, Contact, Health
    assert len(frames) == 9, frames
    run = subprocess.run([str(exe), str(N_RANDOM)] + [f"{n}:{i}" for n, i in frames],
                         capture_output=True, text=True, timeout=120)
    print(run.stdout)
    result: dict[str, dict[str, float]] = {}
    for line in run.stdout.splitlines():
        kv = dict(item.split("=", 1) for item in line.split())
        name = kv.pop("frame")
        result[name] = {k: float(v) for k, v in kv.items()}
    assert set(result) == {n for n, _ in frames}
    assert run.returncode == 0, run.stdout + run.stderr
    return result


def test_every_single_and_double_bit_error_is_detected(figures: dict[str, dict[str, float]]) -> None:
    for name, f in figures.items():
        assert f["single"] == 64 and f["single_undetected"] == 0, name
        assert f["double"] == 64 * 63 / 2 and f["double_undetected"] == 0, name
        assert f["bursts"] > 6000 and f["burst_undetected"] == 0, name


def test_triple_bit_and_crc_byte_figures(figures: dict[str, dict[str, float]]) -> None:
    for name, f in figures.items():
        assert f["triple"] == 41664, name
        # HD = 3: some 3-bit patterns slip through, but well under 1 %.
        assert f["triple_undetected"] / f["triple"] < 0.01, name
        print(f"{name}: 3-bit undetected {int(f['triple_undetected'])}/{int(f['triple'])}, "
              f"bursts touching the CRC byte undetected "
              f"{int(f['crc_byte_burst_undetected'])}/{int(f['crc_byte_bursts'])}")


def test_random_corruption_residual_rate(figures: dict[str, dict[str, float]]) -> None:
    expected_any = 1.0 / 256.0 * 14.0 / 16.0
    expected_seq = 1.0 / 256.0 / 16.0
    for name, f in figures.items():
        assert f["random"] == N_RANDOM
        # 5 binomial standard deviations at 10**6 trials
        assert abs(f["random_rate"] - expected_any) < 5 * (expected_any / N_RANDOM) ** 0.5 + 1e-9, (
            name, f["random_rate"])
        assert abs(f["in_sequence_rate"] - expected_seq) < 5 * (expected_seq / N_RANDOM) ** 0.5, (
            name, f["in_sequence_rate"])
        print(f"{name}: random corruption accepted {f['random_rate']:.2e} "
              f"(in sequence {f['in_sequence_rate']:.2e}) of {N_RANDOM}")
