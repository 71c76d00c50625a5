"""Frames played onto vcan keep their order only when their sender stays on one CPU
(host_bench/one_cpu.sh says why): the bench's players run pinned to one."""
from __future__ import annotations

import os


def pin_to_one_cpu() -> None:
    """Pin the calling thread to the first CPU it may use; a process it starts afterwards
    (canplayer) inherits the pin.  Where the platform has no affinity calls, nothing."""
    try:
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    except (AttributeError, OSError):
        pass


__all__ = ["pin_to_one_cpu"]
