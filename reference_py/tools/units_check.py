"""The units check of the CSV reader: whether an insertion read in N, s and mm looks like one.

:func:`check_units` refuses (:class:`UnitsError`) a trial whose values are implausible in the
tools' units and names the probable unit or convention and the option that converts it
(csvio.read_trial calls it after converting, unless ``--no-units-check``); :class:`Limits` are
the estimator's accepted ranges it judges against.  Every rule and threshold is here; the C
twin, firmware/host/units_check.c, gets the thresholds generated into nte_units.h and gives
the same messages word for word (tests/python/test_run_units.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ..config import EstimatorConfig
from ..fmath import Array
from .read_options import (COLUMN_KEYS, COLUMN_KEYS_REQUIRED, DEPTH_OFFSET_MAX_MM, DEPTH_UNITS,
                           FORCE_UNITS, TIME_UNITS, CsvError, Units)


class Insertion(Protocol):
    """What the check reads of an insertion (csvio.Trial, converted to N, s and mm)."""
    path: str
    t_s: Array
    depth_mm: Array
    force_n: Array           # NaN where no force was read (a sparse column)
    velocity_mm_s: Array
    lines: list[int]         # the physical line of every sample
    clock: bool              # the time was written as clock times (in seconds by its writing)


class UnitsError(CsvError):
    """The file's values are implausible in the tools' units: the message names the probable
    unit or convention and the option that converts it."""


@dataclass(frozen=True)
class Limits:
    """The estimator's accepted ranges (EstimatorConfig's defaults): beyond them a sample is
    rejected; a time step above dt_max_s restarts the state.  The defaults are read from
    EstimatorConfig (reference_py/config.py), the envelope's one source."""
    depth_min_mm: float = EstimatorConfig.depth_min_mm
    depth_max_mm: float = EstimatorConfig.depth_max_mm
    speed_max_mm_s: float = EstimatorConfig.speed_max_mm_s
    force_max_n: float = EstimatorConfig.force_max_n
    dt_max_s: float = EstimatorConfig.dt_max_s

    @classmethod
    def from_config(cls, cfg: object) -> "Limits":
        return cls(*(float(getattr(cfg, f)) for f in ("depth_min_mm", "depth_max_mm",
                                                     "speed_max_mm_s", "force_max_n",
                                                     "dt_max_s")))


#: A stroke shorter than this is not an insertion in mm (probably metres).
MIN_STROKE_MM = 1.0
#: Above this share of out-of-range samples a file is refused ("most samples rejected").
MAX_REJECTED_SHARE = 0.5
#: Above this share of forces beyond the range, the force column's unit is questioned.
MAX_FORCE_OUT_SHARE = 0.05
#: The force's sign is judged less its tare, the median of the first TARE_SAMPLES forces (a
#: record as measured starts in the air) ...
TARE_SAMPLES = 20
#: ... on the samples taken while inserting where it departs from the tare by more than this
#: share of its largest departure there (the air gap's samples sit at the tare, either sign)
SIGN_DEPART_SHARE = 0.1
#: Inserting: the velocity above this (and the depth > 0); the sign is judged on at least
#: INSERTING_MIN_SAMPLES such samples.
INSERTING_SPEED_MM_S = 0.5
INSERTING_MIN_SAMPLES = 10
#: Above this share of negative depths the depth is probably measured the other way.
NEGATIVE_DEPTH_SHARE = 0.5
#: The direction of an insertion is judged only where the force departs from its tare by more
#: than this many median absolute deviations of the tare's samples (a record in the air alone
#: departs by its noise, either way).
DEPARTURE_MADS = 15.0
#: A force beyond this many times the configured range is not a force in N.
FORCE_IMPLAUSIBLE_FACTOR = 1000.0
#: The words a time step's hint gives the smaller units it proposes.
TIME_UNIT_WORDS = {"ms": "milliseconds", "us": "microseconds", "ns": "nanoseconds"}


