"""A stream of bus frames written as a candump log.

A stream is a list of (t_s, can.Message) in send order, t_s the scenario time; the log is what
can-utils' canplayer replays in real time and what ``nte-node --replay`` reads, so the bench, its
tests and the fault table hand the node their frames through it.
"""
from __future__ import annotations

from pathlib import Path

import can


def write_candump(path: Path, frames: list[tuple[float, can.Message]], channel: str,
                  speed: float, start: float = 1_000_000.0) -> None:
    """candump -l format (python-can's CanutilsLogWriter, frames marked T for sent), times
    scaled by 1/speed (canplayer replays them in real time)."""
    writer = can.CanutilsLogWriter(str(path), channel=channel)
    try:
        for t, m in frames:
            writer.on_message_received(can.Message(
                timestamp=start + t / speed, arbitration_id=m.arbitration_id,
                is_extended_id=m.is_extended_id, data=bytes(m.data), is_rx=False,
                channel=channel))
    finally:
        writer.stop()
