"""Reading measured trials.

A trial is one insertion recording: times (s), stage/insertion depth (mm), axial force (N) and,
when the recorder logged it, the stage velocity (mm/s).  Readers are chosen by file suffix from
:data:`READERS`; the CSV reader is implemented.  A candump log decoded through the project's DBC
plugs in by adding a reader for ``.log`` that returns the same :class:`Trial` (see
:func:`read_candump`).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ..fmath import Array
from ..tools.csvio import CsvError, Units
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


def read_csv(path: Path, units: Units | None = None) -> Trial:
    """CSV with a header naming t_s, depth_mm, force_n (any order) and optionally velocity_mm_s,
    read by the tools' one reader (reference_py.tools.csvio: its rules and its messages).

    Lines starting with '#' are comments.  Times must increase strictly (irregular spacing and
    gaps are fine); every value must be a finite number.
    """
    try:
        tr = read_csv_trial(path, units=units)
    except CsvError as exc:
        raise InputError(exc) from None
    if len(tr.t_s) < 2:
        raise InputError(path, None, None, "fewer than 2 data rows")
    return Trial(path.stem, tr.t_s, tr.depth_mm, tr.force_n,
                 tr.velocity_mm_s if tr.velocity_given else None)


def read_candump(path: Path) -> Trial:
    """Placeholder for candump logs: decoding needs the project's DBC frame definitions.

    To plug it in: decode each frame with the DBC (depth, velocity, force signals in mm, mm/s,
    N), collect (timestamp, signal) rows, and return a :class:`Trial` like :func:`read_csv`.
    """
    raise InputError(path, None, None, "candump logs are not supported yet (needs the DBC "
                     "decoder); export the trial as CSV with t_s,depth_mm,force_n")


READERS: dict[str, Callable[[Path], Trial]] = {".csv": read_csv, ".log": read_candump}


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