#: a stroke under MIN_STROKE_MM read as mm may be in one of these (the unit, its name): each
#: is named in which the stroke is MIN_STROKE_MM..STROKE_MAX_MM (a needle's: the values cannot
#: tell them apart, the rig's manual can); if none, each in which a shallow stroke would move
#: at a needle's speed (SLOW_SPEED_MM_S)
SHORT_STROKE_UNITS = (("m", "metres"), ("in", "inches"), ("cm", "centimetres"))
STROKE_MAX_MM = 200.0
#: ... and only when the depth also moves slower than this (mm/s, :func:`ramp_speed`; half the
#: slowest preset's 0.4 mm/s): a shallow indentation at a needle's speed (a relaxation test's
#: 0.5 mm ramp at 1 mm/s) is no unit question, while metres read as mm move at 0.02 mm/s at
#: most (at 20 mm/s), inches under 0.2 up to 5 mm/s (faster ones are not told from mm)
SLOW_SPEED_MM_S = 0.2
#: the ramp speed is measured between these fractions of the depth's reach from its start
RAMP_FROM, RAMP_TO = 0.1, 0.9


def ramp_speed(t: Array, d: Array) -> float:
    """How fast the depth moves (mm/s, as read): RAMP_TO - RAMP_FROM of its largest distance
    from the first sample over the time from first reaching RAMP_FROM of it to first reaching
    RAMP_TO (a ramp's speed, whatever holds or noise surround it; inf when one sample does it,
    0 when the depth never moves).  C twin: units_check.c ramp_speed."""
    away = np.abs(d - d[0])
    reach = float(np.max(away))
    if reach == 0.0:
        return 0.0
    k_from = int(np.argmax(away >= RAMP_FROM * reach))
    k_to = int(np.argmax(away >= RAMP_TO * reach))
    if k_to <= k_from:
        return math.inf
    return (RAMP_TO - RAMP_FROM) * reach / float(t[k_to] - t[k_from])


def _stroke_hint(stroke: float, speed: float, units: Units) -> str:
    """The advice for a depth that spans under MIN_STROKE_MM at ``speed`` (C twin:
    units_check.c stroke_hint)."""
    named = [(u, word) for u, word in SHORT_STROKE_UNITS
             if MIN_STROKE_MM <= stroke * DEPTH_UNITS[u] <= STROKE_MAX_MM]
    if not named:
        named = [(u, word) for u, word in SHORT_STROKE_UNITS
                 if speed * DEPTH_UNITS[u] >= SLOW_SPEED_MM_S]
    if units.depth != "mm" or not named:
        return "no insertion"
    words = [word for _, word in named]
    said = words[0] if len(words) == 1 else f"{', '.join(words[:-1])} or {words[-1]}"
    return (f"probably {said}: convert with "
            + " or ".join(f"--depth-unit {u}" for u, _ in named))


def _pct(x: float) -> str:
    return f"{100.0 * x:.0f} %"


def _time_hint(dt: float, unit: str, dt_max: float, clock: bool) -> str:
    """Why a median time step of ``dt`` s (read as ``unit``) is too long: the smaller unit
    (of TIME_UNITS, after ``unit``) that makes it fit the gap limit, or too coarse (a clock's
    time is in seconds by its writing: a logger that stamps whole seconds at 100 Hz)."""
    units = list(TIME_UNITS)
    for smaller in units[units.index(unit) + 1:] if not clock else []:
        if dt * TIME_UNITS[smaller] / TIME_UNITS[unit] <= dt_max:
            return f"probably {TIME_UNIT_WORDS[smaller]}: convert with --time-unit {smaller}"
    return "too coarse for the estimator"


