"""A units row: the record under a header that names each column's unit, as materials testers
and spreadsheets write it (``"Time","Extension","Load"`` then ``"(s)","(mm)","(N)"``).

The reader (csvio.read_table) takes the first record after the header for a units row when
none of its cells is a number and one of the read columns' cells (time, depth, force) at
least reads as a unit (:func:`unit_like`: a unit of the tools' tables, or any text in
brackets); it is no sample.  The row is then held to the options, not obeyed: each read
column's cell must name a unit of its quantity, or the refusal lists the units the tools read
(a load cell's "(V)" or a "kip" asks for a conversion, not for "not a number"), and that unit
must be the one the column is read in (``--KIND-unit``, the tools' own by default), or the
refusal gives the option that reads it (:func:`units_row_check`) -- the same rule as a unit in
a column's name, which is advised, not guessed.  C twin: firmware/host/units_row.c.
"""
from __future__ import annotations

from .read_options import (DEPTH_UNITS, FORCE_UNITS, TIME_UNITS, UNIT_NAME_SPELLINGS, CsvError,
                           Units, ascii_lower)

#: the brackets a units row's cell may put around its unit (one pair)
UNITS_ROW_BRACKETS = (("(", ")"), ("[", "]"))


def _in_brackets(text: str) -> str | None:
    """The stripped text inside one pair of UNITS_ROW_BRACKETS around stripped ``text``, or
    None when it has none."""
    for opening, closing in UNITS_ROW_BRACKETS:
        if len(text) >= 2 and text.startswith(opening) and text.endswith(closing):
            return text[1:-1].strip()
    return None


def unit_of_token(cell: str) -> tuple[str, str] | None:
    """The (kind, unit) a units row's cell names: one of the unit tables' units or
    UNIT_NAME_SPELLINGS, bare or in one pair of UNITS_ROW_BRACKETS, ASCII case aside; None
    when it names none."""
    text = cell.strip()
    inside = _in_brackets(text)
    name = ascii_lower(text if inside is None else inside)
    spelled = {ascii_lower(other): unit for unit, other in UNIT_NAME_SPELLINGS}
    for kind, table in (("time", TIME_UNITS), ("depth", DEPTH_UNITS), ("force", FORCE_UNITS)):
        for unit in table:
            if name == ascii_lower(unit) or spelled.get(name) == unit:
                return kind, unit
    return None


def unit_like(cell: str) -> bool:
    """Whether a units row's cell reads as a unit: it names one (unit_of_token), or it is text
    in one pair of UNITS_ROW_BRACKETS (a unit the tools do not read, which units_row_check
    then refuses by name).  C twin: units_row.c nte_unit_like."""
    return unit_of_token(cell) is not None or bool(_in_brackets(cell.strip()))


def units_row_check(path: str, line: int, tokens: dict[str, str], units: Units) -> None:
    """Refuse (CsvError) a file whose units row gives, for a column read, no unit of its
    quantity (the message lists the units the tools read) or another unit than the one it is
    read in (--KIND-unit, the tools' own by default: the message gives the option that reads
    it).  ``tokens``: the read columns' cells (by the
    file's names), non-empty.  C twin: units_row.c nte_units_row_check."""
    cmap = units.columns
    for col, kind, given, table in ((cmap.t, "time", units.time, TIME_UNITS),
                                    (cmap.depth, "depth", units.depth, DEPTH_UNITS),
                                    (cmap.force, "force", units.force, FORCE_UNITS)):
        if col not in tokens:
            continue
        named = unit_of_token(tokens[col])
        cell = tokens[col].strip()
        if named is None or named[0] != kind:
            raise CsvError(f"{path}:{line}: column '{col}': the units row's {cell!r} is not a "
                           f"unit of {kind} the tools read ({', '.join(table)}): convert the "
                           f"column to one of them")
        if named[1] != given:
            raise CsvError(f"{path}:{line}: column '{col}': the units row gives {cell!r}: "
                           f"convert with --{kind}-unit {named[1]}")
