"""Bench replay: send a scenario's depth and force samples to the node over CAN, record the bus.

Scenario CSV (read by reference_py.tools.csvio, the tools' one reader), one row per depth
sample, header required: t_s, depth_mm, force_n, and optionally velocity_mm_s (else central
differences of depth).  ``force_n`` may be empty on rows without a force sample (e.g. 1 kHz
depth, 200 Hz force); ``--force-every N`` keeps only every N-th force sample. Each row becomes
a Depth frame and, if it has a force, a Force frame, both stamped with SensorTime = round(t_s / 100 us) mod 2^16,
sent at start + t_s / speed (speed 0 = as fast as possible: the node must use the frames' own
timestamps, never arrival times). Everything the bus delivers to this process is written with
python-can's writers (CSV and candump -L log); the frames sent are written too, marked "T".

    nte-bench send scenario.csv --interface socketcan --channel vcan0 \\
        --record-csv run.csv --record-log run.log

``nte-bench replay`` sends the same scenario resampled instead (scenario_frames): depth frames at
a fixed rate, interpolated from the rows, force frames at the rows that have one, on the 100 us
tick grid, values outside a signal's DBC range clipped and counted rather than refused.

Both streams come from one encoder (FrameEncoder: SensorTime, E2E, the range rule) and leave
by one pacing rule (paced), which nte-bench replay's sender (send_retrying) shares with send.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, NamedTuple, Sequence

import can
import numpy as np

from reference_py.bus.dbc import TICK_S, TICK_WRAP, NteDatabase, seconds_to_ticks
from reference_py.config import EstimatorConfig
from reference_py.tools.csvio import Units, left_out_note, read_trial

#: the envelope's depth (tests/python/test_envelope.py: the Depth signal's range is the same)
DEPTH_MAX_MM = EstimatorConfig.depth_max_mm
DEPTH_SLACK_MM = 1e-6  #: depths within this of the range are clamped, not rejected


@dataclass
class ScenarioRow:
    t_s: float
    depth_mm: float
    velocity_mm_s: float
    force_n: float | None


def read_scenario(path: str | Path, units: Units | None = None,
                  note: Callable[[str], None] | None = None) -> list[ScenarioRow]:
    """Read a scenario CSV with the tools' one reader (reference_py.tools.csvio: increasing
    t_s, finite values, velocity_mm_s optional, force_n empty where no force sample was
    taken), converted and checked by ``units`` when given (csvio.Units).  The rows the reader
    left out (a missing depth or velocity, a repeated time) are told to ``note`` in the
    estimating tools' words (csvio.left_out_note), so the bench says what it does not send."""
    trial = read_trial(path, sparse=("force_n",), units=units)
    said = left_out_note(trial)
    if said is not None and note is not None:
        note(said)
    rows: list[ScenarioRow] = []
    for t, d, v, fo in zip(trial.t_s, trial.depth_mm, trial.velocity_mm_s, trial.force_n):
        d = float(d)
        if -DEPTH_SLACK_MM <= d < 0.0:
            d = 0.0
        if DEPTH_MAX_MM < d <= DEPTH_MAX_MM + DEPTH_SLACK_MM:
            d = DEPTH_MAX_MM
        rows.append(ScenarioRow(float(t), d, float(v), None if math.isnan(fo) else float(fo)))
    return rows


class ScheduledFrame(NamedTuple):
    """A frame and its scenario time: the stream element every sender, writer and fault
    injector of the bench takes, as (t_s, message)."""
    t_s: float
    message: can.Message


class FrameEncoder:
    """The bench's one encoder of Depth and Force frames: each frame E2E protected (one alive
    counter per message, in the order asked for) and stamped with SensorTime = ticks mod 2^16.
    ``clipped`` chooses what a value outside its signal's DBC range does: None, it reaches
    the codec, which refuses it (cantools' EncodeError); a dict, it is clipped to the range
    and counted there by signal name."""

    def __init__(self, db: NteDatabase, clipped: dict[str, int] | None = None) -> None:
        self.tx = db.sender()
        self.clipped = clipped
        self.ranges = {sig: db.signal_range(msg, sig) for msg, sig in
                       (("Depth", "Depth"), ("Depth", "Velocity"), ("Force", "Force"))}

    def _value(self, sig: str, x: float) -> float:
        lo, hi = self.ranges[sig]
        if self.clipped is None or lo <= x <= hi:
            return x
        self.clipped[sig] = self.clipped.get(sig, 0) + 1
        return min(max(x, lo), hi)

    def depth(self, ticks: int, depth_mm: float, velocity_mm_s: float) -> can.Message:
        """A Depth frame at sensor time ``ticks`` (100 us ticks, not yet wrapped)."""
        return self.tx.message("Depth", {"Depth": self._value("Depth", depth_mm),
                                         "Velocity": self._value("Velocity", velocity_mm_s),
                                         "SensorTime": (ticks % TICK_WRAP) * TICK_S})

    def force(self, ticks: int, force_n: float) -> can.Message:
        """A Force frame at sensor time ``ticks`` (100 us ticks, not yet wrapped)."""
        return self.tx.message("Force", {"Force": self._value("Force", force_n),
                                         "SensorTime": (ticks % TICK_WRAP) * TICK_S})


