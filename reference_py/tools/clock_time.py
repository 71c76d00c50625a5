"""A time column written as a clock or a calendar reads, in seconds.

A logger that stamps its rows with the wall clock writes ``12:00:00.010`` (a time of day) or
``2026-11-30 12:00:00.010`` / ``2026-11-30T12:00:00.010Z`` (a date and time, as pandas, ISO 8601
and most data loggers write them; ``/`` between the date's fields too, and a zone ``Z``,
``+01:00`` or ``+0100`` after a date's time).  Such a cell reads as:

* a date and time: the seconds since 1970-01-01 00:00 UTC (the zone's offset taken off; no
  zone: the clock's own time, as if UTC: only the differences matter to the estimator);
* a time of day: the seconds since midnight; a time more than 12 h before the previous one is
  taken as the next day's (a record across midnight).

The value is the whole seconds (an integer, exact) plus the fraction read as the decimal
``0.DIGITS`` (one rounding, the same as the C twin's strtod), so both readers give the same
bits.  Day-first and month-first dates (30.11.2026, 11/30/2026) are not read: which is which
cannot be told from the cell.  C twin: firmware/host/clock_time.c.
"""
from __future__ import annotations

import datetime
import re
from typing import NamedTuple

#: a date's fields (year, month, day, one separator for both), then ``T`` or a space
_DATE = r"(?P<y>\d{4})(?P<sep>[-/])(?P<mo>\d{2})(?P=sep)(?P<d>\d{2})[T ]"
#: a time of day: hours (one or two digits), minutes, seconds, an optional fraction
_CLOCK = r"(?P<h>\d{1,2}):(?P<mi>\d{2}):(?P<s>\d{2})(?:[MARKS](?P<frac>\d{1,18}))?"
#: a zone after a date's time
_ZONE = r"(?P<z>Z|[+-]\d{2}:?\d{2})"
#: the decimal marks of a fraction: a point, and a comma where the cells are not separated by
#: commas (csvio's decimal comma)
_MARKS = {False: r".", True: r".,"}
_CELL = {comma: re.compile(f"(?:{_DATE})?{_CLOCK.replace('MARKS', re.escape(m))}(?:{_ZONE})?",
                           re.ASCII)
         for comma, m in _MARKS.items()}

#: the day of 1970-01-01 (proleptic Gregorian ordinal)
_EPOCH_DAY = datetime.date(1970, 1, 1).toordinal()
SECONDS_PER_DAY = 86400
#: a time of day this far before the previous one is the next day's
ROLLOVER_S = 43200


class Stamp(NamedTuple):
    """A clock cell read: ``dated`` (a date and time) or a time of day; the whole seconds and
    the fraction's digits ("" none)."""
    dated: bool
    whole: int
    fraction: str


def read_stamp(cell: str, decimal_comma: bool = False) -> Stamp | None:
    """The cell (stripped) as a :class:`Stamp`, or None when it is not written as a clock or
    a date and time, or names an hour, minute, second, day or zone that does not exist."""
    m = _CELL[decimal_comma].fullmatch(cell)
    if m is None or (m["z"] is not None and m["y"] is None):
        return None                     # a zone belongs to a date's time only
    h, mi, s = int(m["h"]), int(m["mi"]), int(m["s"])
    if h > 23 or mi > 59 or s > 59:
        return None
    whole = h * 3600 + mi * 60 + s
    if m["y"] is None:
        return Stamp(False, whole, m["frac"] or "")
    try:
        day = datetime.date(int(m["y"]), int(m["mo"]), int(m["d"])).toordinal() - _EPOCH_DAY
    except ValueError:
        return None                     # no such day (month 13, 30 February, year 0)
    zone = m["z"]
    if zone is not None and zone != "Z":
        zh, zm = int(zone[1:3]), int(zone[-2:])
        if zh > 23 or zm > 59:
            return None
        whole -= (1 if zone[0] == "+" else -1) * (zh * 3600 + zm * 60)
    return Stamp(True, day * SECONDS_PER_DAY + whole, m["frac"] or "")


class ClockColumn:
    """The time column's clock cells in their order: the days a time of day has rolled over
    midnight (a time more than ROLLOVER_S before the previous one's)."""

    def __init__(self) -> None:
        self.days = 0
        self.previous: int | None = None

    def seconds(self, stamp: Stamp) -> float:
        """The stamp's seconds: the whole (a time of day's days added) plus the fraction."""
        whole = stamp.whole
        if not stamp.dated:
            if self.previous is not None and whole < self.previous - ROLLOVER_S:
                self.days += 1
            self.previous = whole
            whole += self.days * SECONDS_PER_DAY
        return float(whole) + (float("0." + stamp.fraction) if stamp.fraction else 0.0)
