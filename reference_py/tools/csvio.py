"""The one CSV reader of the Python tools.

Reading (:func:`read_table`, :func:`read_trial`)
    Parsed with the standard ``csv`` module; the file is decoded as UTF-8 with an optional BOM
    (``utf-8-sig``).  Lines starting with ``#`` are comments; blank lines (white space only,
    or only empty cells: a spreadsheet's ``,,``) are skipped wherever they stand.  The first
    other line that holds every required name is the header (column names, surrounding spaces
    ignored, no duplicates); the lines before it are a logger's preamble, skipped -- unless a
    sample (:func:`_is_data`) comes first, when the first of them is refused as the header
    (the first whose names ``missing_hint`` advises on, if any).  Where no line but a comment
    holds the names, the last such comment before the first line that is neither blank nor a
    comment, its ``#`` dropped, is the header (numpy.savetxt writes ``# t_s depth_mm
    force_n``); where none does, the last whose names ``missing_hint`` advises on is refused
    as the header, with that advice (``# time depth force``).  A file without a header: where
    every name read is a position (:func:`_positions`), the first sample (judged by the cells
    at those positions: the others are not read) has its cells named "1".."N" and is read as
    a sample; without a map, its refusal says so (after a preamble line too, whose refusal it
    then is).  Every later line is one sample with
    exactly as many cells as the header; the first may be a *units row*
    (:mod:`reference_py.tools.units_row`).  A time written as a clock reads in seconds
    (:mod:`reference_py.tools.clock_time`).  Cells are separated by commas, or -- as loggers
    and spreadsheets set to a decimal comma write -- by semicolons or tabs, or by runs of
    spaces (numpy.savetxt's default, a plotting program's .dat file): the header's first line
    decides (:func:`delimiter_of`).  Where the separator is not a comma, a number may
    write its decimal mark as a comma (``2,5`` is 2.5).  Cells may be quoted.  Required columns
    for an insertion: ``t_s``, ``depth_mm``, ``force_n``; ``velocity_mm_s`` is optional (when it
    is absent it is computed by central differences of depth); the simulator's noise-free
    force ``force_true_n`` (TRUTH_COLUMN) is read too where there is one, for the plots, and
    these are the columns of ``Trial.columns``.  Other columns are not read: their cells may
    hold anything (a logger's state word, a note, a second clock), and a row with nothing in
    the columns read (another sensor's line) is skipped like a blank one.  Every cell of a
    column read must be a decimal number (``1``,
    ``-0.5``, ``2.5e-3``; no hex, no ``_``), finite (``inf`` and overflowing values are
    refused, and ``nan`` but where a value may be missing), and ``t_s`` must increase -- but
    in an insertion (:func:`read_trial`) a row whose time *equals* the previous sample's (a
    logger that wrote a sample twice, or a time printed too coarsely for the rate) is left
    out, as the library rejects a sample not later than the last; it is listed in
    ``Trial.repeated`` and said by :func:`left_out_note`.  A time that goes back is refused.
    A *missing* value -- an empty cell, ``nan`` (as MATLAB and LabVIEW write a dropout), ``NA``
    (R) or ``n/a``, case aside: :func:`is_missing` -- is allowed in two kinds of column.  One
    named in ``sparse`` keeps its row (no sample of that quantity on that line, e.g. a 200 Hz
    force among 1 kHz depths; stored as NaN).  One named in ``skip_missing`` leaves its row out
    (a sensor's dropout: the row is not a sample; its other cells must still be numbers or
    missing, and its time is not compared): an insertion's depth, force and given velocity
    (:func:`read_trial`), each left-out line listed in ``Trial.left_out`` and said by
    :func:`left_out_note`.  One named in ``nan_ok`` may hold ``nan`` (the estimate file's
    ``surface_mm`` before a surface is found; stored as NaN).  Every refusal is a
    :class:`CsvError` whose message has one form::

        FILE:LINE: column 'NAME': reason        (or FILE:LINE: reason, or FILE: reason)

    (a refused option: ``--OPTION VALUE: reason``).

What the reader is told about a file -- which columns hold what (``--columns``), their units
and signs (``--force-unit``...), and the advice for a header that names its units -- is
:mod:`reference_py.tools.read_options` (its names are re-exported here, as the tools import
them from this module).  Whether the converted values look like an insertion in N, s and mm
is :mod:`reference_py.tools.units_check` (``check_units``, ``Limits`` and ``UnitsError`` are
re-exported here).  Outputs are written by :mod:`reference_py.tools.safe_write`
(``write_atomic`` is re-exported here).  Floats are printed with '%.17g' (float64) or '%.9g'
(float32): enough digits to round-trip, and the same text the C host program prints.
"""
from __future__ import annotations