def schedule(rows: Sequence[ScenarioRow], db: NteDatabase, force_every: int = 1) -> list[ScheduledFrame]:
    """The rows as they are (nte-bench send): a Depth frame per row, a Force frame for every
    force_every-th row that has a force, at the row's time; within a row depth first.
    Raises ValueError, naming the row, on a value outside its DBC range."""
    enc = FrameEncoder(db)
    out: list[ScheduledFrame] = []
    n_force = 0
    for i, r in enumerate(rows):
        ticks = seconds_to_ticks(r.t_s)
        try:
            out.append(ScheduledFrame(r.t_s, enc.depth(ticks, r.depth_mm, r.velocity_mm_s)))
            if r.force_n is not None:
                if n_force % force_every == 0:
                    out.append(ScheduledFrame(r.t_s, enc.force(ticks, r.force_n)))
                n_force += 1
        except Exception as exc:  # cantools raises its own EncodeError for range errors
            raise ValueError(f"row {i}: t_s={r.t_s}: {exc}") from None
    return out


def scenario_frames(csv_path: str, db: NteDatabase, depth_rate_hz: float,
                    clipped: dict[str, int] | None = None, units: Units | None = None,
                    note: Callable[[str], None] | None = None) -> list[ScheduledFrame]:
    """The scenario CSV resampled (nte-bench replay): depth at depth_rate_hz (interpolated),
    force at the CSV rows that have one; at equal times depth first.  Times are on the 100 us
    tick grid.  A value outside its signal's DBC range is clipped to the range and counted in
    ``clipped`` (by signal name) when a dict is given; ``units`` converts and checks the CSV
    (csvio) and tells ``note`` what the reader left out (read_scenario)."""
    rows = read_scenario(csv_path, units, note)
    t = np.array([r.t_s for r in rows])
    d = np.array([r.depth_mm for r in rows])
    v = np.array([r.velocity_mm_s for r in rows])
    enc = FrameEncoder(db, clipped if clipped is not None else {})
    step_ticks = max(1, int(round(1.0 / depth_rate_hz / TICK_S)))
    t0 = int(round(t[0] / TICK_S))
    t1 = int(round(t[-1] / TICK_S))
    events: list[tuple[int, int, float, float]] = []   # (ticks, kind 0 depth / 1 force, a, b)
    for k in range(t0, t1 + 1, step_ticks):
        ts = k * TICK_S
        events.append((k, 0, float(np.interp(ts, t, d)), float(np.interp(ts, t, v))))
    for r in rows:
        if r.force_n is not None:
            events.append((int(round(r.t_s / TICK_S)), 1, r.force_n, 0.0))
    events.sort(key=lambda e: (e[0], e[1]))
    return [ScheduledFrame(k * TICK_S, enc.depth(k, a, b) if kind == 0 else enc.force(k, a))
            for k, kind, a, b in events]


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


def paced(frames: Sequence[tuple[float, can.Message]], speed: float,
          emit: Callable[[can.Message], None], progress: bool = False) -> float:
    """The bench's one pacing rule: emit(message) for each frame at start + (t_s - t_s of the
    first frame) / speed (speed <= 0: back to back), never early; a frame due while an earlier
    one was late goes at once, so the schedule catches up after a stall.  It sleeps in steps
    of at most 2 ms and only yields (sleep(0)) in the last 0.5 ms before a frame is due, so
    as not to sleep past it.  Returns the worst lateness, s.  ``progress`` shows a tqdm bar
    (on a terminal only).  An empty stream sends nothing."""
    t_first = frames[0][0] if frames else 0.0
    if progress:
        from tqdm import tqdm
        frames = tqdm(frames, desc="replay", unit="frame", disable=None, leave=False)
    start = time.perf_counter()
    worst = 0.0
    for t, m in frames:
        if speed > 0:
            target = start + (t - t_first) / speed
            while True:
                now = time.perf_counter()
                if now >= target:
                    break
                time.sleep(min(target - now, 0.002) if target - now > 0.0005 else 0)
            worst = max(worst, time.perf_counter() - target)
        emit(m)
    return worst


def send_retrying(bus: can.BusABC, m: can.Message) -> None:
    """Send m's id and data as a plain frame (a remote or FD frame of a log goes as a classic
    data frame, the log's channel not used), retrying for up to 0.1 s while the TX queue is
    full (ENOBUFS: CanOperationError); a frame the queue never takes is left out."""
    for _ in range(200):
        try:
            bus.send(can.Message(arbitration_id=m.arbitration_id, data=m.data,
                                 is_extended_id=m.is_extended_id))
            return
        except can.CanOperationError:
            time.sleep(0.0005)


def replay(bus: can.BusABC, frames: Iterable[tuple[float, can.Message]], *, speed: float = 1.0,
           writers: Sequence[can.Listener] = (), tail_s: float = 0.2,
           db: NteDatabase | None = None) -> ReplayResult:
    """Send `frames` on `bus` paced by `paced` (speed <= 0: back to back), passing every
    received message and every sent one to `writers`. Keeps receiving for `tail_s` after the
    last frame. The caller owns the bus and closes the writers."""
    frames = list(frames)
    counter = _Received(writers)
    notifier = can.Notifier(bus, [counter])
    res = ReplayResult()

    def emit(msg: can.Message) -> None:
        msg.timestamp = time.time()
        bus.send(msg)
        counter.write(can.Message(timestamp=msg.timestamp, arbitration_id=msg.arbitration_id,
                                  is_extended_id=False, data=msg.data, is_rx=False,
                                  channel=msg.channel))
        res.sent += 1
        if db is not None:
            name = db.name_of(msg.arbitration_id) or "?"
            res.sent_by_name[name] = res.sent_by_name.get(name, 0) + 1

    start = time.perf_counter()
    try:
        res.max_late_s = paced(frames, speed, emit)
        time.sleep(max(tail_s, 0.0))
    finally:
        notifier.stop()
    res.duration_s = time.perf_counter() - start
    res.received = counter.n
    return res
