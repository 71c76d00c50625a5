"""host_bench/with-vcan: a real SocketCAN vcan0, natively or in a user-mode-linux kernel.

Inside it: candump captures cansend's frames, python-can's socketcan interface round-trips a
message, a 200 Hz request/answer stream is timed; a failing command's status and output come
back; a command that overruns the timeout is stopped, with nothing left running.
Needs (Debian): user-mode-linux kmod can-utils iproute2 -- or a kernel with vcan.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
WITH_VCAN = ROOT / "host_bench" / "with-vcan"


def _available() -> bool:
    if shutil.which("linux.uml") and Path("/usr/lib/uml/modules").is_dir():
        return True
    r = subprocess.run(["ip", "link", "add", "dev", "vcanprobe", "type", "vcan"],
                       capture_output=True)
    if r.returncode == 0:
        subprocess.run(["ip", "link", "del", "dev", "vcanprobe"], capture_output=True)
        return True
    return False


pytestmark = pytest.mark.skipif(
    not _available(),
    reason="no vcan: apt-get install -y user-mode-linux kmod can-utils iproute2")


def run(args: list[str], tmp_path: Path, timeout: float = 150, **env: str):
    e = dict(os.environ, TMPDIR=str(tmp_path), **env)
    t = time.monotonic()
    r = subprocess.run([str(WITH_VCAN), *args], capture_output=True, text=True, env=e,
                       timeout=timeout, cwd=ROOT)
    return r, time.monotonic() - t


def _leftovers(marker: str) -> list[str]:
    """Processes whose command line mentions `marker` (read-only scan of /proc)."""
    found = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            except OSError:
                continue
            if marker in cmd:
                found.append(f"{d.name}: {cmd}")
    return found


def test_candump_pycan_and_200hz_round_trip(tmp_path: Path) -> None:
    out = tmp_path / "probe.json"
    timing = tmp_path / "timing.txt"
    r, wall = run([".venv/bin/python" if (ROOT / ".venv/bin/python").exists() else "python3",
                   "tests/python/vcan_probe.py", str(out), "400"], tmp_path,
                  WITH_VCAN_TIMING=str(timing))
    assert r.returncode == 0, r.stdout + r.stderr
    res = json.loads(out.read_text())
    # candump -L: "(1700000000.123456) vcan0 123#DEADBEEF"
    frames = [line.split()[-1] for line in res["candump"]]
    assert frames == ["123#DEADBEEF", "5A1#0102", "7FF#0011223344556677"], res["candump"]
    assert all(re.match(r"^\(\d+\.\d{6}\) vcan0 ", line) for line in res["candump"])
    assert res["pycan"] == {"id": 0x321, "data": "010203fa", "dlc": 4, "ext": False}
    # 200 Hz stream: every request answered; the median round trip (Python on both ends,
    # measured 1.1-1.3 ms in UML on a shared 2-core machine) within one 5 ms period, and the
    # tail (scheduling jitter of the shared machine, seen up to 14 ms) bounded.
    assert res["answered"] == res["n"] == 400
    assert 150.0 <= res["rate_hz"] <= 205.0
    assert res["rtt_median_ms"] < 3.0, res
    assert res["rtt_p99_ms"] < 30.0, res
    m = re.match(r"boot_s=([\d.]+) cmd_s=([\d.]+) total_s=([\d.]+)", timing.read_text())
    assert m, timing.read_text()
    boot_s = float(m.group(1))
    assert 0.0 <= boot_s < 30.0
    print(f"\nwith-vcan: boot {boot_s:.2f} s, command {float(m.group(2)):.2f} s; 200 Hz round trip "
          f"median {res['rtt_median_ms']:.3f} ms, p99 {res['rtt_p99_ms']:.3f} ms, "
          f"max {res['rtt_max_ms']:.3f} ms over {res['n']}")


def test_failing_command_status_and_output(tmp_path: Path) -> None:
    r, _ = run(["sh", "-c", 'echo "out $PWD"; echo "err $HOME" >&2; '
                "ip link show vcan0 | grep -q UP || exit 99; "
                'case ":$PATH:" in *":/usr/sbin:"*) ;; *) exit 98 ;; esac; exit 7'], tmp_path)
    assert r.returncode == 7, r.stdout + r.stderr
    assert r.stdout == f"out {ROOT}\n"
    assert f"err {os.environ.get('HOME', '/root')}" in r.stderr
    assert not list(tmp_path.glob("with-vcan.*")), "temp dir not removed"


def test_timeout_stops_everything(tmp_path: Path) -> None:
    r, wall = run(["sleep", "300"], tmp_path, WITH_VCAN_TIMEOUT="8")
    assert r.returncode == 124, r.stdout + r.stderr
    assert 7.0 <= wall < 25.0
    time.sleep(0.5)
    assert _leftovers(str(tmp_path)) == []
    assert not list(tmp_path.glob("with-vcan.*"))
