"""The command lines' shared arguments: one-line refusals, bounded numbers, the input CSV's units.

Every command of the project (``nte-ref``, ``nte-discrepancy``, ``nte-bench``) parses its flags
with these, so a refusal reads the same everywhere -- ``PROG: error: argument --flag: why (see
PROG --help)``, exit status 2 -- and every reader of an insertion CSV takes the same unit and sign
flags.  They live apart from the commands so that a command never imports another command.
"""
from __future__ import annotations

import argparse
import math
import sys
from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:
    from .csvio import Units

EXIT_BAD_INPUT = 2


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Keeps the description's layout and shows every flag's default in --help (a flag
    without a default says so in its own help text)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        shown = action.default is not None and action.default is not False \
            and action.default != argparse.SUPPRESS
        if shown and action.option_strings and "default" not in text:
            text += " (default: %(default)s)"
        return text


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose refusals are one line on stderr and exit status 2:
    ``PROG: error: argument --flag: why (see PROG --help)``."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]

    def error(self, message: str) -> None:  # type: ignore[override]
        print(f"{self.prog}: error: {message} (see {self.prog} --help)", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT)


def bounded(lo: float, hi: float, unit: str = "", *, integer: bool = False,
            lo_open: bool = False) -> Callable[[str], float]:
    """An argparse type: a finite number (an integer if ``integer``) in [lo, hi], or in
    (lo, hi] if ``lo_open``; otherwise a message with the range, the unit and the value."""
    kind = "an integer" if integer else "a number"

    def show(x: float) -> str:
        return str(int(x)) if integer else f"{x:g}"

    low = f"> {show(lo)}" if lo_open else f">= {show(lo)}"

    def parse(text: str) -> float:
        try:
            value: float = int(text, 10) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not {kind}: {text!r}") from None
        if not math.isfinite(value) or value < lo or (lo_open and value <= lo) or value > hi:
            raise argparse.ArgumentTypeError(f"must be {low} and <= {show(hi)}{unit} (got {text})")
        return value

    parse.__name__ = kind  # argparse names the type in its own messages
    return parse


def _sign(text: str) -> int:
    if text not in ("1", "+1", "-1"):
        raise argparse.ArgumentTypeError(f"must be +1 or -1 (got {text!r})")
    return -1 if text == "-1" else 1


def add_unit_arguments(p: argparse.ArgumentParser) -> None:
    """The input conversion flags of every tool that reads an insertion CSV (csvio.Units)."""
    from .csvio import DEPTH_OFFSET_MAX_MM, DEPTH_UNITS, FORCE_UNITS, TIME_UNITS
    g = p.add_argument_group("units and signs of the input CSV (converted by the reader; "
                             "implausible values are refused naming the likely option)")
    g.add_argument("--force-unit", choices=tuple(FORCE_UNITS), default="N",
                   help="unit of the force_n column (or the one --columns names force)")
    g.add_argument("--time-unit", choices=tuple(TIME_UNITS), default="s",
                   help="unit of the t_s column (or the one --columns names t; us: "
                        "microseconds)")
    g.add_argument("--depth-unit", choices=tuple(DEPTH_UNITS), default="mm",
                   help="unit of the depth_mm (and velocity_mm_s, per time unit) column (or "
                        "the ones --columns names)")
    g.add_argument("--force-sign", type=_sign, default=1, metavar="+1|-1",
                   help="-1: the sensor reads the insertion force as negative")
    g.add_argument("--depth-sign", type=_sign, default=1, metavar="+1|-1",
                   help="-1: the depth column grows out of the tissue")
    g.add_argument("--depth-offset", type=bounded(-DEPTH_OFFSET_MAX_MM, DEPTH_OFFSET_MAX_MM,
                                                  " mm"), default=0.0, metavar="MM",
                   help="added to the depth after --depth-unit and --depth-sign: a stage that "
                        "counts from an origin beyond the tissue (e.g. down from 120 mm: "
                        "--depth-sign -1 --depth-offset 120) reads from 0")
    g.add_argument("--no-units-check", action="store_true",
                   help="do not refuse implausible units or signs (default: check)")
    g.add_argument("--columns", metavar="MAP",
                   help="the file's own column names, as t=NAME,depth=NAME,force=NAME"
                        "[,velocity=NAME]: a logger's CSV read as it is (e.g. "
                        "t=time_us,depth=pz,force=fz with --time-unit us); the velocity is "
                        "computed from the depth unless the map names it (default: t_s, "
                        "depth_mm, force_n and velocity_mm_s if present)")


def units_from(a: argparse.Namespace) -> "Units":
    """The reader's Units from the flags of add_unit_arguments; a malformed --columns is a
    CsvError (``--columns MAP: reason``).  Under --predict-only the map may leave out the
    force (none is read)."""
    from .csvio import ColumnMap, Units
    columns = ColumnMap() if a.columns is None else ColumnMap.parse(
        a.columns, force_optional=bool(getattr(a, "predict_only", False)))
    return Units(a.force_unit, a.time_unit, a.depth_unit, a.force_sign, a.depth_sign,
                 not a.no_units_check, columns, a.depth_offset)