import csv
import itertools
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator, Sequence

import numpy as np

from ..fmath import Array
from .read_options import (  # noqa: F401  (re-exported: the reader's options live there)
    COLUMN_KEYS, COLUMN_KEYS_REQUIRED, DEPTH_OFFSET_MAX_MM, DEPTH_UNITS, FORCE_UNITS, TIME_UNITS,
    UNIT_NAME_FORMS, UNIT_NAME_SPELLINGS, UNIT_SUFFIX_QUANTITIES, ColumnMap, CsvError, Units,
    ascii_lower, unit_suffix_hint)
from .clock_time import ClockColumn, read_stamp
from .safe_write import write_atomic  # noqa: F401  (re-exported)
from .units_row import unit_like, units_row_check
from .units_check import Limits, UnitsError, check_units  # noqa: F401  (re-exported)

REQUIRED = ("t_s", "depth_mm", "force_n")
OPTIONAL = ("velocity_mm_s",)

#: a line that starts with this is a comment
COMMENT = "#"
#: a cell's number, ASCII only (the C reader, firmware/host/csv_in.c, reads the same grammar)
_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?", re.ASCII)
#: ... where the cells are not separated by commas: the decimal mark may be a comma
_NUMBER_DECIMAL_COMMA = re.compile(r"[+-]?(\d+[.,]?\d*|[.,]\d+)([eE][+-]?\d+)?", re.ASCII)
#: the cell separators the reader knows, in the order the header's first line is searched
#: for them (C twin: csv_in.c delimiter_of)
DELIMITERS = (",", ";", "\t")
#: ... and where a header's line holds none of them: cells separated by runs of spaces
#: (numpy.savetxt's default, a plotting program's .dat file), when the line's names so cut
#: include every one read; leading and trailing spaces and tabs of each line are then ignored
BLANKS = " "
_NOT_FINITE = re.compile(r"[+-]?(nan|inf|infinity)", re.IGNORECASE | re.ASCII)
_NAN = re.compile(r"[+-]?nan", re.IGNORECASE | re.ASCII)
#: a missing value: an empty cell or a dropout's word (C twin: csv_in.c is_missing)
MISSING_WORDS = ("nan", "+nan", "-nan", "na", "n/a")
#: the refusal's advice for a file whose first record is a sample (no header) and whose
#: columns the tool was not told
NO_HEADER_ADVICE = ("no header line: name the columns by their positions, from 1: --columns "
                    "t=N,depth=N,force=N")
#: at most this many left-out lines are listed by left_out_note
LEFT_OUT_LISTED = 5


def is_missing(cell: str) -> bool:
    """Whether a cell holds no value: empty (spaces aside) or one of MISSING_WORDS, case aside
    in ASCII only (as the C twin compares)."""
    text = cell.strip()
    return text == "" or ascii_lower(text) in MISSING_WORDS


@dataclass
class Table:
    path: str
    header: list[str]
    columns: dict[str, Array]       # every column, float64 (NaN where a sparse cell is missing)
    lines: list[int]                # physical line number of every sample
    left_out: list[int] = field(default_factory=list)  # lines left out (``skip_missing``)
    left_out_columns: list[str] = field(default_factory=list)  # ``skip_missing`` in the header
    repeated: list[int] = field(default_factory=list)  # lines of a repeated time
    clock: bool = False     # the time column is written as clock times (clock_time)
    units_row: dict[str, str] = field(default_factory=dict)  # a units row's cells, by column
    units_row_line: int = 0


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
    left_out: list[int] = field(default_factory=list)   # lines without a depth or force value
    left_out_columns: list[str] = field(default_factory=list)  # the columns that leave a row out
    repeated: list[int] = field(default_factory=list)   # lines whose time equals the previous
    clock: bool = False     # the time column is written as clock times, read in seconds

    @property
    def name(self) -> str:
        """The file name without its folder and suffix."""
        return Path(self.path).stem


