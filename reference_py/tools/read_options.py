"""What the CSV reader is told about a file, and how it says what to tell it.

Column map (:class:`ColumnMap`, ``--columns t=NAME,depth=NAME,force=NAME[,velocity=NAME]``)
    A logger's file is read as it is: the map names the file's columns that hold the time,
    the depth and the force (and the velocity; without ``velocity=`` it is computed from the
    depth, whatever other columns the file has).  Every rule of the reader (csvio) then
    applies to the mapped columns, and every message names them as the file does.  A map
    whose every name is a position, from 1 (``t=2,depth=3,force=1``), reads a file without a
    header (csvio.read_table: the names "1".."N" given to the first sample's cells).  With
    ``--time-unit us`` (and the other unit options) a time in microseconds, a depth in
    metres... are converted.

Units (:class:`Units`: ``--force-unit``, ``--time-unit``, ``--depth-unit``, the signs,
``--depth-offset``)
    How the mapped columns are converted to N, s and mm before anything else reads them
    (reference_py.tools.arguments parses the flags into one).

A header that names its quantities, with their units or without (:func:`unit_suffix_hint`)
    Not guessed at; the refusal of a missing standard column gives the options that read it.

Every refusal is a :class:`CsvError` (``--OPTION VALUE: reason`` for an option).  The reader,
:mod:`reference_py.tools.csvio`, re-exports these names.  C twins: column_map.c (the map),
csv_in.c unit_suffix_hint (the advice), nte_units.h (the tables, generated from here).
"""
from __future__ import annotations

import shlex
from dataclasses import dataclass
from typing import Sequence


class CsvError(ValueError):
    """Bad input: the message says which file, line and column, and why."""


#: the keys of --columns and the standard column each one stands for
COLUMN_KEYS = {"t": "t_s", "depth": "depth_mm", "force": "force_n", "velocity": "velocity_mm_s"}
#: the keys --columns must give (velocity is optional)
COLUMN_KEYS_REQUIRED = ("t", "depth", "force")

#: Units the reader converts from (factor to the tools' unit: N, s, mm; the first of each is
#: the tools' own).  gf, kgf: a gram- and a kilogram-force (standard gravity, 9.80665 m/s^2),
#: what a load cell read in grams or kilograms gives; lbf: a pound-force (0.45359237 kg at
#: standard gravity); kN: a materials tester's load cell; um: micrometres, a stage's encoder
#: counts; in: an inch, 25.4 mm; ns:
#: nanoseconds, a robot middleware's stamps (ROS exports its messages' times so, since 1970).
FORCE_UNITS = {"N": 1.0, "mN": 1.0e-3, "gf": 9.80665e-3, "kgf": 9.80665, "lbf": 4.4482216152605,
               "kN": 1.0e3}
TIME_UNITS = {"s": 1.0, "ms": 1.0e-3, "us": 1.0e-6, "ns": 1.0e-9}
DEPTH_UNITS = {"mm": 1.0, "m": 1.0e3, "um": 1.0e-3, "cm": 10.0, "in": 25.4}


#: what a header may name its insertion columns: one of the quantity's words, alone or with
#: one of its units in one of UNIT_NAME_FORMS (case aside: force_mN, t_ms, "Time [s]",
#: "Position (mm)", "Fz / N"; "Time", "Position", "Force").  The reader does not guess (a
#: column named so may hold anything); it says how to read them, a word alone in the tools'
#: own unit (the units check then judges the values: a time in ms read as s is refused with
#: --time-unit ms).  Per quantity: the --columns key, the --KIND-unit kind, the words (%time:
#: a ROS export's stamps), the units.
#: C twin: unit_suffix_hint in firmware/host/csv_in.c (test_run_columns: word for word).
UNIT_SUFFIX_QUANTITIES = (
    ("t", "time", ("t", "time", "timestamp", "%time"), TIME_UNITS),
    ("depth", "depth", ("depth", "position", "pos", "displacement", "insertion",
                        "insertion depth", "z", "extension"), DEPTH_UNITS),
    ("force", "force", ("force", "f", "fz", "load", "axial force"), FORCE_UNITS))
#: a word and a unit joined as loggers and spreadsheets write them: WORD + between + UNIT +
#: after, for each (between, after)
UNIT_NAME_FORMS = (("_", ""), (" [", "]"), ("[", "]"), (" (", ")"), ("(", ")"), (" / ", ""),
                   ("/", ""), (" in ", ""))
#: a unit as a name or a units row may write it with the micro sign (U+00B5) or the Greek mu
#: (U+03BC), or a second as loggers abbreviate it ("Time (sec)", "msec"): each (the unit the
#: options call it, the spelling)
UNIT_NAME_SPELLINGS = (("us", "\u00b5s"), ("us", "\u03bcs"), ("um", "\u00b5m"), ("um", "\u03bcm"),
                       ("s", "sec"), ("ms", "msec"))
def ascii_lower(text: str) -> str:
    """A-Z lowered, every other character as it is (the C twin compares so: str.lower would
    also lower a few letters beyond ASCII)."""
    return text.translate(_ASCII_LOWER)


