"""The node's CAN database (firmware/can/nte.dbc) with AUTOSAR E2E profile 11 protection.

The DBC is the single source of truth for ids, layouts, scalings and E2E data ids; this module
only reads it (cantools) and adds the E2E header (autosar-e2e), the configurable base id and the
counter bookkeeping of a sender and of a receiver:

>>> db = NteDatabase()                       # base id from the DBC (0x200) unless given
>>> tx = db.sender()
>>> msg = tx.message("Depth", {"Depth": 12.5, "Velocity": 10.0, "SensorTime": 0.0123})
>>> rx = db.receiver()
>>> name, signals, status = rx.decode(msg.arbitration_id, msg.data)   # status "ok"

Units: mm, mm/s, N, s, as in the DBC. E2E statuses, as the C module nte_e2e reports them:
"ok", "skipped" (frames lost, still accepted), "repeated", "bad_crc", "wrong_length",
"bad_counter"; the last four mean the frame must be discarded.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import can
import cantools
from e2e.p11 import E2E_P11_DATAID_BOTH, e2e_p11_check, e2e_p11_protect

#: Where the DBC lives in the repository; NTE_DBC overrides it.
DBC_PATH = Path(__file__).resolve().parents[2] / "firmware" / "can" / "nte.dbc"

COUNTER_MODULUS = 15  #: counter counts 0..14
FRAME_LENGTH = 8
TICK_S = 1e-4  #: SensorTime resolution, s
TICK_WRAP = 1 << 16  #: SensorTime wraps after this many ticks (6.5536 s)
STD_LOG10_ZERO = -32.768  #: Params *StdLog10 value that means "std = 0 (fixed)"
STD_LOG10_MIN = -32.767
STD_LOG10_MAX = 32.767
#: Params multiplexer indices 0..6 (every model) and 7..9 (Model III's relaxation strengths and
#: turn-over length)
PARAM_NAMES = ("sigma0", "sigma1", "sigma2", "f1", "f2", "alpha", "beta", "g_fast", "g_slow",
               "delta")
#: Params signal names by parameter index
PARAM_SIGNALS = (
    ("Sigma0", "Sigma0StdLog10"),
    ("Sigma1", "Sigma1StdLog10"),
    ("Sigma2", "Sigma2StdLog10"),
    ("F1", "F1StdLog10"),
    ("F2", "F2StdLog10"),
    ("Alpha", "AlphaStdLog10"),
    ("Beta", "BetaStdLog10"),
    ("GFast", "GFastStdLog10"),
    ("GSlow", "GSlowStdLog10"),
    ("Delta", "DeltaStdLog10"),
)


class E2EError(ValueError):
    """A received frame failed the end-to-end check."""

    def __init__(self, status: str, message: str) -> None:
        super().__init__(message)
        self.status = status


def dbc_path() -> Path:
    return Path(os.environ.get("NTE_DBC", DBC_PATH))


def seconds_to_ticks(t_s: float) -> int:
    """Sender time in s -> 16-bit SensorTime raw ticks (100 us, wrapping)."""
    return int(round(t_s / TICK_S)) % TICK_WRAP


def std_to_log10(std: float) -> float:
    """Standard deviation -> the Params *StdLog10 signal (0 -> the 'fixed' value)."""
    if not math.isfinite(std) or std < 0.0:
        raise ValueError(f"standard deviation must be finite and >= 0, got {std!r}")
    if std == 0.0:
        return STD_LOG10_ZERO
    return min(max(math.log10(std), STD_LOG10_MIN), STD_LOG10_MAX)


def log10_to_std(value: float) -> float:
    """The Params *StdLog10 signal -> standard deviation."""
    if value <= STD_LOG10_ZERO + 0.0005:
        return 0.0
    return 10.0**value


class NteDatabase:
    """nte.dbc loaded with cantools, with ids relative to a configurable base id."""

    def __init__(self, path: str | os.PathLike[str] | None = None, base_id: int | None = None):
        self.path = Path(path) if path is not None else dbc_path()
        self.db = cantools.database.load_file(str(self.path))
        self.dbc_base_id = int(self.db.dbc.attributes["NteBaseId"].value)
        self.base_id = self.dbc_base_id if base_id is None else int(base_id)
        self.offsets: dict[str, int] = {}
        self.data_ids: dict[str, int] = {}
        for m in self.db.messages:
            self.offsets[m.name] = int(m.dbc.attributes["NteIdOffset"].value)
            self.data_ids[m.name] = int(m.dbc.attributes["NteE2EDataId"].value)
            if m.frame_id != self.dbc_base_id + self.offsets[m.name]:
                raise ValueError(f"{m.name}: frame id and NteIdOffset disagree in {self.path}")
        if not 0 <= self.base_id or self.base_id + max(self.offsets.values()) > 0x7FF:
            raise ValueError(f"base id 0x{self.base_id:X} puts ids beyond 0x7FF")
        self._by_id = {self.base_id + off: name for name, off in self.offsets.items()}

    def message_names(self) -> list[str]:
        return [m.name for m in self.db.messages]

    def frame_id(self, name: str) -> int:
        return self.base_id + self.offsets[name]

    def signal_range(self, message: str, signal: str) -> tuple[float, float]:
        """(minimum, maximum) physical value of a signal, as the DBC declares it."""
        sig = self.db.get_message_by_name(message).get_signal_by_name(signal)
        if sig.minimum is None or sig.maximum is None:
            raise ValueError(f"{self.path}: {message}.{signal} declares no range")
        return float(sig.minimum), float(sig.maximum)

    def name_of(self, can_id: int) -> str | None:
        return self._by_id.get(can_id)

    def encode(self, name: str, signals: Mapping[str, Any], counter: int) -> bytes:
        """Pack `signals` (physical values; Crc/Counter not needed; any other signal not given
        is 0 in a frame without multiplexer), set the counter, add the CRC.  Raises ValueError (cantools' strict range check) for an out-of-range value."""
        if not 0 <= counter < COUNTER_MODULUS:
            raise ValueError(f"counter {counter} outside 0..14")
        msg = self.db.get_message_by_name(name)
        values = dict(signals)
        if not msg.is_multiplexed():
            # a signal not given is 0: the value of "not in use" for every signal added to a
            # frame later (Force.SensorFault, Command.ForceSource), so older callers send the
            # frames they always sent
            for sig in msg.signals:
                values.setdefault(sig.name, 0)
        values["Crc"] = 0
        values["Counter"] = counter
        data = bytearray(msg.encode(values, scaling=True, strict=True))
        e2e_p11_protect(data, self.data_ids[name], data_id_mode=E2E_P11_DATAID_BOTH,
                        increment_counter=False)
        return bytes(data)

    def decode_unchecked(self, name: str, data: bytes) -> dict[str, Any]:
        """Decode without any E2E check (choices as plain numbers)."""
        return dict(self.db.get_message_by_name(name).decode(bytes(data), decode_choices=False))

    def crc_ok(self, name: str, data: bytes) -> bool:
        if len(data) != FRAME_LENGTH:
            return False
        return bool(e2e_p11_check(bytearray(data), self.data_ids[name],
                                  data_id_mode=E2E_P11_DATAID_BOTH))

    def sender(self) -> "E2ESender":
        return E2ESender(self)

    def receiver(self) -> "E2EReceiver":
        return E2EReceiver(self)


@dataclass
class E2ESender:
    """One alive counter per message; the first frame of each message has counter 0."""

    db: NteDatabase
    counters: dict[str, int] = field(default_factory=dict)

    def encode(self, name: str, signals: Mapping[str, Any]) -> bytes:
        counter = self.counters.get(name, 0)
        data = self.db.encode(name, signals, counter)
        self.counters[name] = (counter + 1) % COUNTER_MODULUS
        return data

    def message(self, name: str, signals: Mapping[str, Any], timestamp: float = 0.0) -> can.Message:
        return can.Message(arbitration_id=self.db.frame_id(name), is_extended_id=False,
                           data=self.encode(name, signals), timestamp=timestamp)


@dataclass
class E2EReceiver:
    """Checks every frame as the C nte_e2e_check does, one counter history per message."""

    db: NteDatabase
    last: dict[str, int] = field(default_factory=dict)
    lost: dict[str, int] = field(default_factory=dict)
    errors: dict[str, int] = field(default_factory=dict)

    def check(self, name: str, data: bytes) -> tuple[str, int]:
        """Return (status, frames lost before this one) and advance on ok/skipped."""
        if len(data) != FRAME_LENGTH:
            return "wrong_length", 0
        counter = data[1] & 0x0F
        if counter >= COUNTER_MODULUS:
            return "bad_counter", 0
        if not self.db.crc_ok(name, data):
            return "bad_crc", 0
        if name not in self.last:
            self.last[name] = counter
            return "ok", 0
        delta = (counter - self.last[name]) % COUNTER_MODULUS
        if delta == 0:
            return "repeated", 0
        self.last[name] = counter
        return ("ok", 0) if delta == 1 else ("skipped", delta - 1)

    def decode(self, can_id: int, data: bytes) -> tuple[str | None, dict[str, Any] | None, str]:
        """(message name, signals, status); name None for a foreign id, signals None if the
        frame failed E2E. Counts lost frames and errors per message."""
        name = self.db.name_of(can_id)
        if name is None:
            return None, None, "unknown_id"
        status, lost = self.check(name, bytes(data))
        if status not in ("ok", "skipped"):
            self.errors[name] = self.errors.get(name, 0) + 1
            return name, None, status
        self.lost[name] = self.lost.get(name, 0) + lost
        return name, self.db.decode_unchecked(name, bytes(data)), status

    def decode_strict(self, can_id: int, data: bytes) -> tuple[str, dict[str, Any]]:
        name, signals, status = self.decode(can_id, data)
        if name is None or signals is None:
            raise E2EError(status, f"frame 0x{can_id:03X} {bytes(data).hex()}: {status}")
        return name, signals