def delimiter_of(line: str, wanted: Sequence[str] = ()) -> str:
    """The cell separator of a file whose header starts with ``line``: the first of DELIMITERS
    found outside double quotes.  Where the line holds more than one, the first under which
    its names include every one of ``wanted`` (the columns to read): a semicolon file may have
    a name with a comma, "Temp, C".  Where it holds none, BLANKS if its names cut at spaces
    include every one of ``wanted``, else a comma (a one-column header)."""
    found = _separators(line)
    if not found:
        return BLANKS if wanted and set(wanted) <= set(_names(line, BLANKS)) else ","
    for d in found if len(found) > 1 and wanted else []:
        if set(wanted) <= set(_names(line, d)):
            return d
    return found[0] if found else ","


def _holding(line: str, wanted: Sequence[str]) -> str:
    """The first of DELIMITERS found in ``line`` outside double quotes (BLANKS where it holds
    none of them) under which its names include every one of ``wanted``; "" when none does (C
    twin: csv_in.c holding)."""
    return next((d for d in _separators(line) or [BLANKS]
                 if set(wanted) <= set(_names(line, d))), "")


def _advising(line: str, hint: Callable[[list[str]], str]) -> str:
    """The separator ``line``'s names are cut at -- its first of DELIMITERS, else BLANKS --
    when ``hint`` advises on those names; "" when it does not (C twin: csv_in.c advising)."""
    cut = (_separators(line) or [BLANKS])[0]
    return cut if hint(_names(line, cut)) else ""


def _separators(line: str) -> list[str]:
    """The DELIMITERS ``line`` holds outside double quotes, in their order (C twin: csv_in.c
    separators_seen)."""
    outside, quoted = [], False
    for ch in line:
        if ch == '"':
            quoted = not quoted
        elif not quoted:
            outside.append(ch)
    return [d for d in DELIMITERS if d in outside]


def _trailing_blanks_dropped(text: str) -> str:
    """A line without the spaces and tabs before its line break (C twin: csv_in.c
    trailing_blanks)."""
    body = text.rstrip("\r\n")
    return body.rstrip(" \t") + text[len(body):]


def _names(line: str, delimiter: str) -> list[str]:
    """The header line's names as ``delimiter`` would cut them: cut outside double quotes, the
    quotes dropped, each stripped (what :func:`delimiter_of` compares; C twin: csv_in.c
    names_hold)."""
    names, cell, quoted = [], [], False
    for ch in line:
        if ch == '"':
            quoted = not quoted
        elif ch == delimiter and not quoted:
            names.append("".join(cell).strip())
            cell = []
        else:
            cell.append(ch)
    return names + ["".join(cell).strip()]


def parse_cell(name: str, lineno: int, col: str, text: str, decimal_comma: bool = False
               ) -> float:
    """One cell as a finite float, or CsvError with the file, line and column.
    ``decimal_comma``: the file's cells are not separated by commas, so ``2,5`` is 2.5."""
    cell = text.strip()
    number = _NUMBER_DECIMAL_COMMA if decimal_comma else _NUMBER
    if number.fullmatch(cell):
        value = float(cell.replace(",", ".", 1))
        if math.isfinite(value):
            return value
        raise CsvError(f"{name}:{lineno}: column '{col}': not finite: {cell!r}")
    if _NOT_FINITE.fullmatch(cell):
        raise CsvError(f"{name}:{lineno}: column '{col}': not finite: {cell!r}")
    raise CsvError(f"{name}:{lineno}: column '{col}': not a number: {cell!r}")


#: what a time column holds when its first row is written as a clock (clock_time.Stamp.dated)
TIME_FORMS = {False: "a time of day", True: "a date and time"}


class _TimeColumn:
    """The time column's cells: numbers, or clock times (clock_time) when its first row is one;
    every row then in the first row's form (C twin: csv_in.c time_cell)."""

    def __init__(self) -> None:
        self.dated: bool | None = None      # None: numbers (or no row yet)
        self.numbers = False
        self.clock = ClockColumn()

    def read(self, name: str, lineno: int, col: str, text: str, decimal_comma: bool) -> float:
        cell = text.strip()
        stamp = None if self.numbers else read_stamp(cell, decimal_comma)
        if stamp is not None and self.dated in (None, stamp.dated):
            self.dated = stamp.dated
            return self.clock.seconds(stamp)
        if self.dated is not None:
            raise CsvError(f"{name}:{lineno}: column '{col}': not {TIME_FORMS[self.dated]} as "
                           f"in the first row: {cell!r}")
        self.numbers = True
        return parse_cell(name, lineno, col, cell, decimal_comma)


