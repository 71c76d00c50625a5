"""The node's rules for a configuration transfer (nte_node.h SETTINGS; nte_node.c
nte_node_on_setting), as the bench's mirror follows them: which Setting frame is taken, which
breaks the transfer off (counted as setting_refused), when the configurations hold a transfer
not yet applied (model changes and resets then refused).

The mirror runs presets, so a transfer the node would apply is refused here with ValueError:
compare such a run with `nte-node --replay --config FILE` (tests/python/test_node_settings.py).
"""
from __future__ import annotations

import math

from reference_py.bus.dbc import NteDatabase

from .settings_file import FRAME_ITEMS_LAST, item_numbers, value_ok


def whole(value: float, lo: int, hi: int) -> bool:
    """A whole number in lo..hi (nte_node.c nte_node_whole)."""
    return lo <= value <= hi and float(int(value)) == value


class SettingTransfer:
    """One node's transfer state: open, unapplied, the count announced, the items taken."""

    def __init__(self, db: NteDatabase) -> None:
        self.n = item_numbers(db)
        self.open = False
        self.unapplied = False
        self.announced = 0
        self.seen: set[int] = set()

    def frame_ok(self, item: int, value: float) -> bool:
        """The frame layer's check (nte_frames_decode_setting): an item and a finite value."""
        return (item <= FRAME_ITEMS_LAST or item == self.n["commit"]) and math.isfinite(value)

    def lost(self) -> None:
        """A Setting frame that failed its checks: an item may be missing."""
        self.open = False

    def take(self, item: int, value: float, skipped: bool, in_tissue: bool) -> bool:
        """A Setting frame decoded whole; False when it is refused (the transfer breaks off)."""
        n = self.n
        if item == n["begin"]:
            if not (whole(value, 1, FRAME_ITEMS_LAST) and not in_tissue):
                return self._refuse()
            self.open = self.unapplied = True
            self.announced = int(value)
            self.seen = set()
            return True
        if not self.open or skipped:
            return self._refuse()
        if item == n["commit"]:
            self.open = False
            if (whole(value, 0, 255) and int(value) == self.announced
                    and len(self.seen) == self.announced and n["model"] in self.seen
                    and not in_tissue):
                raise ValueError("the node mirror does not follow a configuration sent over "
                                 "the bus (Setting frames): compare such a run with nte-node "
                                 "--replay --config FILE")
            return False
        if item in self.seen or len(self.seen) >= self.announced or not value_ok(item, value, n):
            return self._refuse()
        self.seen.add(item)
        return True

    def _refuse(self) -> bool:
        self.open = False
        return False


__all__ = ["SettingTransfer", "whole"]