def check_units(tr: Insertion, units: Units = Units(), limits: Limits = Limits()) -> None:
    """Refuse (UnitsError) a trial whose values, in N, s and mm, are implausible: time steps of
    seconds (ms or us read as s), a depth stroke under a millimetre at under a needle's speed
    (m, in or cm read as mm: _stroke_hint, ramp_speed), depths mostly outside the accepted
    range that a thousandth would bring in (um read as mm), depth mostly negative (the other
    way, the force's sign with it when read so it is negative while inserting; or an origin
    before the needle's start when the depth grows where the force first departs:
    --depth-offset), falling where the force first rises or first falls (_check_direction: a
    stage counting down, the sensor inverted too) or force mostly negative while inserting
    (the opposite sign; judged from the air's tare, _air_tare), force mostly beyond the
    configured range (mN or gf read as N), a force beyond a thousand times the range, or most
    samples outside the estimator's accepted ranges.  The message names the column, the
    probable unit or convention and the option that converts it."""
    n = len(tr.t_s)
    name = tr.path
    # the file's names of the time, depth and force columns (--columns)
    ct, cd, cf = (units.columns.name(COLUMN_KEYS[k]) for k in COLUMN_KEYS_REQUIRED)
    fmax = limits.force_max_n
    if n >= 2:
        dt = float(np.median(np.diff(tr.t_s)))
        if dt > limits.dt_max_s:
            raise UnitsError(f"{name}: column '{ct}': median time step {dt:.4g} s "
                             f"(longer than the {limits.dt_max_s:g} s gap limit): "
                             f"{_time_hint(dt, units.time, limits.dt_max_s, tr.clock)}")
    d = tr.depth_mm
    stroke = float(np.max(d) - np.min(d))
    # (a depth that never moves, or a shallow one at a needle's speed, is no unit question)
    speed = ramp_speed(tr.t_s, d) if 0.0 < stroke < MIN_STROKE_MM else math.inf
    if speed < SLOW_SPEED_MM_S:
        hint = _stroke_hint(stroke, speed, units)
        raise UnitsError(f"{name}: column '{cd}': the depth spans only {stroke:.4g} mm at "
                         f"{speed:.2g} mm/s (less than {MIN_STROKE_MM:g} mm, slower than "
                         f"{SLOW_SPEED_MM_S:g} mm/s): {hint}")
    far = float(np.mean((d < limits.depth_min_mm) | (d > limits.depth_max_mm)))
    um = DEPTH_UNITS["um"]
    if (far > MAX_REJECTED_SHARE and units.depth == "mm" and stroke * um >= MIN_STROKE_MM
            and np.all((d * um >= limits.depth_min_mm) & (d * um <= limits.depth_max_mm))):
        raise UnitsError(f"{name}: column '{cd}': {_pct(far)} of the depths are outside the "
                         f"accepted range {limits.depth_min_mm:g}..{limits.depth_max_mm:g} mm "
                         f"(from {float(np.min(d)):.4g} to {float(np.max(d)):.4g}): probably "
                         f"micrometres: convert with --depth-unit um")
    f = tr.force_n
    present = np.isfinite(f)
    # the force is judged less its tare, where it departs from the tare: a record starts
    # in the air, and a negative tare over a long air gap is no sign
    tare = float(np.median(f[present][:TARE_SAMPLES])) if np.any(present) else 0.0
    rel = np.where(present, f - tare, 0.0)
    neg = float(np.mean(d < 0.0))
    if neg > NEGATIVE_DEPTH_SHARE:
        first, _ = _first_departures(tr.velocity_mm_s, rel, present)
        grows = tr.velocity_mm_s[first] > 0.0
        if (units.depth_sign == 1 and len(first) == INSERTING_MIN_SAMPLES
                and 2 * int(np.count_nonzero(grows)) > len(first)):
            # the force first departs while the depth grows: the direction is right, the
            # origin is not (a stage counting up from before the needle's start) - and the
            # force's sign too if it first falls
            falls = 2 * int(np.count_nonzero(grows & (rel[first] < 0.0))) > len(first)
            raise UnitsError(f"{name}: column '{cd}': {_pct(neg)} of the depths are negative "
                             f"(down to {float(np.min(d)):.4g} mm) although the depth grows "
                             f"where the force first {'falls' if falls else 'rises'} from its "
                             f"tare: the stage counts from an origin before the needle's start"
                             f"{', and the force is measured the other way' if falls else ''}: "
                             f"{_offset_advice(units, d, falls)}")
        if units.depth_sign == 1:
            # read the other way, would the force still be pulled while inserting?  Then
            # both columns are: one message, not two in turn
            both = _negative_while_inserting(rel, present, -tr.velocity_mm_s, -d)
            also = "" if both is None else (
                f", and the force with it (read that way, the force less its tare is negative "
                f"in {_pct(both)} of the samples taken while inserting)")
            raise UnitsError(f"{name}: column '{cd}': {_pct(neg)} of the depths are negative "
                             f"(down to {float(np.min(d)):.4g} mm): probably measured the "
                             f"other way{also}: {_sign_advice(units, True, both is not None)}")
        # the sign was given: a stage that counts down to the tissue from a positive origin
        raise UnitsError(f"{name}: column '{cd}': {_pct(neg)} of the depths are negative with "
                         f"--depth-sign -1 (down to {float(np.min(d)):.4g} mm): the stage "
                         f"counts from an origin beyond the tissue: {_offset_advice(units, d)}")
    fa = np.abs(f[present])
    if len(fa):
        out = float(np.mean(fa > fmax))
        if out > MAX_FORCE_OUT_SHARE:
            peak = float(np.max(fa))
            if units.force == "N" and peak * FORCE_UNITS["gf"] <= fmax:
                # a factor 9.8 apart: the values cannot tell them, the rig's manual can
                hint = ("probably millinewtons, or grams-force (a load cell read in grams): "
                        "convert with --force-unit mN or --force-unit gf")
            elif units.force == "N" and peak * FORCE_UNITS["mN"] <= fmax:
                hint = "probably millinewtons: convert with --force-unit mN"
            else:
                hint = "not a force in N"
            raise UnitsError(f"{name}: column '{cf}': {_pct(out)} of the forces exceed the "
                             f"configured range ±{fmax:g} N (up to {peak:.4g}): {hint}")
        k = int(np.argmax(np.where(present, np.abs(f), -1.0)))
        if abs(float(f[k])) > FORCE_IMPLAUSIBLE_FACTOR * fmax:
            line = f":{tr.lines[k]}" if tr.lines else ""
            raise UnitsError(f"{name}{line}: column '{cf}': {float(f[k]):.4g} N is not a "
                             f"plausible force (the configured range is ±{fmax:g} N)")
        _check_direction(tr, units, cd, tare, rel, present)
        air = _air_tare(tr, present, tare)
        share = _negative_while_inserting(np.where(present, f - air, 0.0), present,
                                          tr.velocity_mm_s, d)
        if share is not None:
            raise UnitsError(f"{name}: column '{cf}': the force less its tare ({air:.4g} "
                             f"N) is negative in {_pct(share)} of the samples taken while "
                             f"inserting: probably the sensor's opposite sign: "
                             f"{_sign_advice(units, False, True)}")
    bad = ((d < limits.depth_min_mm) | (d > limits.depth_max_mm)
           | (np.abs(tr.velocity_mm_s) > limits.speed_max_mm_s)
           | (present & (np.abs(np.where(present, f, 0.0)) > fmax)))
    share = float(np.mean(bad))
    if share > MAX_REJECTED_SHARE:
        raise UnitsError(f"{name}: {int(np.count_nonzero(bad))} of {n} samples "
                         f"({_pct(share)}) are outside the estimator's accepted ranges (depth "
                         f"{limits.depth_min_mm:g}..{limits.depth_max_mm:g} mm, speed "
                         f"±{limits.speed_max_mm_s:g} mm/s, force ±{fmax:g} N): check the "
                         f"units (--time-unit, --depth-unit, --force-unit) and signs")


