"""The force sensor's failures, injected into a stream of bus frames (lists of (t_s,
can.Message) in send order): SensorFault flagged on Force frames, Force frames lost, and
Commands switching the node's force source.  Used by `nte-bench replay`'s options
(host_bench/cli.py) and the fault table (host_bench/faults.py).
"""
from __future__ import annotations

import can

from reference_py.bus.dbc import NteDatabase


def _in_spans(t: float, spans) -> bool:
    return any(a <= t < b for a, b in spans)


def sensor_fault(frames: list[tuple[float, can.Message]], db: NteDatabase,
                 spans: list[tuple[float, float]], force: float | None = None
                 ) -> list[tuple[float, can.Message]]:
    """`frames` with SensorFault = 1 on every Force frame sent in one of the [t0, t1) spans (s):
    the sensor's driver flags its samples bad (same counter, CRC recomputed); ``force`` also
    replaces their value (a stuck or saturated reading), else it is kept."""
    frc = db.frame_id("Force")
    out = []
    for t, m in frames:
        if m.arbitration_id == frc and _in_spans(t, spans):
            m = reencode(db, "Force", m, SensorFault=1,
                         **({} if force is None else {"Force": force}))
        out.append((t, m))
    return out


def sensor_lost(frames: list[tuple[float, can.Message]], db: NteDatabase,
                spans: list[tuple[float, float]]) -> list[tuple[float, can.Message]]:
    """`frames` without the Force frames sent in the [t0, t1) spans (s): a lost sensor (the
    Depth frames go on).  The frames after a span keep their counters: the node counts the
    gap as frames lost."""
    frc = db.frame_id("Force")
    return [(t, m) for t, m in frames if not (m.arbitration_id == frc and _in_spans(t, spans))]


FORCE_SOURCES = {"keep": 0, "sensor": 1, "model": 2}


def force_source_commands(frames: list[tuple[float, can.Message]], db: NteDatabase,
                          commands: list[tuple[float, str]]) -> list[tuple[float, can.Message]]:
    """`frames` with a Command frame carrying ForceSource (``sensor`` or ``model``) inserted at
    each (t_s, source), before the first frame at or after t_s; alive counters 0, 1, ... in time
    order (the node wants each command's counter to follow the previous one's).  The node's
    rate limit (100 ms of its clock by default) applies between commands."""
    tx = db.sender()
    cmds = sorted(commands)
    out: list[tuple[float, can.Message]] = []
    i = 0
    for t, m in frames:
        while i < len(cmds) and cmds[i][0] <= t:
            tc, src = cmds[i]
            out.append((tc, tx.message("Command", {"ForceSource": FORCE_SOURCES[src]},
                                       timestamp=tc)))
            i += 1
        out.append((t, m))
    for tc, src in cmds[i:]:
        out.append((tc, tx.message("Command", {"ForceSource": FORCE_SOURCES[src]},
                                   timestamp=tc)))
    return out


def reencode(db: NteDatabase, name: str, m: can.Message, **changes) -> can.Message:
    """`m` (a frame of message `name`) with some signals changed: same alive counter, CRC
    recomputed."""
    sig = db.decode_unchecked(name, bytes(m.data))
    sig.pop("Crc", None)
    sig.pop("Counter", None)
    sig.update(changes)
    return can.Message(arbitration_id=m.arbitration_id, data=db.encode(name, sig, m.data[1] & 0x0F),
                       is_extended_id=False, timestamp=m.timestamp)
