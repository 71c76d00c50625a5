"""The physical envelope against the DBC.

The envelope -- the estimator's accepted ranges, EstimatorConfig's defaults depth_max_mm,
speed_max_mm_s and force_max_n in reference_py/config.py -- is written once there: the bench,
the node mirror and the tools import it, and firmware/tools/gen_constants.py writes it into
firmware/src/nte_constants.h for the C programs.  The bus (firmware/can/nte.dbc) declares its
own ranges, and the rule between the two, which holds today, is equality:

    every signal that carries a depth, a speed or a force spans exactly the envelope:
    Depth.Depth [0, depth_max_mm]; Contact.Surface [-depth_max_mm, depth_max_mm] (a stage
    position, ContactConfig's bound); Depth.Velocity [-speed_max_mm_s, speed_max_mm_s];
    Force.Force, Estimate.ForceEst and Contact.Tare [-force_max_n, force_max_n];
    and each signal's raw field (its bits, sign and scale) can hold both ends.

So a value the estimator accepts can be sent, and nothing the bus carries lies beyond what it
accepts; the node mirror (host_bench/node_mirror.py) clamps and refuses at the envelope on that
ground, and the C frame layer (firmware/can/nte_frames.h) at its NTE_FRAMES_* ranges, checked
here to be the DBC's.  Changing the envelope in config.py without the DBC (or the DBC without
config.py) fails here.
"""
from __future__ import annotations

import re
from pathlib import Path

import cantools
import pytest

from reference_py.bus.dbc import DBC_PATH
from reference_py.config import EstimatorConfig

ROOT = Path(__file__).resolve().parents[2]
FRAMES_H = ROOT / "firmware" / "can" / "nte_frames.h"

DEPTH = EstimatorConfig.depth_max_mm
SPEED = EstimatorConfig.speed_max_mm_s
FORCE = EstimatorConfig.force_max_n

#: (message, signal): the (minimum, maximum) the envelope gives it
ENVELOPE = {
    ("Depth", "Depth"): (0.0, DEPTH),
    ("Depth", "Velocity"): (-SPEED, SPEED),
    ("Force", "Force"): (-FORCE, FORCE),
    ("Estimate", "ForceEst"): (-FORCE, FORCE),
    ("Contact", "Surface"): (-DEPTH, DEPTH),
    ("Contact", "Tare"): (-FORCE, FORCE),
}

#: nte_frames.h's ranges: define -> (message, signal, end of the range it is)
FRAME_LAYER = {
    "NTE_FRAMES_DEPTH_MAX_MM": ("Depth", "Depth", "maximum"),
    "NTE_FRAMES_VELOCITY_MAX_MM_S": ("Depth", "Velocity", "maximum"),
    "NTE_FRAMES_FORCE_MAX_N": ("Force", "Force", "maximum"),
    "NTE_FRAMES_SURFACE_MAX_MM": ("Contact", "Surface", "maximum"),
}


@pytest.fixture(scope="module")
def dbc() -> cantools.database.can.Database:
    return cantools.database.load_file(str(DBC_PATH))


@pytest.mark.parametrize("message,signal", sorted(ENVELOPE))
def test_signal_range_is_the_envelope(dbc, message: str, signal: str) -> None:
    sig = dbc.get_message_by_name(message).get_signal_by_name(signal)
    lo, hi = ENVELOPE[(message, signal)]
    assert (sig.minimum, sig.maximum) == (lo, hi), (
        f"{message}.{signal}: the DBC declares [{sig.minimum}, {sig.maximum}], the envelope "
        f"(reference_py/config.py EstimatorConfig) is [{lo:g}, {hi:g}]: change both together")


@pytest.mark.parametrize("message,signal", sorted(ENVELOPE))
def test_raw_field_holds_the_envelope(dbc, message: str, signal: str) -> None:
    sig = dbc.get_message_by_name(message).get_signal_by_name(signal)
    raw_lo, raw_hi = ((-(1 << (sig.length - 1)), (1 << (sig.length - 1)) - 1) if sig.is_signed
                      else (0, (1 << sig.length) - 1))
    lo, hi = ENVELOPE[(message, signal)]
    assert raw_lo * sig.scale + sig.offset <= lo and hi <= raw_hi * sig.scale + sig.offset, (
        f"{message}.{signal}: {sig.length} bits at {sig.scale:g} cannot hold [{lo:g}, {hi:g}]")


def test_frame_layer_ranges_are_the_dbc(dbc) -> None:
    text = FRAMES_H.read_text()
    for name, (message, signal, end) in FRAME_LAYER.items():
        m = re.search(rf"^#define {name} ([0-9.eE+-]+)f\b", text, re.MULTILINE)
        assert m, f"{FRAMES_H}: no #define {name}"
        sig = dbc.get_message_by_name(message).get_signal_by_name(signal)
        assert float(m.group(1)) == getattr(sig, end), (name, message, signal)