def read_table(path: str | os.PathLike[str], required: Sequence[str] = REQUIRED,
               sparse: Sequence[str] = (), increasing: str | None = "t_s",
               nan_ok: Sequence[str] = (), skip_missing: Sequence[str] = (),
               missing_hint: Callable[[list[str]], str] | None = None,
               repeat_left_out: bool = False, units_row: Sequence[str] = (),
               read: Sequence[str] | None = None) -> Table:
    """Read a numeric CSV by the rules of this module (see the module's docstring).
    ``missing_hint(header)``: advice appended to the refusal of a missing column ("" none).
    ``repeat_left_out``: a row whose ``increasing`` value equals the previous sample's is left
    out (listed in ``Table.repeated``) instead of refused.  ``units_row``: the columns whose
    cells name a unit in a units row: the first record after the header, when none of its
    cells is a number and one of these columns' cells at least reads as a unit
    (units_row.unit_like), is no sample: ``Table.units_row`` keeps these columns' non-empty
    cells (for units_row.units_row_check, which refuses what is not a unit).  ``read``: the
    columns read (None: every one); the others' cells are not looked at (a logger's state
    word, a note), a row with nothing in the columns read is no sample (skipped like a blank
    line), and ``Table.columns`` holds the columns read only."""
    name = str(path)
    try:
        fh = open(path, "rb")
    except OSError as exc:
        raise CsvError(f"{name}: cannot read: {exc.strerror or exc}") from None
    lineno = 0
    # the comments before the first line that is neither blank nor a comment, without their
    # mark, with their numbers: where no other line holds the names read, the last of them
    # that does is the header (numpy.savetxt writes its header so: "# t_s depth_mm force_n")
    leading_comments: list[tuple[int, str]] = []

    def numbered() -> Iterator[str]:
        """Decoded lines, comments skipped; ``lineno`` is the physical line last read."""
        nonlocal lineno
        started = False
        for raw in fh:
            lineno += 1
            try:
                text = raw.decode("utf-8-sig" if lineno == 1 else "utf-8")
            except UnicodeDecodeError:
                raise CsvError(f"{name}:{lineno}: not UTF-8 text") from None
            if text.startswith(COMMENT):
                if not started:
                    leading_comments.append((lineno, text[len(COMMENT):]))
                continue
            started = started or bool(text.strip())
            yield text

    def records() -> Iterator[list[str]]:
        """The csv module's records, split at the separator the header's first line shows
        (the blank lines before it are read with any: they hold no separator); where the first
        line that is not blank does not hold the names read (a logger's preamble), at the
        separator of the first line that does (:func:`_holding`), if one does; where none
        does, the last leading comment that holds them is the header, at its separator (or,
        where none does either, the last that missing_hint advises on, to be refused with
        that advice)."""
        nonlocal lineno, delimiter
        lines = numbered()
        ahead: list[tuple[int, str]] = []      # lines read ahead, with their numbers
        for text in lines:
            ahead.append((lineno, text))
            if text.strip():
                break
        begun = bool(ahead) and bool(ahead[-1][1].strip())     # a line not blank was found
        delimiter = delimiter_of(ahead[-1][1], required) if ahead else ","
        held = not required or (bool(ahead)
                                and set(required) <= set(_names(ahead[-1][1], delimiter)))
        if ahead and not held:
            for text in lines:
                ahead.append((lineno, text))
                found = _holding(text, required)
                if found:
                    delimiter, held = found, True
                    break
        if begun and not held:
            # the last leading comment that holds the names; else, for the refusal's advice,
            # the last whose names missing_hint advises on ("# time depth force")
            chosen = [(number, text, found) for number, text in leading_comments
                      if (found := _holding(text, required))]
            if not chosen and missing_hint is not None:
                chosen = [(number, text, found) for number, text in leading_comments
                          if (found := _advising(text, missing_hint))]
            if chosen:
                number, text, delimiter = chosen[-1]
                ahead.insert(sum(at < number for at, _ in ahead), (number, text))

        def replayed() -> Iterator[str]:
            nonlocal lineno
            for number, text in ahead:
                lineno = number
                yield text
        source = itertools.chain(replayed(), lines)
        if delimiter == BLANKS:
            # runs of spaces between cells (the csv module's skipinitialspace), none at a line's
            # end, which would make an empty last cell
            yield from csv.reader(map(_trailing_blanks_dropped, source), delimiter=BLANKS,
                                  skipinitialspace=True)
        else:
            yield from csv.reader(source, delimiter=delimiter)

    header: list[str] | None = None
    header_line = 0
    rows: list[list[float]] = []
    lines: list[int] = []
    prev_t = -math.inf
    t_index = -1
    sparse_idx: set[int] = set()
    skip_idx: set[int] = set()
    nan_idx: set[int] = set()
    left_out: list[int] = []
    repeated: list[int] = []
    delimiter = ","
    times = _TimeColumn()
    units_cells: dict[str, str] = {}
    units_line = 0
    read_idx: set[int] | None = None      # the columns read (None: every one)
    first_record = True                   # the record after the header: a units row?
    # the lines before the header (a logger's preamble) that were refused as one: the refusal
    # to give if no header comes, the first that advises how to read the file, else the first
    preamble: tuple[bool, str] | None = None
    preamble_last_width = 0     # the cells of the last line refused so (a header's: a sample's)
    try:
        with fh:
            for cells in records():
                if all(cell.strip() == "" for cell in cells):
                    continue                    # a blank line, or a row of empty cells
                if header is None:
                    names = [c.strip() for c in cells]
                    absent = next((col for col in required if col not in names), None)
                    positional = _positions(required)
                    sample = _is_data(cells, delimiter != ",",
                                      [int(c) - 1 for c in required] if positional else None)
                    by_position = absent is not None and sample and positional
                    beyond = [c for c in required if by_position and int(c) > len(cells)]
                    if beyond:
                        raise CsvError(f"{name}:{lineno}: column '{beyond[0]}': no such "
                                       f"position: the first sample has {len(cells)} cells")
                    if by_position:
                        # no header, the columns named by their positions: this is a sample
                        names = [str(k) for k in range(1, len(cells) + 1)]
                    elif absent is not None:
                        # a logger's preamble line, or a header without the names: refused
                        # when the samples begin (or the file ends) before the names come
                        advice = missing_hint(names) if missing_hint else ""
                        if sample and missing_hint and not advice:
                            advice = NO_HEADER_ADVICE
                        refusal = (f"{name}:{lineno}: column '{absent}': missing from the "
                                   f"header (have: {', '.join(names)})"
                                   + (f"; {advice}" if advice else ""))
                        if sample and preamble and not preamble[0] and \
                                advice == NO_HEADER_ADVICE and preamble_last_width != len(cells):
                            # a preamble, then samples: no header line ("Rig 3" before
                            # MATLAB's numbers).  A line just before them with as many cells
                            # is their header under other names: no such advice
                            raise CsvError(f"{preamble[1]}; {advice}")
                        if sample:
                            raise CsvError(preamble[1] if preamble else refusal)
                        if not preamble or (advice and not preamble[0]):
                            preamble = (bool(advice), refusal)
                        preamble_last_width = len(cells)
                        continue
                    header = names
                    header_line = 0 if by_position else lineno
                    if len(set(header)) != len(header):
                        dup = next(c for c in header if header.count(c) > 1)
                        raise CsvError(f"{name}:{lineno}: column '{dup}': duplicate column "
                                       f"name in the header")
                    t_index = header.index(increasing) if increasing in header else -1
                    sparse_idx = {header.index(c) for c in sparse if c in header}
                    skip_idx = {header.index(c) for c in skip_missing if c in header}
                    nan_idx = {header.index(c) for c in nan_ok if c in header}
                    if read is not None:
                        read_idx = {i for i, c in enumerate(header) if c in read}
                    if not by_position:
                        continue
                if len(cells) != len(header):
                    raise CsvError(f"{name}:{lineno}: expected {len(header)} cells, found "
                                   f"{len(cells)}")
                if first_record:
                    first_record = False
                    units_cells = _units_row(header, cells, units_row, delimiter != ",")
                    if units_cells:
                        units_line = lineno
                        continue
                if read_idx is not None and all(cells[i].strip() == "" for i in read_idx):
                    continue        # nothing in the columns read: another sensor's line
                missing = [is_missing(cell) for cell in cells]
                skip = any(missing[i] for i in skip_idx)
                row = [math.nan if ((read_idx is not None and i not in read_idx)
                                    or (missing[i] and (skip or i in sparse_idx))
                                    or (i in nan_idx and _NAN.fullmatch(cell.strip())))
                       else times.read(name, lineno, col, cell, delimiter != ",")
                       if i == t_index
                       else parse_cell(name, lineno, col, cell, delimiter != ",")
                       for i, (col, cell) in enumerate(zip(header, cells))]
                if skip:
                    left_out.append(lineno)     # a dropout: not a sample
                    continue
                if t_index >= 0:
                    t = row[t_index]
                    if repeat_left_out and t == prev_t:
                        repeated.append(lineno)     # the library would reject it: not later
                        continue
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
        raise CsvError(preamble[1] if preamble else f"{name}:1: no header line")
    skip_named = [c for c in skip_missing if c in header]
    if not rows and left_out:
        cols = "' or '".join(skip_named)
        raise CsvError(f"{name}:{left_out[0]}: no sample: every row after the header has a "
                       f"value missing in column '{cols}' ({len(left_out)} rows)")
    if not rows:
        raise CsvError(f"{name}:{header_line + 1}: no samples after the header")
    data = np.asarray(rows, dtype=np.float64)
    return Table(name, header, {c: data[:, i] for i, c in enumerate(header)
                                if read_idx is None or i in read_idx}, lines, left_out,
                 skip_named, repeated, times.dated is not None, units_cells, units_line)


