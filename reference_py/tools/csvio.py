"""Reading insertion CSV files and writing estimate CSV files, strictly and atomically.

Input: a header line of comma-separated column names (lines starting with '#' are comments),
then one sample per line.  Required columns t_s, depth_mm, force_n; optional velocity_mm_s;
any other column is ignored.  Every cell must be a finite number and t_s strictly increasing.
A violation raises :class:`CsvError` naming the file, the line and the column.

Output files are written to a temporary file beside the target and renamed into place, so a
failure never leaves a half-written file.  Floats are printed with '%.17g' (float64) or '%.9g'
(float32): enough digits to round-trip, and the same text the C host program prints.
"""
from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from ..fmath import Array

REQUIRED = ("t_s", "depth_mm", "force_n")
OPTIONAL = ("velocity_mm_s",)


class CsvError(ValueError):
    """Bad input: the message says which file, line and column, and why."""


@dataclass
class Trial:
    path: str
    t_s: Array
    depth_mm: Array
    force_n: Array
    velocity_mm_s: Array
    velocity_given: bool
    columns: dict[str, Array]     # every numeric column of the file, by name


def read_trial(path: str | os.PathLike[str], required: Sequence[str] = REQUIRED) -> Trial:
    name = str(path)
    try:
        with open(path, newline="") as fh:
            lines = fh.read().split("\n")
    except OSError as exc:
        raise CsvError(f"{name}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise CsvError(f"{name}: not a text file") from None
    header: list[str] | None = None
    header_line = 0
    rows: list[list[float]] = []
    prev_t = -math.inf
    for lineno, raw in enumerate(lines, start=1):
        line = raw.rstrip("\r")
        if line.startswith("#"):
            continue
        if line == "":
            if lineno == len(lines):
                continue
            raise CsvError(f"{name}:{lineno}: empty line")
        cells = line.split(",")
        if header is None:
            header = [c.strip() for c in cells]
            header_line = lineno
            for col in required:
                if col not in header:
                    raise CsvError(f"{name}:{lineno}: column '{col}': missing from the header "
                                   f"(have: {', '.join(header)})")
            if len(set(header)) != len(header):
                raise CsvError(f"{name}:{lineno}: duplicate column name in the header")
            continue
        if len(cells) != len(header):
            raise CsvError(f"{name}:{lineno}: expected {len(header)} cells, found {len(cells)}")
        row = []
        for col, cell in zip(header, cells):
            text = cell.strip()
            try:
                value = float(text)
            except ValueError:
                raise CsvError(f"{name}:{lineno}: column '{col}': not a number: {text!r}") \
                    from None
            if not math.isfinite(value):
                raise CsvError(f"{name}:{lineno}: column '{col}': not finite: {text!r}")
            row.append(value)
        t = row[header.index("t_s")]
        if not t > prev_t:
            raise CsvError(f"{name}:{lineno}: column 't_s': time {t!r} does not increase "
                           f"(previous {prev_t!r})")
        prev_t = t
        rows.append(row)
    if header is None:
        raise CsvError(f"{name}:1: no header line")
    if not rows:
        raise CsvError(f"{name}:{header_line + 1}: no samples after the header")
    data = np.asarray(rows, dtype=np.float64)
    cols = {c: data[:, i] for i, c in enumerate(header)}
    t, depth = cols["t_s"], cols["depth_mm"]
    given = "velocity_mm_s" in cols
    vel = cols["velocity_mm_s"] if given else central_difference(t, depth)
    return Trial(name, t, depth, cols["force_n"], vel, given, cols)


def central_difference(t: Array, x: Array) -> Array:
    """dx/dt by central differences (one-sided at the ends), in double, sample by sample.

    Written as a loop of scalar operations so the C host program computes the same bits.
    """
    n = len(t)
    v = np.zeros(n)
    if n < 2:
        return v
    v[0] = (x[1] - x[0]) / (t[1] - t[0])
    for k in range(1, n - 1):
        v[k] = (x[k + 1] - x[k - 1]) / (t[k + 1] - t[k - 1])
    v[n - 1] = (x[n - 1] - x[n - 2]) / (t[n - 1] - t[n - 2])
    return v


def time_us(t_s: Array) -> Array:
    """Sample times in integer microseconds, the library's clock: floor(t * 1e6 + 0.5)."""
    return np.array([math.floor(float(t) * 1e6 + 0.5) for t in t_s], dtype=np.int64)


def format_real(value: float, precision: str) -> str:
    return ("%.9g" if precision == "float32" else "%.17g") % float(value)


def write_atomic(path: str | os.PathLike[str], lines: Iterable[str]) -> None:
    """Write text lines to ``path`` through a temporary file and a rename."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix="." + target.name + ".", dir=str(target.parent))
    try:
        with os.fdopen(fd, "w", newline="") as fh:
            for line in lines:
                fh.write(line)
                fh.write("\n")
        os.replace(tmp, target)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
