"""A configuration file (``--config FILE``) as the Setting frames of one transfer
(firmware/can/nte.dbc Setting; firmware/node/nte_node.h SETTINGS).

The twin of firmware/port/linux/nte_settings_file.c: the same value items in the same order,
rounded to float32 as the frame carries them, so a node configured by ``nte-bench settings
FILE`` and one started with ``nte-node --config FILE`` run alike, bit for bit
(tests/python/test_node_settings.py compares the two lists and the two nodes' outputs).
Item numbers come from the DBC's value table of Setting.Item; the layer sets' items follow
``layer_sets``: set k, field j at ``layer_sets + 1 + k * (1 + len(LAYER_SET_NAMES)) + j``.
"""
from __future__ import annotations

import can
import numpy as np

from reference_py.bus.dbc import E2ESender, NteDatabase
from reference_py.layers import LAYER_MAX
from reference_py.params import LAYER_SET_NAMES, PARAM_NAMES, RELAX_NAMES
from reference_py.tools.estconfig import FileConfig

#: layer sets the Setting frame can address (the DBC's Item comment, set k = 0..7;
#: nte_frames.h NTE_FRAMES_SETTING_LAYER_SETS_MAX) and the last value item that makes
FRAME_LAYER_SETS = 8
FRAME_ITEMS_LAST = 19 + (1 + len(LAYER_SET_NAMES)) * FRAME_LAYER_SETS
#: layer sets a host node takes (nte.h NTE_LAYER_SETS_MAX, the reference's LAYER_MAX - 1)
NODE_LAYER_SETS = LAYER_MAX - 1


def item_numbers(db: NteDatabase) -> dict[str, int]:
    """Setting.Item's named values, name -> number (begin, model, sigma0, ..., commit)."""
    sig = db.db.get_message_by_name("Setting").get_signal_by_name("Item")
    return {str(name): int(value) for value, name in sig.choices.items()}


def setting_items(fc: FileConfig, db: NteDatabase) -> list[tuple[int, float]]:
    """The value items of a read configuration file, (item, float32 value), in item order."""
    n = item_numbers(db)
    out: list[tuple[int, float]] = [(n["model"], float(fc.model))]
    out += [(n[name], v) for name, v in zip(PARAM_NAMES, fc.params)]
    if fc.strengths:
        out += [(n[name], fc.strengths[name]) for name in RELAX_NAMES]
    m3 = fc.m3
    if "presliding_mm" in m3:
        out.append((n["delta"], float(m3["presliding_mm"])))     # delta starts there
    if fc.r_n2 is not None:
        out.append((n["r_n2"], fc.r_n2))
    if fc.surface_mm is not None:        # a per-trial list: the node finds it from the force
        out.append((n["surface_mm"], fc.surface_mm))
    for key in ("tau_fast_s", "tau_slow_s", "relax_branches", "relaxation",
                "direction_memory"):
        if key in m3:
            out.append((n[key], float(m3[key])))                 # bools and counts as 0/1, n
    sets = m3.get("layer_sets") or ()
    if sets:
        out.append((n["layer_sets"], float(len(sets))))
        fields = 1 + len(LAYER_SET_NAMES)
        for k, ls in enumerate(sets):
            first = n["layer_sets"] + 1 + fields * k
            out += [(first + j, v) for j, v in enumerate((ls.start_mm, *ls.values))]
    return [(item, float(np.float32(v))) for item, v in out]


def value_ok(item: int, value: float, n: dict[str, int]) -> bool:
    """Whether a host node takes a value item (nte_node.c nte_node_setting_apply's refusals:
    counts and switches whole and in range, a layer set within the capacity)."""
    def whole(lo: int, hi: int) -> bool:
        return lo <= value <= hi and float(int(value)) == value
    fields = 1 + len(LAYER_SET_NAMES)
    if item > n["layer_sets"]:
        return (item - n["layer_sets"] - 1) // fields < NODE_LAYER_SETS
    limits = {n["model"]: (1, 3), n["relax_branches"]: (1, 2), n["relaxation"]: (0, 1),
              n["direction_memory"]: (0, 1), n["layer_sets"]: (0, NODE_LAYER_SETS)}
    return whole(*limits[item]) if item in limits else item != n["begin"]


def transfer(items: list[tuple[int, float]], sender: E2ESender,
             timestamp: float = 0.0) -> list[can.Message]:
    """BEGIN with the count, the value items, COMMIT with the count: one transfer's frames,
    consecutive E2E counters from `sender`'s Setting counter."""
    n = item_numbers(sender.db)
    count = float(len(items))
    frames = [(n["begin"], count)] + list(items) + [(n["commit"], count)]
    return [sender.message("Setting", {"Item": item, "Value": value}, timestamp)
            for item, value in frames]


__all__ = ["FRAME_ITEMS_LAST", "FRAME_LAYER_SETS", "item_numbers", "setting_items", "transfer",
           "value_ok"]
