"""clock_time (a time column written as a clock or a calendar) against Python's datetime.

The C twin (firmware/host/clock_time.c) is held to this module by test_run_reader's table;
this module is held here to the standard library: for dates and times drawn over the whole
calendar, in every zone and written in every form the reader takes, the seconds it reads are
datetime's seconds since 1970 UTC (fromisoformat, then timestamp arithmetic on whole seconds),
and a time of day's are the seconds since midnight, a day added at each pass over midnight.
"""
from __future__ import annotations

import datetime
import random

import pytest

from reference_py.tools.clock_time import ClockColumn, read_stamp

UTC = datetime.timezone.utc
EPOCH = datetime.datetime(1970, 1, 1, tzinfo=UTC)


def _draw(rng: random.Random) -> tuple[datetime.datetime, int]:
    """A date and time anywhere in the calendar (whole seconds) and a zone offset, minutes."""
    day = datetime.date.fromordinal(rng.randint(1, datetime.date(9999, 12, 31).toordinal()))
    clock = datetime.time(rng.randint(0, 23), rng.randint(0, 59), rng.randint(0, 59))
    return datetime.datetime.combine(day, clock), rng.choice([0, 60, -300, 330, 525, -690, 840])


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_dates_and_times_are_datetimes_seconds_since_1970(seed):
    rng = random.Random(seed)
    for _ in range(2000):
        naive, offset_min = _draw(rng)
        zone = datetime.timezone(datetime.timedelta(minutes=offset_min))
        aware = naive.replace(tzinfo=zone)
        want = (aware - EPOCH) // datetime.timedelta(seconds=1)
        sign = "+" if offset_min >= 0 else "-"
        hh, mm = divmod(abs(offset_min), 60)
        digits = f"{rng.randint(0, 10**6 - 1):06d}"
        for sep, t, z in [("-", " ", ""), ("-", "T", "Z"), ("/", " ", f"{sign}{hh:02d}:{mm:02d}"),
                          ("-", "T", f"{sign}{hh:02d}{mm:02d}")]:
            text = (f"{naive.year:04d}{sep}{naive.month:02d}{sep}{naive.day:02d}{t}"
                    f"{naive:%H:%M:%S}.{digits}{z}")
            stamp = read_stamp(text)
            assert stamp is not None and stamp.dated, text
            # no zone, or Z: the clock's own time, as if UTC
            expect = want if z not in ("", "Z") else (naive.replace(tzinfo=UTC) - EPOCH) \
                // datetime.timedelta(seconds=1)
            assert stamp.whole == expect and stamp.fraction == digits, text
            assert ClockColumn().seconds(stamp) == float(expect) + float("0." + digits)


def test_times_of_day_roll_over_midnight():
    col, out = ClockColumn(), []
    for text in ["23:59:59.5", "0:00:00.25", "11:59:00", "23:00:00", "00:00:01"]:
        stamp = read_stamp(text)
        assert stamp is not None and not stamp.dated
        out.append(col.seconds(stamp))
    # 11:59 is less than 12 h after 23:59:59.5 of the day before: the same (second) day
    assert out == [86399.5, 86400.25, 86400 + 43140, 86400 + 82800, 2 * 86400 + 1]


@pytest.mark.parametrize("text", ["2023-02-29 00:00:00", "2026-13-01 00:00:00", "24:00:00",
                                  "2026-11-30 23:59:60", "0000-01-01 00:00:00", "12:00:00Z",
                                  "2026-11-30 12:00:00+24:00", "123:00:00", "30.11.2026 12:00:00",
                                  "2026-11-30", "12:00:00.", "12:00:00,5", "2026-11-30X12:00:00",
                                  "2026-11/30 12:00:00", "12:60:00", "1:2:03", "\u0661:00:00"])
def test_what_is_not_a_clock(text):
    assert read_stamp(text) is None


def test_a_decimal_comma_where_cells_are_not_separated_by_commas():
    stamp = read_stamp("12:00:00,5", decimal_comma=True)
    assert stamp is not None and stamp.fraction == "5"