def _positions(names: Sequence[str]) -> bool:
    """Whether every one of ``names`` is a column's position, from 1, in ASCII digits
    (``--columns t=1,depth=2,force=3``: a file without a header; C twin: csv_in.c
    positions)."""
    return all(re.fullmatch(r"[1-9][0-9]{0,8}", n, re.ASCII) for n in names)


def _is_data(cells: list[str], decimal_comma: bool, at: list[int] | None = None) -> bool:
    """Whether a record is a sample's, not a preamble's or a header's: two cells at least, each
    a number or missing (is_missing), a number among them (C twin: csv_in.c is_data).  ``at``:
    only the cells at these indices that the record has are judged (a file read by positions,
    whose other columns are not read: a logger's state word beside its numbers)."""
    number = _NUMBER_DECIMAL_COMMA if decimal_comma else _NUMBER
    judged = cells if at is None else [cells[i] for i in at if i < len(cells)]
    numbers = [bool(number.fullmatch(cell.strip())) for cell in judged]
    return (len(cells) >= 2 and any(numbers)
            and all(n or is_missing(cell) for n, cell in zip(numbers, judged)))


def _units_row(header: list[str], cells: list[str], named: Sequence[str],
               decimal_comma: bool) -> dict[str, str]:
    """The first record after the header as a units row (read_table's ``units_row``): the
    named columns' non-empty cells, or {} when it is not one."""
    number = _NUMBER_DECIMAL_COMMA if decimal_comma else _NUMBER
    if any(number.fullmatch(cell.strip()) for cell in cells):
        return {}
    found = {col: cell for col, cell in zip(header, cells) if col in named and cell.strip()}
    if not any(unit_like(cell) for cell in found.values()):
        return {}
    return found


