"""Run inside host_bench/with-vcan by test_with_vcan.py: exercises vcan0 and writes JSON.

    python tests/python/vcan_probe.py OUT.json [N_ROUND_TRIPS]

1. candump -L vcan0 captures three frames sent by cansend (between two marker frames);
2. python-can's socketcan interface: a message sent on one Bus arrives on another;
3. a 200 Hz round trip: a python-can echo process (started here, stopped by its PID) answers
   every frame 0x100 with 0x101; the send -> answer times are recorded.
"""
from __future__ import annotations

import json
import os
import select
import statistics
import subprocess
import sys
import time

import can

ECHO = r"""
import can, sys
bus = can.Bus(interface="socketcan", channel="vcan0")
bus.set_filters([{"can_id": 0x100, "can_mask": 0x7FF}])
print("ready", flush=True)
while True:
    m = bus.recv(1.0)
    if m is not None:
        bus.send(can.Message(arbitration_id=0x101, is_extended_id=False, data=m.data))
"""


MARK_START, MARK_END = "7E0#01", "7E0#02"
#: how long a sent frame may wait for its answer before it counts as lost, s
ANSWER_LIMIT_S = 10.0


def lines_until(proc: subprocess.Popen, ending: str, poke, limit_s: float = 120.0) -> list[str]:
    """Lines of proc's stdout up to and including the first that ends with `ending`; `poke()` is
    called before each wait of 0.2 s (to send a marker again).  Raises after limit_s."""
    assert proc.stdout is not None
    fd = proc.stdout.fileno()
    buf, lines = b"", []
    deadline = time.monotonic() + limit_s
    while time.monotonic() < deadline:
        poke()
        ready, _, _ = select.select([fd], [], [], 0.2)
        if not ready:
            continue
        chunk = os.read(fd, 65536)
        if not chunk:
            break
        buf += chunk
        *done, buf = buf.split(b"\n")
        for raw in done:
            lines.append(raw.decode())
            if lines[-1].endswith(ending):
                return lines
    raise RuntimeError(f"candump did not show {ending!r} within {limit_s:.0f} s: {lines}")


def main() -> int:
    out_path = sys.argv[1]
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 400
    res: dict = {}

    # 1. candump / cansend.  No sleep decides when candump listens or has printed everything
    # (under QEMU's TCG on a loaded host half a second was not enough): a marker frame is sent
    # until candump shows it, the three frames follow, then an end marker, read back before
    # candump is stopped.  candump's output is line-buffered by stdbuf (a pipe would hold it).
    dump = subprocess.Popen(["stdbuf", "-oL", "candump", "-L", "vcan0"], stdout=subprocess.PIPE)
    lines: list[str] = []
    try:
        lines_until(dump, f"vcan0 {MARK_START}", lambda: subprocess.run(
            ["cansend", "vcan0", MARK_START], check=True))
        for frame in ("123#DEADBEEF", "5A1#0102", "7FF#0011223344556677"):
            subprocess.run(["cansend", "vcan0", frame], check=True)
        subprocess.run(["cansend", "vcan0", MARK_END], check=True)
        lines = lines_until(dump, f"vcan0 {MARK_END}", lambda: None)
    finally:
        dump.terminate()  # by PID: this Popen's own process
        dump.communicate(timeout=10)
    res["candump"] = [ln for ln in lines if not ln.endswith((MARK_START, MARK_END))]

    # 2. python-can round trip between two sockets
    with can.Bus(interface="socketcan", channel="vcan0") as a, \
            can.Bus(interface="socketcan", channel="vcan0") as b:
        sent = can.Message(arbitration_id=0x321, is_extended_id=False, data=bytes([1, 2, 3, 250]))
        a.send(sent)
        got = b.recv(ANSWER_LIMIT_S)
        res["pycan"] = None if got is None else {
            "id": got.arbitration_id, "data": got.data.hex(), "dlc": got.dlc,
            "ext": got.is_extended_id}

    # 3. 200 Hz round trip through an echo process
    echo = subprocess.Popen([sys.executable, "-c", ECHO], stdout=subprocess.PIPE, text=True)
    rtts: list[float] = []
    try:
        assert echo.stdout is not None and echo.stdout.readline().strip() == "ready"
        with can.Bus(interface="socketcan", channel="vcan0") as bus:
            bus.set_filters([{"can_id": 0x101, "can_mask": 0x7FF}])
            period = 1.0 / 200.0
            t0 = time.perf_counter()
            sent = 0
            for k in range(n):
                target = t0 + k * period
                while time.perf_counter() < target:
                    time.sleep(max(0.0, min(0.001, target - time.perf_counter())))
                data = k.to_bytes(4, "little")
                ts = time.perf_counter()
                bus.send(can.Message(arbitration_id=0x100, is_extended_id=False, data=data))
                sent += 1
                # an answer counts however late it comes (a user-mode or TCG guest on a loaded
                # host can stall for more than half a second); only ANSWER_LIMIT_S without it
                # makes it a missing one
                answered = False
                while not answered and (left := ts + ANSWER_LIMIT_S - time.perf_counter()) > 0.0:
                    m = bus.recv(left)
                    if m is None:
                        break
                    if bytes(m.data) == data:
                        rtts.append(time.perf_counter() - ts)
                        answered = True
                if not answered:
                    # the echo is gone or the bus dead: every further frame would wait the
                    # whole limit too, and the run would end at with-vcan's limit, not here
                    res["first_lost"] = k
                    break
            # the rate of the frames sent (fewer than n when the stream ended at a lost one)
            res["rate_hz"] = sent / (time.perf_counter() - t0)
    finally:
        echo.terminate()  # by PID
        echo.wait(timeout=10)
    res["n"] = n
    res["answered"] = len(rtts)
    if rtts:
        s = sorted(rtts)
        res["rtt_median_ms"] = statistics.median(s) * 1e3
        res["rtt_p99_ms"] = s[min(len(s) - 1, int(0.99 * len(s)))] * 1e3
        res["rtt_max_ms"] = s[-1] * 1e3
    with open(out_path, "w") as f:
        json.dump(res, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
