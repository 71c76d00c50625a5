"""A units row: the record under a header that names each column's unit, as materials testers
and spreadsheets write it (``"Time","Extension","Load"`` then ``"(s)","(mm)","(N)"``).

The reader (csvio.read_table) takes the first record after the header for a units row when
none of its cells is a number and each of the read columns' cells (time, depth, force) is
empty or names a unit, one at least (:func:`unit_of_token`); it is no sample.  The row is then
held to the options, not obeyed: a read column's unit must be the one it is read in
(``--KIND-unit``, the tools' own by default), or the refusal gives the option that reads it
(:func:`units_row_check`) -- the same rule as a unit in a column's name, which is advised, not
guessed.  C twin: firmware/host/units_row.c.
"""
from __future__ import annotations

from .read_options import (DEPTH_UNITS, FORCE_UNITS, TIME_UNITS, UNIT_NAME_SPELLINGS, CsvError,
                           Units, ascii_lower)

#: the brackets a units row's cell may put around its unit (one pair)
UNITS_ROW_BRACKETS = (("(", ")"), ("[", "]"))


def unit_of_token(cell: str) -> tuple[str, str] | None:
    """The (kind, unit) a units row's cell names: one of the unit tables' units or
    UNIT_NAME_SPELLINGS, bare or in one pair of UNITS_ROW_BRACKETS, ASCII case aside; None
    when it names none."""
    text = cell.strip()
    for opening, closing in UNITS_ROW_BRACKETS:
        if len(text) >= 2 and text.startswith(opening) and text.endswith(closing):
            text = text[1:-1].strip()
            break
    name = ascii_lower(text)
    spelled = {ascii_lower(other): unit for unit, other in UNIT_NAME_SPELLINGS}
    for kind, table in (("time", TIME_UNITS), ("depth", DEPTH_UNITS), ("force", FORCE_UNITS)):
        for unit in table:
            if name == ascii_lower(unit) or spelled.get(name) == unit:
                return kind, unit
    return None


def units_row_check(path: str, line: int, tokens: dict[str, str], units: Units) -> None:
    """Refuse (CsvError) a file whose units row names, for a column read, another quantity's
    unit or another unit than the one it is read in (--KIND-unit, the tools' own by default):
    the message gives the option that reads it.  ``tokens``: the read columns' cells (by the
    file's names), non-empty.  C twin: units_row.c nte_units_row_check."""
    cmap = units.columns
    for col, kind, given in ((cmap.t, "time", units.time), (cmap.depth, "depth", units.depth),
                             (cmap.force, "force", units.force)):
        if col not in tokens:
            continue
        named = unit_of_token(tokens[col])
        cell = tokens[col].strip()
        if named is None or named[0] != kind:
            raise CsvError(f"{path}:{line}: column '{col}': the units row's {cell!r} is not a "
                           f"unit of {kind}")
        if named[1] != given:
            raise CsvError(f"{path}:{line}: column '{col}': the units row gives {cell!r}: "
                           f"convert with --{kind}-unit {named[1]}")