#: the simulator's noise-free force, read with an insertion when the file has it (the plots
#: draw it; C twin: csv_in.c TRUTH_COLUMN, read and checked alike)
TRUTH_COLUMN = "force_true_n"


def read_trial(path: str | os.PathLike[str], required: Sequence[str] = REQUIRED,
               sparse: Sequence[str] = (), units: Units | None = None,
               limits: Limits = Limits(), force_ignored: bool = False) -> Trial:
    """An insertion: t_s, depth_mm, force_n and velocity_mm_s (given or central differences).

    ``force_ignored`` (--predict-only: the model runs on the depth alone): the force column
    may be absent, and a missing force keeps its row; such a force is NaN.

    With ``units``, the columns are the ones ``units.columns`` names (``required`` and
    ``sparse`` give standard names; each is read under its mapped name), converted from the
    file's units and signs to N, s, mm (a given velocity by depth unit / time unit and the depth
    sign) and, if ``units.check``, the result is checked by :func:`check_units` against
    ``limits``.  Without, nothing is mapped, converted or checked (the library's own files)."""
    cmap = units.columns if units is not None else ColumnMap()
    if force_ignored:
        required = tuple(c for c in required if c != "force_n")
        sparse = tuple(sparse) + ("force_n",)
    named = tuple(cmap.name(c) for c in required)
    if cmap.text and cmap.velocity is not None:
        named += (cmap.velocity,)       # a velocity the map names must be there
    sparse_named = tuple(cmap.name(c) for c in sparse)
    # a dropout of a measured quantity leaves its row out (one not in ``sparse``); the time
    # cannot be missing (it places the sample)
    data_named = (cmap.depth, cmap.force) + ((cmap.velocity,) if cmap.velocity else ())
    table = read_table(path, named, sparse_named, increasing=cmap.t,
                       skip_missing=tuple(c for c in data_named if c not in sparse_named),
                       missing_hint=None if cmap.text else unit_suffix_hint,
                       repeat_left_out=True, units_row=(cmap.t, cmap.depth, cmap.force),
                       read=named + sparse_named + (TRUTH_COLUMN,) + (
                           (cmap.velocity,) if cmap.velocity else ()))
    cols = table.columns
    t, depth = cols[cmap.t], cols[cmap.depth]
    force = cols[cmap.force] if cmap.force in cols else np.full(len(t), math.nan)
    given = cmap.velocity is not None and cmap.velocity in cols
    vel = cols[cmap.velocity] if given else None  # type: ignore[index]
    if units is not None:
        for kind, unit, known in (("force", units.force, FORCE_UNITS),
                                  ("time", units.time, TIME_UNITS),
                                  ("depth", units.depth, DEPTH_UNITS)):
            if unit not in known:
                raise CsvError(f"--{kind}-unit {unit}: not one of {', '.join(known)}")
        if table.clock and units.time != next(iter(TIME_UNITS)):
            raise CsvError(f"--time-unit {units.time}: column '{cmap.t}' holds clock times, "
                           f"read in seconds")
        if table.units_row:
            units_row_check(table.path, table.units_row_line, table.units_row, units)
        kt, kd = TIME_UNITS[units.time], DEPTH_UNITS[units.depth] * units.depth_sign
        kf = FORCE_UNITS[units.force] * units.force_sign
        if kt != 1.0:
            t = t * kt
        if kd != 1.0:
            depth = depth * kd
        if kf != 1.0:
            force = force * kf
        if units.depth_offset_mm != 0.0:
            depth = depth + units.depth_offset_mm
        if vel is not None and kd / kt != 1.0:
            vel = vel * (kd / kt)
    if vel is None:
        vel = central_difference(t, depth)
    tr = Trial(table.path, t, depth, force, vel, given, cols, table.lines, table.left_out,
               table.left_out_columns, table.repeated, table.clock)
    if units is not None and units.check:
        check_units(tr, units, limits)
    return tr


