"""Run inside host_bench/with-vcan by test_bench_replay.py.

    python tests/python/replay_probe.py SCENARIO.csv OUTDIR SPEED FRAMES

Starts candump -L vcan0 (capturing to OUTDIR/candump.log; it exits by itself after FRAMES
frames, the replay's and the heartbeats: under TCG it lags the bus by seconds, and stopping it
when the replay ends left frames still queued in its socket unwritten), runs the replay engine
(nte-bench send, as python -m host_bench.cli send) on the scenario with --record-csv/--record-log into OUTDIR, and
meanwhile plays a stand-in for the node: five Heartbeat frames (E2E protected, from
reference_py.bus.dbc) sent 0.2 s apart, which the replay must record. Both child processes are
stopped by their own PIDs.
"""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import can

from reference_py.bus.dbc import NteDatabase


def main() -> int:
    scenario, outdir, speed, frames = sys.argv[1], Path(sys.argv[2]), sys.argv[3], sys.argv[4]
    dump_file = open(outdir / "candump.log", "w")
    dump = subprocess.Popen(["candump", "-L", "-n", frames, "-r", "16000000", "vcan0"],
                            stdout=dump_file)
    replay = None
    try:
        time.sleep(0.3)
        replay = subprocess.Popen(
            [sys.executable, "-m", "host_bench.cli", "send", scenario, "--interface", "socketcan",
             "--channel", "vcan0", "--speed", speed, "--tail", "0.5",
             "--record-csv", str(outdir / "record.csv"), "--record-log", str(outdir / "record.log")],
            stdout=open(outdir / "replay.out", "w"), stderr=subprocess.STDOUT)
        db = NteDatabase()
        tx = db.sender()
        with can.Bus(interface="socketcan", channel="vcan0") as bus:
            # wait until the replay's first frame is on the bus, then send the heartbeats
            bus.set_filters([{"can_id": db.frame_id("Depth"), "can_mask": 0x7FF}])
            if bus.recv(600.0) is None:   # the sender imports numpy first: slow under TCG
                print("no depth frame seen", file=sys.stderr)
                return 3
            for k in range(5):
                bus.send(tx.message("Heartbeat", {
                    "NodeState": 1, "ActiveModel": 1, "ActiveEstimator": 0, "Uptime": 10.0 + k,
                    "E2eErrors": 0, "RangeErrors": 0, "StepTime": 0.000734}))
                time.sleep(0.2)
        rc = replay.wait(timeout=120)
        try:
            dump.wait(timeout=300)   # until it has written all FRAMES
        except subprocess.TimeoutExpired:
            print(f"candump did not see all {frames} frames within 300 s", file=sys.stderr)
            return 4
        return rc
    finally:
        if replay is not None and replay.poll() is None:
            replay.kill()  # by PID
            replay.wait()
        dump.terminate()  # by PID
        dump.wait(timeout=10)
        dump_file.close()


if __name__ == "__main__":
    sys.exit(main())
