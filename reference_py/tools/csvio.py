"""The one CSV reader of the Python tools.

Reading (:func:`read_table`, :func:`read_trial`)
    Parsed with the standard ``csv`` module; the file is decoded as UTF-8 with an optional BOM
    (``utf-8-sig``).  Lines starting with ``#`` are comments.  The first other line is the
    header (column names, surrounding spaces ignored, no duplicates); every later line is one
    sample with exactly as many cells as the header.  Cells may be quoted.  Required columns
    for an insertion: ``t_s``, ``depth_mm``, ``force_n``; ``velocity_mm_s`` is optional (when it
    is absent it is computed by central differences of depth); other columns are kept in
    ``Trial.columns`` and otherwise ignored.  Every cell must be a decimal number (``1``,
    ``-0.5``, ``2.5e-3``; no hex, no ``_``), finite (``nan``, ``inf`` and overflowing values are
    refused), and ``t_s`` must increase strictly.  A column named in ``sparse`` may have empty
    cells (no sample on that line; stored as NaN, see ``Trial.present``).  A blank line is an
    error.  Every refusal is a :class:`CsvError` whose message has one form::

        FILE:LINE: column 'NAME': reason        (or FILE:LINE: reason, or FILE: reason)

Outputs are written by :mod:`reference_py.tools.safe_write` (``write_atomic`` is re-exported
here).  Floats are printed with '%.17g' (float64) or '%.9g' (float32): enough digits to
round-trip, and the same text the C host program prints.
"""
from __future__ import annotations

import csv
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Iterator, Sequence

import numpy as np

from ..fmath import Array
from .safe_write import write_atomic  # noqa: F401  (re-exported)

REQUIRED = ("t_s", "depth_mm", "force_n")
OPTIONAL = ("velocity_mm_s",)

_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
_NOT_FINITE = re.compile(r"[+-]?(nan|inf|infinity)", re.IGNORECASE)


class CsvError(ValueError):
    """Bad input: the message says which file, line and column, and why."""


@dataclass
class Table:
    path: str
    header: list[str]
    columns: dict[str, Array]       # every column, float64 (NaN where a sparse cell is empty)
    lines: list[int]                # physical line number of every sample


@dataclass
class Trial:
    path: str
    t_s: Array
    depth_mm: Array
    force_n: Array
    velocity_mm_s: Array
    velocity_given: bool
    columns: dict[str, Array]       # every numeric column of the file, by name
    lines: list[int] = field(default_factory=list)

    @property
    def name(self) -> str:
        """The file name without its folder and suffix."""
        return Path(self.path).stem


def parse_cell(name: str, lineno: int, col: str, text: str) -> float:
    """One cell as a finite float, or CsvError with the file, line and column."""
    cell = text.strip()
    if _NUMBER.fullmatch(cell):
        value = float(cell)
        if math.isfinite(value):
            return value
        raise CsvError(f"{name}:{lineno}: column '{col}': not finite: {cell!r}")
    if _NOT_FINITE.fullmatch(cell):
        raise CsvError(f"{name}:{lineno}: column '{col}': not finite: {cell!r}")
    raise CsvError(f"{name}:{lineno}: column '{col}': not a number: {cell!r}")


def read_table(path: str | os.PathLike[str], required: Sequence[str] = REQUIRED,
               sparse: Sequence[str] = (), increasing: str | None = "t_s") -> Table:
    """Read a numeric CSV by the rules of this module (see the module's docstring)."""
    name = str(path)
    try:
        fh = open(path, "rb")
    except OSError as exc:
        raise CsvError(f"{name}: cannot read: {exc.strerror or exc}") from None
    lineno = 0

    def numbered() -> Iterator[str]:
        """Decoded lines, comments skipped; ``lineno`` is the physical line last read."""
        nonlocal lineno
        for raw in fh:
            lineno += 1
            try:
                text = raw.decode("utf-8-sig" if lineno == 1 else "utf-8")
            except UnicodeDecodeError:
                raise CsvError(f"{name}:{lineno}: not UTF-8 text") from None
            if text.startswith("#"):
                continue
            yield text

    header: list[str] | None = None
    header_line = 0
    rows: list[list[float]] = []
    lines: list[int] = []
    prev_t = -math.inf
    t_index = -1
    sparse_idx: set[int] = set()
    try:
        with fh:
            for cells in csv.reader(numbered()):
                if not cells or (len(cells) == 1 and cells[0].strip() == ""):
                    raise CsvError(f"{name}:{lineno}: empty line")
                if header is None:
                    header = [c.strip() for c in cells]
                    header_line = lineno
                    for col in required:
                        if col not in header:
                            raise CsvError(f"{name}:{lineno}: column '{col}': missing from the "
                                           f"header (have: {', '.join(header)})")
                    if len(set(header)) != len(header):
                        dup = next(c for c in header if header.count(c) > 1)
                        raise CsvError(f"{name}:{lineno}: column '{dup}': duplicate column "
                                       f"name in the header")
                    t_index = header.index(increasing) if increasing in header else -1
                    sparse_idx = {header.index(c) for c in sparse if c in header}
                    continue
                if len(cells) != len(header):
                    raise CsvError(f"{name}:{lineno}: expected {len(header)} cells, found "
                                   f"{len(cells)}")
                row = [math.nan if (i in sparse_idx and cell.strip() == "")
                       else parse_cell(name, lineno, col, cell)
                       for i, (col, cell) in enumerate(zip(header, cells))]
                if t_index >= 0:
                    t = row[t_index]
                    if not t > prev_t:
                        raise CsvError(f"{name}:{lineno}: column '{increasing}': time {t!r} "
                                       f"does not increase (previous {prev_t!r})")
                    prev_t = t
                rows.append(row)
                lines.append(lineno)
    except csv.Error as exc:
        raise CsvError(f"{name}:{lineno}: {exc}") from None
    except OSError as exc:
        raise CsvError(f"{name}: cannot read: {exc.strerror or exc}") from None
    if header is None:
        raise CsvError(f"{name}:1: no header line")
    if not rows:
        raise CsvError(f"{name}:{header_line + 1}: no samples after the header")
    data = np.asarray(rows, dtype=np.float64)
    return Table(name, header, {c: data[:, i] for i, c in enumerate(header)}, lines)


def read_trial(path: str | os.PathLike[str], required: Sequence[str] = REQUIRED,
               sparse: Sequence[str] = ()) -> Trial:
    """An insertion: t_s, depth_mm, force_n and velocity_mm_s (given or central differences)."""
    table = read_table(path, required, sparse)
    cols = table.columns
    t, depth = cols["t_s"], cols["depth_mm"]
    given = "velocity_mm_s" in cols
    vel = cols["velocity_mm_s"] if given else central_difference(t, depth)
    return Trial(table.path, t, depth, cols["force_n"], vel, given, cols, table.lines)


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