_ASCII_LOWER = {c: c + 32 for c in range(ord("A"), ord("Z") + 1)}


def _named_with_unit(column: str, words: Sequence[str], unit: str) -> bool:
    """The column is one of ``words`` and ``unit`` (or one of its UNIT_NAME_SPELLINGS) in one
    of UNIT_NAME_FORMS, ASCII case aside."""
    name = ascii_lower(column)
    spellings = [unit] + [other for u, other in UNIT_NAME_SPELLINGS if u == unit]
    return any(name == ascii_lower(f"{word}{between}{spelled}{after}")
               for word in words for spelled in spellings for between, after in UNIT_NAME_FORMS)


def unit_suffix_hint(header: list[str]) -> str:
    """The options that read a header whose time, depth and force columns are named by their
    quantity, with their unit (t_ms, depth_m, "Force [mN]"...) or without ("Time", "Depth"):
    ``--columns t=..,depth=..,force=..`` (quoted for the shell where a name needs it) and a
    ``--KIND-unit U`` for every unit named that is not the tools' own; "" when a quantity has
    no such column or more than one (then nothing is sure enough to advise)."""
    mapped, options = [], []
    for key, kind, words, units in UNIT_SUFFIX_QUANTITIES:
        own = next(iter(units))            # the first unit of each table is the tools' own
        found = [(col, own) for col in header if ascii_lower(col) in words]
        found += [(col, unit) for col in header for unit in units
                  if _named_with_unit(col, words, unit)]
        if len(found) != 1:
            return ""
        col, unit = found[0]
        mapped.append(f"{key}={col}")
        if unit != own:
            options.append(f"--{kind}-unit {unit}")
    return "read it with --columns " + " ".join([shlex.quote(",".join(mapped))] + options)


@dataclass(frozen=True)
class ColumnMap:
    """Which of the file's columns hold the time, depth, force and velocity (the module's
    docstring, "Column map").  The default is the standard names, the velocity read when the
    file has it; a parsed map (``text`` not empty) reads the velocity only when it names it."""
    t: str = "t_s"
    depth: str = "depth_mm"
    force: str = "force_n"
    velocity: str | None = "velocity_mm_s"
    text: str = ""              # the --columns value it was parsed from ("": the standard names)

    @classmethod
    def parse(cls, text: str, force_optional: bool = False) -> "ColumnMap":
        """``t=NAME,depth=NAME,force=NAME[,velocity=NAME]``, or CsvError naming what is wrong:
        an item that is not KEY=NAME, an unknown or repeated key, a key missing, one column
        given two meanings.  ``force_optional`` (--predict-only, which reads no force): the
        map may leave out ``force=`` (the standard name then stands, absent or ignored)."""
        def refuse(why: str) -> CsvError:
            return CsvError(f"--columns {text}: {why}")

        keys = ", ".join(COLUMN_KEYS)
        given: dict[str, str] = {}
        for item in text.split(","):
            key, eq, name = (part.strip() for part in item.partition("="))
            if not eq or not key:
                raise refuse(f"{item.strip()!r} is not KEY=NAME (expected "
                             f"t=NAME,depth=NAME,force=NAME[,velocity=NAME])")
            if key not in COLUMN_KEYS:
                raise refuse(f"unknown key {key!r} (keys: {keys})")
            if key in given:
                raise refuse(f"key {key!r} given twice")
            if not name:
                raise refuse(f"key {key!r} names no column")
            twin = next((k for k, v in given.items() if v == name), None)
            if twin is not None:
                raise refuse(f"column {name!r} given for both {twin!r} and {key!r}")
            given[key] = name
        if force_optional:
            given.setdefault("force", COLUMN_KEYS["force"])
        missing = [k for k in COLUMN_KEYS_REQUIRED if k not in given]
        if missing:
            raise refuse(f"key {missing[0]!r} missing ({', '.join(COLUMN_KEYS_REQUIRED)} are "
                         f"required, velocity is optional)")
        return cls(given["t"], given["depth"], given["force"], given.get("velocity"), text)

    def name(self, standard: str) -> str:
        """The file's name of the column that stands for the standard column ``standard``
        (a column that is not an insertion's keeps its name)."""
        for key, std in COLUMN_KEYS.items():
            if std == standard:
                return getattr(self, key) or standard
        return standard


@dataclass(frozen=True)
class Units:
    """How a file's columns are converted to N, s, mm (and the sign conventions: depth grows
    into the tissue, force is positive while inserting), whether to check plausibility, and
    which columns hold what (``columns``)."""
    force: str = "N"
    time: str = "s"
    depth: str = "mm"
    force_sign: int = 1
    depth_sign: int = 1
    check: bool = True
    columns: ColumnMap = ColumnMap()
    depth_offset_mm: float = 0.0    # added to the depth after its unit and sign, mm


#: --depth-offset's range, mm: a stage's origin within a metre of the tissue
DEPTH_OFFSET_MAX_MM = 1000.0