def _air_tare(tr: Insertion, present: np.ndarray, tare: float) -> float:
    """The force in the air, which the force's sign is judged from: the ``tare`` of the first
    forces, unless the record ends more than MIN_STROKE_MM shallower than it starts (the
    medians of the first and last TARE_SAMPLES depths) - a logger started, or a node restarted,
    with the needle in the tissue: its first forces are the tissue's, and the median of its
    last forces is the air's."""
    d = tr.depth_mm
    if float(np.median(d[-TARE_SAMPLES:])) < float(np.median(d[:TARE_SAMPLES])) - MIN_STROKE_MM:
        return float(np.median(tr.force_n[present][-TARE_SAMPLES:]))
    return tare


def _negative_while_inserting(rel: np.ndarray, present: np.ndarray, v: np.ndarray,
                              d: np.ndarray) -> float | None:
    """The share of negative forces (``rel``: less the tare) among the samples taken while
    inserting (velocity ``v`` above INSERTING_SPEED_MM_S at depth ``d`` > 0) that depart from
    the tare by more than SIGN_DEPART_SHARE of the largest departure there, if their median is
    negative (the sensor's opposite sign); None if it is not, or too few samples say."""
    inserting = present & (v > INSERTING_SPEED_MM_S) & (d > 0.0)
    if np.count_nonzero(inserting) < INSERTING_MIN_SAMPLES:
        return None
    top = float(np.max(np.abs(rel[inserting])))
    fi = rel[inserting & (np.abs(rel) > SIGN_DEPART_SHARE * top)]
    if len(fi) < INSERTING_MIN_SAMPLES or float(np.median(fi)) >= 0.0:
        return None
    return float(np.mean(fi < 0.0))


