"""Faults injected into a stream of bus frames (lists of (t_s, can.Message) in send order).

burst(): a seeded burst of foreign frames on the node's input ids -- random lengths and data
(almost all fail the CRC) and frames crafted to pass the CRC with a sensor time far ahead of or
behind their stream, carrying the alive counter the next genuine frame of that stream will have
(the worst case for the counter check).  The genuine frames are never altered or removed, so a
node that cannot be blinded publishes the same estimates with and without the burst.
"""
from __future__ import annotations

from dataclasses import dataclass

import can
import numpy as np

from .dbc import TICK_S, NteDatabase


@dataclass
class BurstReport:
    random_frames: int = 0
    crafted_forward: int = 0
    crafted_backward: int = 0

    @property
    def total(self) -> int:
        return self.random_frames + self.crafted_forward + self.crafted_backward


def _sensor_ticks(db: NteDatabase, name: str, m: can.Message) -> int:
    return int(db.decode_unchecked(name, bytes(m.data))["SensorTime"] / TICK_S + 0.5) % 65536


def burst(frames: list[tuple[float, can.Message]], db: NteDatabase, seed: int,
          every_s: float = 0.5, size: int = 12, min_jump_s: float = 0.05,
          max_jump_s: float = 3.0) -> tuple[list[tuple[float, can.Message]], BurstReport]:
    """`frames` with a burst of `size` foreign frames after the first genuine frame at or after
    every `every_s` seconds (from the second burst period on).  In each burst one depth and one
    force frame are crafted (valid CRC, sensor time moved by +-min_jump_s..max_jump_s, counter
    of the next genuine frame of the stream); the rest are random (id: Depth or Force; length
    0..8; random bytes).  Deterministic for a seed."""
    rng = np.random.default_rng(seed)
    ids = {db.frame_id("Depth"): "Depth", db.frame_id("Force"): "Force"}
    rep = BurstReport()
    # the counter of the next genuine frame of each stream, from every position
    next_counter: list[dict[str, int]] = [{} for _ in frames]
    upcoming: dict[str, int] = {}
    for i in range(len(frames) - 1, -1, -1):
        name = ids.get(frames[i][1].arbitration_id)
        if name is not None:
            upcoming = dict(upcoming, **{name: frames[i][1].data[1] & 0x0F})
        next_counter[i] = upcoming
    last_ticks: dict[str, int] = {}
    out: list[tuple[float, can.Message]] = []
    t_next = 2 * every_s
    for i, (t, m) in enumerate(frames):
        out.append((t, m))
        name = ids.get(m.arbitration_id)
        if name is not None:
            last_ticks[name] = _sensor_ticks(db, name, m)
        if t < t_next or len(last_ticks) < 2 or i + 1 >= len(frames):
            continue
        t_next += every_s
        nxt = next_counter[i + 1]
        crafted = [n for n in ("Depth", "Force") if n in nxt]
        slots = sorted(rng.choice(size, size=len(crafted), replace=False).tolist())
        for k in range(size):
            if slots and k == slots[0]:
                slots.pop(0)
                cname = crafted.pop(0)
                jump = int(rng.uniform(min_jump_s, max_jump_s) / TICK_S)
                forward = bool(rng.integers(2))
                ticks = (last_ticks[cname] + (jump if forward else -jump)) % 65536
                sig = {"SensorTime": ticks * TICK_S}
                if cname == "Depth":
                    sig.update(Depth=float(rng.uniform(0.0, 400.0)),
                               Velocity=float(rng.uniform(-400.0, 400.0)))
                else:
                    sig.update(Force=float(rng.uniform(-40.0, 40.0)))
                data = db.encode(cname, sig, nxt[cname])
                out.append((t, can.Message(arbitration_id=db.frame_id(cname), data=data,
                                           is_extended_id=False, timestamp=t)))
                if forward:
                    rep.crafted_forward += 1
                else:
                    rep.crafted_backward += 1
                continue
            cid = db.frame_id("Depth" if rng.integers(2) == 0 else "Force")
            n = int(rng.integers(0, 9))
            data = bytes(rng.integers(0, 256, size=n, dtype=np.uint8).tolist())
            out.append((t, can.Message(arbitration_id=cid, data=data, dlc=n,
                                       is_extended_id=False, timestamp=t)))
            rep.random_frames += 1
    return out, rep


def clock_jump(frames: list[tuple[float, can.Message]], db: NteDatabase, at_s: float,
               jump_s: float) -> list[tuple[float, can.Message]]:
    """`frames` with the sensor clock moved by jump_s (either sign) from at_s on: every Depth
    and Force frame from then carries SensorTime + jump_s (same counter, CRC recomputed)."""
    ids = {db.frame_id("Depth"): "Depth", db.frame_id("Force"): "Force"}
    shift = int(round(jump_s / TICK_S))
    out = []
    for t, m in frames:
        name = ids.get(m.arbitration_id)
        if name is None or t < at_s:
            out.append((t, m))
            continue
        sig = db.decode_unchecked(name, bytes(m.data))
        sig["SensorTime"] = ((_sensor_ticks(db, name, m) + shift) % 65536) * TICK_S
        sig.pop("Crc", None)
        sig.pop("Counter", None)
        data = db.encode(name, sig, m.data[1] & 0x0F)
        out.append((t, can.Message(arbitration_id=m.arbitration_id, data=data,
                                   is_extended_id=False, timestamp=t)))
    return out
