"""Reading measured trials.

A trial is one insertion recording: times (s), stage/insertion depth (mm), axial force (N) and,
when the recorder logged it, the stage velocity (mm/s).  Readers are chosen by file suffix from
:data:`READERS`: CSV (the tools' one reader: a spreadsheet export with a byte-order mark,
quoted cells, semicolons and a decimal comma is fine; also as ``.tsv`` and ``.txt``, the names
loggers give their tab-separated exports) and candump logs (``.log``, ``candump -l``/``-L``)
decoded with the project's DBC (firmware/can/nte.dbc through reference_py.bus.dbc, end-to-end
checks included).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ..fmath import Array
from ..tools.csvio import CsvError, Units, left_out_note
from ..tools.csvio import read_trial as read_csv_trial

REQUIRED = ("t_s", "depth_mm", "force_n")
OPTIONAL = ("velocity_mm_s",)


class InputError(Exception):
    """Unreadable or malformed input; the message names the file, line and column (or is the
    reader's own message, a ``csvio.CsvError``, passed alone)."""

    def __init__(self, path: str | Path | Exception, line: int | None = None,
                 column: str | None = None, msg: str = "") -> None:
        if isinstance(path, Exception):
            super().__init__(str(path))
            return
        where = str(path)
        if line is not None:
            where += f":{line}"
        if column is not None:
            where += f": column {column}"
        super().__init__(f"{where}: {msg}")


@dataclass
class Trial:
    """One measured insertion (units: s, mm, N, mm/s)."""

    name: str
    t_s: Array
    depth_mm: Array
    force_n: Array
    velocity_mm_s: Array | None = None
    #: what the reader left out (csvio.left_out_note: rows with a dropout), or None
    note: str | None = None


def read_csv(path: Path, units: Units | None = None) -> Trial:
    """CSV with a header naming t_s, depth_mm, force_n (any order) and optionally velocity_mm_s,
    read by the tools' one reader (reference_py.tools.csvio: its rules and its messages).

    Lines starting with '#' are comments.  Times must increase (irregular spacing and gaps are
    fine; a row whose time repeats the previous sample's is left out); every value must be a
    finite number, or missing in the depth or force (a dropout: the row is left out).  What was
    left out is said by the trial's ``note``.
    """
    try:
        tr = read_csv_trial(path, units=units)
    except CsvError as exc:
        raise InputError(exc) from None
    if len(tr.t_s) < 2:
        raise InputError(path, None, None, "fewer than 2 data rows")
    return Trial(path.stem, tr.t_s, tr.depth_mm, tr.force_n,
                 tr.velocity_mm_s if tr.velocity_given else None, left_out_note(tr))


def read_candump(path: Path) -> Trial:
    """A candump log (``candump -l`` / ``-L`` format) of the bench's Depth and Force frames.

    Frames are decoded with the project's DBC and their end-to-end protection is checked (frames
    that fail are dropped); times are the log's own time stamps.  Depth and velocity are
    interpolated at each Force frame's time.
    """
    try:
        import can
        from ..bus.dbc import NteDatabase
    except ImportError as exc:
        raise InputError(path, None, None, f"candump logs need python-can and cantools ({exc})"
                         ) from None
    try:
        msgs = list(can.LogReader(str(path)))
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise InputError(path, None, None, f"not a candump log: {exc}") from None
    db = NteDatabase()
    rx = db.receiver()
    dep: list[tuple[float, float, float]] = []
    frc: list[tuple[float, float]] = []
    dropped = 0
    for m in msgs:
        if m.is_error_frame or m.is_remote_frame:
            continue
        name, sig, status = rx.decode(m.arbitration_id, bytes(m.data))
        if name is None:
            continue
        if status not in ("ok", "skipped") or sig is None:
            dropped += 1
            continue
        if name == "Depth":
            dep.append((m.timestamp, float(sig["Depth"]), float(sig["Velocity"])))
        elif name == "Force":
            frc.append((m.timestamp, float(sig["Force"])))
    if len(dep) < 2 or len(frc) < 2:
        raise InputError(path, None, None, f"needs Depth and Force frames (found {len(dep)} "
                         f"Depth, {len(frc)} Force, {dropped} failed the end-to-end check)")
    td, d, v = (np.asarray(c) for c in zip(*dep))
    tf, f = (np.asarray(c) for c in zip(*frc))
    keep = (tf >= td[0]) & (tf <= td[-1])
    tf, f = tf[keep], f[keep]
    order = np.argsort(tf, kind="stable")
    tf, f = tf[order], f[order]
    uniq = np.concatenate([[True], np.diff(tf) > 0])
    tf, f = tf[uniq], f[uniq]
    if len(tf) < 2:
        raise InputError(path, None, None, "no Force frame inside the span of the Depth frames")
    t0 = tf[0]
    return Trial(path.stem, tf - t0, np.interp(tf, td, d), f, np.interp(tf, td, v))


#: by suffix: .txt and .dat are what numpy.savetxt, MATLAB and plotting programs write
READERS: dict[str, Callable[[Path], Trial]] = {".csv": read_csv, ".tsv": read_csv,
                                               ".txt": read_csv, ".dat": read_csv,
                                               ".log": read_candump}


def read_trial(path: str | Path, units: Units | None = None) -> Trial:
    """A trial by its suffix; a CSV converted and checked by ``units`` (csvio.Units) if given."""
    p = Path(path)
    reader = READERS.get(p.suffix.lower())
    if reader is None:
        raise InputError(p, None, None, f"unknown file type {p.suffix!r} (known: "
                         f"{', '.join(READERS)})")
    return read_csv(p, units) if reader is read_csv else reader(p)


def write_csv(path: str | Path, trial: Trial) -> None:
    """Write a trial in the format :func:`read_csv` reads (used by tests and examples)."""
    cols = [trial.t_s, trial.depth_mm, trial.force_n]
    head = list(REQUIRED)
    if trial.velocity_mm_s is not None:
        cols.append(trial.velocity_mm_s)
        head.append("velocity_mm_s")
    with open(path, "w", encoding="utf-8", newline="") as fh:
        fh.write(",".join(head) + "\n")
        for row in zip(*cols):
            fh.write(",".join(repr(float(x)) for x in row) + "\n")