def _first_departures(v: np.ndarray, rel: np.ndarray, present: np.ndarray
                      ) -> tuple[np.ndarray, float]:
    """The first INSERTING_MIN_SAMPLES samples taken while the stage moves (speed ``v`` above
    INSERTING_SPEED_MM_S either way) where the force (``rel``: less its tare) departs from the
    tare by more than SIGN_DEPART_SHARE of its largest departure while moving, and that
    departure; fewer (none) when too few samples move or depart."""
    moving = present & (np.abs(v) > INSERTING_SPEED_MM_S)
    if np.count_nonzero(moving) < INSERTING_MIN_SAMPLES:
        return np.zeros(0, dtype=np.int64), 0.0
    top = float(np.max(np.abs(rel[moving])))
    first = np.flatnonzero(moving & (np.abs(rel) > SIGN_DEPART_SHARE * top))
    return first[:INSERTING_MIN_SAMPLES], top


def _offset_advice(units: Units, d: np.ndarray, force: bool = False) -> str:
    """The --depth-offset that makes the needle start at 0 mm (its first depth, ``d`` as read
    with ``units``' offset), or, beyond its range, what to do instead; with ``force``, the
    force's sign turned over too."""
    offset = units.depth_offset_mm - float(d[0])
    if abs(offset) > DEPTH_OFFSET_MAX_MM:
        also = f" and {_sign_advice(units, False, True)}" if force else ""
        return f"subtract its start so the needle starts at 0 mm or above{also}"
    add, drop = [f"--depth-offset {offset:.6g}"], []
    if force:
        (drop if units.force_sign == -1 else add).append("--force-sign -1")
    return (f"convert with {' '.join(add)}" +
            (f" and read it without {' '.join(drop)}" if drop else "") +
            " (the needle then starts at 0 mm)")


def _sign_advice(units: Units, depth: bool, force: bool) -> str:
    """The options that turn the depth's and/or the force's sign over from ``units``' reading:
    a sign not given is added, one given is dropped."""
    add, drop = [], []
    for turn, option, given in ((depth, "--depth-sign -1", units.depth_sign == -1),
                                (force, "--force-sign -1", units.force_sign == -1)):
        if turn:
            (drop if given else add).append(option)
    said = ([f"convert with {' '.join(add)}"] if add else []) + \
        ([f"read it without {' '.join(drop)}"] if drop else [])
    return " and ".join(said)


