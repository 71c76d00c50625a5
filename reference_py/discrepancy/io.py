"""Reading measured trials.

A trial is one insertion recording: times (s), stage/insertion depth (mm), axial force (N) and,
when the recorder logged it, the stage velocity (mm/s).  Readers are chosen by file suffix from
:data:`READERS`; the CSV reader is implemented.  A candump log decoded through the project's DBC
plugs in by adding a reader for ``.log`` that returns the same :class:`Trial` (see
:func:`read_candump`).
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ..fmath import Array

REQUIRED = ("t_s", "depth_mm", "force_n")
OPTIONAL = ("velocity_mm_s",)


class InputError(Exception):
    """Unreadable or malformed input; the message names the file, line and column."""

    def __init__(self, path: str | Path, line: int | None, column: str | None, msg: str) -> None:
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


def read_csv(path: Path) -> Trial:
    """CSV with a header naming t_s, depth_mm, force_n (any order) and optionally velocity_mm_s.

    Lines starting with '#' are comments.  Times must increase strictly (irregular spacing and
    gaps are fine); every value must be a finite number.
    """
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(path, None, None, f"cannot read: {exc}") from None
    rows = [(no, row) for no, row in enumerate(csv.reader(text.splitlines()), start=1)
            if row and not row[0].lstrip().startswith("#") and any(c.strip() for c in row)]
    if not rows:
        raise InputError(path, None, None, "empty file (expected a header t_s,depth_mm,force_n)")
    head_no, head = rows[0]
    names = [h.strip() for h in head]
    for req in REQUIRED:
        if req not in names:
            raise InputError(path, head_no, req, f"missing column {req!r} in header {names}")
    cols = {n: names.index(n) for n in REQUIRED + OPTIONAL if n in names}
    data: dict[str, list[float]] = {n: [] for n in cols}
    for no, row in rows[1:]:
        if len(row) != len(names):
            raise InputError(path, no, None, f"expected {len(names)} fields, found {len(row)}")
        for n, j in cols.items():
            cell = row[j].strip()
            try:
                val = float(cell)
            except ValueError:
                raise InputError(path, no, n, f"not a number: {cell!r}") from None
            if not math.isfinite(val):
                raise InputError(path, no, n, f"not finite: {cell!r}")
            data[n].append(val)
        if len(data["t_s"]) > 1 and data["t_s"][-1] <= data["t_s"][-2]:
            raise InputError(path, no, "t_s", "time does not increase")
    if len(data["t_s"]) < 2:
        raise InputError(path, None, None, "fewer than 2 data rows")
    vel = np.asarray(data["velocity_mm_s"]) if "velocity_mm_s" in data else None
    return Trial(path.stem, np.asarray(data["t_s"]), np.asarray(data["depth_mm"]),
                 np.asarray(data["force_n"]), vel)


def read_candump(path: Path) -> Trial:
    """Placeholder for candump logs: decoding needs the project's DBC frame definitions.

    To plug it in: decode each frame with the DBC (depth, velocity, force signals in mm, mm/s,
    N), collect (timestamp, signal) rows, and return a :class:`Trial` like :func:`read_csv`.
    """
    raise InputError(path, None, None, "candump logs are not supported yet (needs the DBC "
                     "decoder); export the trial as CSV with t_s,depth_mm,force_n")


READERS: dict[str, Callable[[Path], Trial]] = {".csv": read_csv, ".log": read_candump}


def read_trial(path: str | Path) -> Trial:
    p = Path(path)
    reader = READERS.get(p.suffix.lower())
    if reader is None:
        raise InputError(p, None, None, f"unknown file type {p.suffix!r} (known: "
                         f"{', '.join(READERS)})")
    return reader(p)


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