def left_out_note(tr: Trial) -> str | None:
    """The note an estimating tool writes (to stderr) when rows of ``tr`` were left out (None
    when none was): one line for the rows without a depth or force value (a dropout), one for
    the rows whose time equals the previous sample's (a repeat); each says how many and the
    first LEFT_OUT_LISTED lines.  C twin: csv_in.c nte_trial_left_out_note, word for word."""
    total = len(tr.t_s) + len(tr.left_out) + len(tr.repeated)
    named = "' or '".join(tr.left_out_columns)
    said = [_left_out_line(tr.path, rows, total, why)
            for rows, why in ((tr.left_out, f"a value missing in column '{named}' (a dropout"),
                              (tr.repeated, "the time equal to the previous sample's (a repeat"))
            if rows]
    return "\n".join(said) if said else None


def _left_out_line(path: str, rows: list[int], total: int, why: str) -> str:
    """One line of :func:`left_out_note`: ``why`` opens the parenthesis the lines close."""
    k = len(rows)
    listed = ", ".join(str(line) for line in rows[:LEFT_OUT_LISTED])
    more = f" and {k - LEFT_OUT_LISTED} more" if k > LEFT_OUT_LISTED else ""
    return (f"{path}: {k} of {total} rows left out, {why}: line{'s' if k > 1 else ''} "
            f"{listed}{more})")


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