def _check_direction(tr: Insertion, units: Units, column: str, tare: float, rel: np.ndarray,
                     present: np.ndarray) -> None:
    """Refuse a depth that runs the other way although its values are positive (a stage that
    counts down towards the tissue; read as it is, its insertion looks like a retraction and
    the force's sign would be blamed).  ``column``: the depth column's name in the file;
    ``rel``: the force less its ``tare``, 0 where it is missing (``present`` false).

    The needle loads the force as it goes in, so where the force first leaves its ``tare``
    (the first TARE_SAMPLES forces') while the stage moves, the depth must grow.  The first
    INSERTING_MIN_SAMPLES moving samples that depart by more than SIGN_DEPART_SHARE of the
    largest departure decide: more than half rising while the depth falls is refused, if
      * the record starts and ends in the air: its last TARE_SAMPLES forces are back at the
        tare.  One that starts in the tissue is no such case: retracting first, its force
        falls from its first "tare"; restarted mid-retraction, its first "tare" is the
        friction's pull below 0, the force rises from it as the needle leaves and never
        comes back to it;
      * the largest departure exceeds DEPARTURE_MADS median absolute deviations of the
        tare's samples: a record of the air alone departs by its noise, either way."""
    v = tr.velocity_mm_s
    first, top = _first_departures(v, rel, present)
    if len(first) < INSERTING_MIN_SAMPLES:
        return
    against = int(np.count_nonzero((v[first] < 0.0) & (rel[first] > 0.0)))
    # ... in a record that starts and ends in the air (its last forces back at the first ones'
    # tare): one that starts in the tissue, a node restarted mid-retraction, has a first
    # "tare" the needle's friction pulls below 0, and the force rises from it as it leaves
    forces = tr.force_n[present]
    end = float(np.median(forces[-TARE_SAMPLES:]))
    mad = float(np.median(np.abs(forces[:TARE_SAMPLES] - tare)))
    in_air = abs(end - tare) <= SIGN_DEPART_SHARE * top
    if top > DEPARTURE_MADS * mad and in_air and 2 * against > len(first):
        k = int(first[0])
        raise UnitsError(f"{tr.path}: column '{column}': the force "
                         f"first rises from its tare while the depth decreases (from "
                         f"{float(tr.t_s[k]):.4g} s, at {float(tr.depth_mm[k]):.4g} mm): a "
                         f"needle goes in towards larger depths: probably measured the other "
                         f"way: {_sign_advice(units, True, False)}")
    # The same stage with the sensor inverted too: the force first *falls* while the depth
    # decreases, and last departs from its tare while the depth grows (the needle leaving).
    # A correct record read from its reversal on (a node restarted there) also first falls
    # while the depth decreases, but it leaves the tissue the same way: its last departures
    # are still taken while the depth decreases.
    departing = np.flatnonzero(present & (np.abs(rel) > SIGN_DEPART_SHARE * top))
    early, late = departing[:INSERTING_MIN_SAMPLES], departing[-INSERTING_MIN_SAMPLES:]
    falling = int(np.count_nonzero((v[early] < 0.0) & (rel[early] < 0.0)))
    leaving = int(np.count_nonzero(v[late] > 0.0))
    if (len(early) == INSERTING_MIN_SAMPLES and top > DEPARTURE_MADS * mad and in_air
            and 2 * falling > len(early) and 2 * leaving > len(late)):
        k = int(early[0])
        raise UnitsError(f"{tr.path}: column '{column}': the force first falls from its tare "
                         f"while the depth decreases (from {float(tr.t_s[k]):.4g} s, at "
                         f"{float(tr.depth_mm[k]):.4g} mm): a needle goes in towards larger "
                         f"depths and pushes the force up: probably both the depth and the "
                         f"force measured the other way: {_sign_advice(units, True, True)}")
