"""Bench replay: send a scenario's depth and force samples to the node over CAN, record the bus.

Scenario CSV, one row per depth sample, header required:
    t_s, depth_mm, velocity_mm_s, force_n
``force_n`` may be empty (or nan) on rows without a force sample (e.g. 1 kHz depth, 200 Hz
force); ``--force-every N`` keeps only every N-th force sample. Each row becomes a Depth frame
and, if it has a force, a Force frame, both stamped with SensorTime = round(t_s / 100 us) mod 2^16,
sent at start + t_s / speed (speed 0 = as fast as possible: the node must use the frames' own
timestamps, never arrival times). Everything the bus delivers to this process is written with
python-can's writers (CSV and candump -L log); the frames sent are written too, marked "T".

    python -m host_bench.replay scenario.csv --interface socketcan --channel vcan0 \\
        --record-csv run.csv --record-log run.log
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

import can

from .dbc import TICK_S, NteDatabase, seconds_to_ticks

DEPTH_MAX_MM = 500.0
DEPTH_SLACK_MM = 1e-6  #: depths within this of the range are clamped, not rejected


@dataclass
class ScenarioRow:
    t_s: float
    depth_mm: float
    velocity_mm_s: float
    force_n: float | None


def read_scenario(path: str | Path) -> list[ScenarioRow]:
    """Read and validate a scenario CSV (strictly increasing t_s, finite values)."""
    rows: list[ScenarioRow] = []
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        need = {"t_s", "depth_mm", "velocity_mm_s", "force_n"}
        if reader.fieldnames is None or not need <= set(reader.fieldnames):
            raise ValueError(f"{path}: header must contain {sorted(need)}")
        for line, rec in enumerate(reader, start=2):
            try:
                t = float(rec["t_s"])
                d = float(rec["depth_mm"])
                v = float(rec["velocity_mm_s"])
                fs = (rec["force_n"] or "").strip()
                fo = float(fs) if fs else None
            except ValueError as exc:
                raise ValueError(f"{path}:{line}: {exc}") from None
            if fo is not None and math.isnan(fo):
                fo = None
            if not all(math.isfinite(x) for x in (t, d, v)) or (fo is not None and not math.isfinite(fo)):
                raise ValueError(f"{path}:{line}: non-finite value")
            if rows and t <= rows[-1].t_s:
                raise ValueError(f"{path}:{line}: t_s must increase")
            if -DEPTH_SLACK_MM <= d < 0.0:
                d = 0.0
            if DEPTH_MAX_MM < d <= DEPTH_MAX_MM + DEPTH_SLACK_MM:
                d = DEPTH_MAX_MM
            rows.append(ScenarioRow(t, d, v, fo))
    if not rows:
        raise ValueError(f"{path}: no rows")
    return rows


@dataclass
class ScheduledFrame:
    t_s: float
    message: can.Message


def schedule(rows: Sequence[ScenarioRow], db: NteDatabase, force_every: int = 1) -> list[ScheduledFrame]:
    """Encode every frame (with E2E) in sending order: at equal times depth before force.
    Raises ValueError on a value outside its DBC range."""
    tx = db.sender()
    out: list[ScheduledFrame] = []
    n_force = 0
    for i, r in enumerate(rows):
        ticks = seconds_to_ticks(r.t_s)
        try:
            out.append(ScheduledFrame(r.t_s, tx.message("Depth", {
                "Depth": r.depth_mm, "Velocity": r.velocity_mm_s, "SensorTime": ticks * TICK_S})))
            if r.force_n is not None:
                if n_force % force_every == 0:
                    out.append(ScheduledFrame(r.t_s, tx.message("Force", {
                        "Force": r.force_n, "SensorTime": ticks * TICK_S})))
                n_force += 1
        except Exception as exc:  # cantools raises its own EncodeError for range errors
            raise ValueError(f"row {i}: t_s={r.t_s}: {exc}") from None
    return out


@dataclass
class ReplayResult:
    sent: int = 0
    received: int = 0
    duration_s: float = 0.0
    max_late_s: float = 0.0  #: worst lateness of a send against its schedule
    sent_by_name: dict[str, int] = field(default_factory=dict)


class _Received(can.Listener):
    """Counts received messages and passes them on marked as received (is_rx = True): on a vcan
    or any frame looped back on this host, python-can's socketcan reports is_rx = False (the
    kernel flags locally originated frames), which would make the records ambiguous; this bus
    does not receive its own frames, so everything arriving here was sent by someone else."""

    def __init__(self, writers: Sequence[can.Listener]) -> None:
        self.n = 0
        self.writers = list(writers)
        self.lock = threading.Lock()  # the sender thread writes its frames to the same writers

    def on_message_received(self, msg: can.Message) -> None:
        msg.is_rx = True
        self.write(msg)
        self.n += 1

    def write(self, msg: can.Message) -> None:
        with self.lock:
            for w in self.writers:
                w.on_message_received(msg)


def replay(bus: can.BusABC, frames: Iterable[ScheduledFrame], *, speed: float = 1.0,
           writers: Sequence[can.Listener] = (), tail_s: float = 0.2,
           db: NteDatabase | None = None) -> ReplayResult:
    """Send `frames` on `bus` at t_s / speed after the start (speed <= 0: back to back), passing
    every received message and every sent one to `writers`. Keeps receiving for `tail_s` after
    the last frame. The caller owns the bus and closes the writers."""
    frames = list(frames)
    counter = _Received(writers)
    notifier = can.Notifier(bus, [counter])
    res = ReplayResult()
    t0_sched = frames[0].t_s if frames else 0.0
    start = time.perf_counter()
    try:
        for fr in frames:
            if speed > 0:
                target = start + (fr.t_s - t0_sched) / speed
                while True:
                    now = time.perf_counter()
                    if now >= target:
                        break
                    time.sleep(min(target - now, 0.002) if target - now > 0.0005 else 0)
                res.max_late_s = max(res.max_late_s, time.perf_counter() - target)
            msg = fr.message
            msg.timestamp = time.time()
            bus.send(msg)
            sent = can.Message(timestamp=msg.timestamp, arbitration_id=msg.arbitration_id,
                               is_extended_id=False, data=msg.data, is_rx=False,
                               channel=msg.channel)
            counter.write(sent)
            res.sent += 1
            if db is not None:
                name = db.name_of(msg.arbitration_id) or "?"
                res.sent_by_name[name] = res.sent_by_name.get(name, 0) + 1
        time.sleep(max(tail_s, 0.0))
    finally:
        notifier.stop()
    res.duration_s = time.perf_counter() - start
    res.received = counter.n
    return res


def open_bus(interface: str, channel: str, bitrate: int = 500000) -> can.BusABC:
    if interface == "socketcan":
        return can.Bus(interface="socketcan", channel=channel)
    if interface == "slcan":
        return can.Bus(interface="slcan", channel=channel, bitrate=bitrate, sleep_after_open=0)
    raise ValueError(f"unsupported interface {interface!r} (socketcan or slcan)")


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m host_bench.replay",
        description="Replay a scenario CSV (t_s, depth_mm, velocity_mm_s, force_n) as Depth and "
                    "Force frames of firmware/can/nte.dbc (E2E protected) at their timestamps, "
                    "recording everything received.",
        epilog="Exit status: 0 on success, 2 on a bad scenario or argument.")
    p.add_argument("scenario", help="scenario CSV file")
    p.add_argument("--interface", default="socketcan", choices=("socketcan", "slcan"),
                   help="python-can interface (default socketcan)")
    p.add_argument("--channel", default="vcan0",
                   help="socketcan interface name, or slcan serial port / pyserial URL "
                        "such as socket://127.0.0.1:PORT (default vcan0)")
    p.add_argument("--bitrate", type=int, default=500000, help="slcan bit rate (default 500000)")
    p.add_argument("--base-id", type=lambda s: int(s, 0), default=None,
                   help="base CAN id (default: the DBC's NteBaseId, 0x200)")
    p.add_argument("--speed", type=float, default=1.0,
                   help="time scale: 1 real time, 0.5 half speed, 0 as fast as possible")
    p.add_argument("--force-every", type=int, default=1, metavar="N",
                   help="send every N-th force sample only (default 1)")
    p.add_argument("--tail", type=float, default=0.2, metavar="S",
                   help="keep recording S seconds after the last frame (default 0.2)")
    p.add_argument("--record-csv", metavar="FILE", help="write all frames with can.CSVWriter")
    p.add_argument("--record-log", metavar="FILE",
                   help="write all frames in candump -L format (can.CanutilsLogWriter)")
    a = p.parse_args(argv)
    if a.force_every < 1:
        p.error("--force-every must be >= 1")
    try:
        db = NteDatabase(base_id=a.base_id)
        frames = schedule(read_scenario(a.scenario), db, force_every=a.force_every)
    except (OSError, ValueError) as exc:
        print(f"replay: {exc}", file=sys.stderr)
        return 2
    writers: list[can.Listener] = []
    if a.record_csv:
        writers.append(can.CSVWriter(a.record_csv))
    if a.record_log:
        writers.append(can.CanutilsLogWriter(a.record_log, channel=a.channel))
    bus = open_bus(a.interface, a.channel, a.bitrate)
    try:
        res = replay(bus, frames, speed=a.speed, writers=writers, tail_s=a.tail, db=db)
    finally:
        bus.shutdown()
        for w in writers:
            w.stop()
    print(f"replay: sent {res.sent} frames ({', '.join(f'{k} {v}' for k, v in sorted(res.sent_by_name.items()))}) "
          f"in {res.duration_s:.3f} s, received {res.received}, worst lateness "
          f"{res.max_late_s * 1e3:.2f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
