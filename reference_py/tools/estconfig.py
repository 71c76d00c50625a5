"""The estimator configuration file (``--config FILE``, schema ``nte-estimator-config/1``).

One reader for both writers: the discrepancy workflow's ``estimator_config.json``
(DISCREPANCY.md §7) and ``--export-config`` of ``nte-ref estimate`` / ``nte-run``.  The C
twin (firmware/config_json/nte_config_file.c) applies the same rules in the same order with the same
message text; tests/python/test_config_loop.py runs both over a table of bad files and asserts
identical lines.  Keep the two in step: every rule below has its twin there.

Mapping onto the estimator (every key optional unless marked):

* ``schema`` (required) = ``nte-estimator-config/1``;
* ``model`` (required) 1, 2 or 3 — the ``--model`` flag overrides it (the workflow writes 2,
  so ``--model 3`` turns its findings into Model III's constants);
* ``params`` (required): the seven force-model values, the new nominal (starting) values;
  sigma0, sigma1, sigma2, f1, alpha, beta > 0, |f2| <= 1000, each <= 1000 and g(0) = f1 + f2 > 0
  when f2 < 0 (the scaled form keeps every sign; MODEL.md §3); Model I's beta0 is ``beta``;
* ``r_n2`` > 0: the measurement noise variance;
* ``surface_mm``: a number (a known surface, stage position: the front end on), ``null`` or a
  list of numbers/nulls (the workflow's per-trial surfaces: they describe its trials, not the
  file being run, so the front end is on and finds the surface from the force);
* ``tare_n``: a number, ``null`` or a list (checked, not used: the tare is learned online);
* ``effects.dwell_relaxation``: ``tau_fast_s``, ``tau_slow_s`` (> 0, <= 3600 s) and
  ``relative_decay_median`` (in (0, 1), or null): the fraction a held force loses, split
  between the nominal strengths in RELAX_NOMINAL's ratio (0.15 : 0.25);
* ``effects.reversal_presliding.presliding_mm`` (> 0, <= 1000 mm): the turn-over length;
* ``model3`` (the export's block; wins over ``effects``): ``direction_memory``, ``relaxation``
  (booleans), ``relax_branches`` (1 or 2), ``presliding_mm``, ``tau_fast_s``, ``tau_slow_s``,
  ``strengths`` {``g_fast``, ``g_slow``} in (0, 1) with a sum < 1, ``layer_sets`` (a list of
  at most LAYER_MAX - 1 objects {``start_mm``, ``sigma0``, ``f1``, ``beta``, ``sigma2``}: the
  layers below the first in depth order, used in predict-only mode; MODEL.md §3b part 3).

Unknown keys are ignored (the workflow writes its evidence beside the configuration).
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field

from typing import Callable

from ..config import EstimatorConfig, LayerSet
from ..layers import LAYER_MAX
from ..params import LAYER_SET_NAMES, PARAM_NAMES, RELAX_NAMES, RELAX_NOMINAL

CONFIG_SCHEMA = "nte-estimator-config/1"
#: |x| of every nominal value (config.NOMINAL_ABS_MAX)
PARAM_MAX = 1000.0
#: |surface_mm|: a surface is a stage position, accepted within +-depth_max_mm (ContactConfig)
SURFACE_MAX_MM = EstimatorConfig.depth_max_mm
#: the parameters that must be positive (f2 may take either sign)
POSITIVE_PARAMS = ("sigma0", "sigma1", "sigma2", "f1", "alpha", "beta")


class ConfigFileError(ValueError):
    """A refused configuration file: ``FILE: key 'KEY': reason`` (or ``FILE: reason``)."""


@dataclass
class FileConfig:
    """What a configuration file sets (None: not given, the flag or default stays)."""
    model: int
    params: list[float]                       # PARAM_NAMES order
    r_n2: float | None = None
    surface_mm: float | None = None           # a known surface
    surface_list: bool = False                # per-trial surfaces: find it from the force
    m3: dict[str, object] = field(default_factory=dict)   # EstimatorConfig fields
    strengths: dict[str, float] = field(default_factory=dict)


def _is_num(v: object) -> bool:
    """A finite JSON number (an integer too large for a double is not finite: C reads inf)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    try:
        return math.isfinite(float(v))
    except OverflowError:
        return False


def _no_constants(name: str) -> object:
    # NaN and Infinity are not JSON (cJSON refuses them too)
    raise ValueError(name)


def read_config_file(path: str) -> FileConfig:
    """Read and check ``path``; raise ConfigFileError with the one-line message."""
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except OSError as e:
        raise ConfigFileError(f"{path}: cannot read: {os.strerror(e.errno or 0)}") from None
    try:
        doc = json.loads(raw.decode("utf-8"), parse_constant=_no_constants)
    except (UnicodeDecodeError, ValueError):
        raise ConfigFileError(f"{path}: not valid JSON") from None
    if not isinstance(doc, dict):
        raise ConfigFileError(f"{path}: not a JSON object")

    def fail(key: str, why: str) -> ConfigFileError:
        return ConfigFileError(f"{path}: key '{key}': {why}")

    def number(obj: dict[str, object], key: str, name: str, lo: float, hi: float,
               lo_open: bool, required: bool) -> float | None:
        if key not in obj or (obj[key] is None and not required):
            if required:
                raise fail(name, "missing")
            return None
        v = obj[key]
        low = "> " if lo_open else ">= "
        if not _is_num(v) or not ((v > lo) if lo_open else (v >= lo)) or v > hi:
            upper = f" and <= {hi:g}" if math.isfinite(hi) else ""
            raise fail(name, f"must be a number {low}{lo:g}{upper}")
        return float(v)  # type: ignore[arg-type]

    def section(obj: dict[str, object], key: str, name: str) -> dict[str, object] | None:
        if key not in obj or obj[key] is None:
            return None
        if not isinstance(obj[key], dict):
            raise fail(name, "must be an object")
        return obj[key]  # type: ignore[return-value]

    if doc.get("schema") != CONFIG_SCHEMA:
        raise fail("schema", f"must be \"{CONFIG_SCHEMA}\"")
    if "model" not in doc:
        raise fail("model", "missing")
    m = doc["model"]
    if not (_is_num(m) and m in (1, 2, 3)):
        raise fail("model", "must be 1, 2 or 3")
    if "params" not in doc:
        raise fail("params", "missing")
    ps = section(doc, "params", "params")
    if ps is None:
        raise fail("params", "must be an object")
    params: list[float] = []
    for nm in PARAM_NAMES:
        key = f"params.{nm}"
        if nm not in ps:
            raise fail(key, "missing")
        v = ps[nm]
        if nm in POSITIVE_PARAMS:
            if not (_is_num(v) and 0 < v <= PARAM_MAX):  # type: ignore[operator]
                raise fail(key, f"must be a positive number <= {PARAM_MAX:g}")
        elif not (_is_num(v) and abs(v) <= PARAM_MAX):  # type: ignore[arg-type]
            raise fail(key, f"must be a number with |x| <= {PARAM_MAX:g}")
        params.append(float(v))  # type: ignore[arg-type]
    f1, f2 = params[PARAM_NAMES.index("f1")], params[PARAM_NAMES.index("f2")]
    if f2 < 0 and not f1 + f2 > 0:
        raise fail("params.f1", "g(0) = f1 + f2 must be > 0")
    out = FileConfig(model=int(m), params=params)  # type: ignore[arg-type]
    out.r_n2 = number(doc, "r_n2", "r_n2", 0.0, math.inf, True, False)

    s = doc.get("surface_mm")
    if isinstance(s, list):
        if not all(x is None or (_is_num(x) and abs(x) <= SURFACE_MAX_MM) for x in s):
            raise fail("surface_mm", f"must be a number with |x| <= {SURFACE_MAX_MM:g}, null "
                                     f"or a list of them")
        out.surface_list = True
    elif s is not None:
        if not (_is_num(s) and abs(s) <= SURFACE_MAX_MM):  # type: ignore[arg-type]
            raise fail("surface_mm", f"must be a number with |x| <= {SURFACE_MAX_MM:g}, null "
                                     f"or a list of them")
        out.surface_mm = float(s)  # type: ignore[arg-type]
    t = doc.get("tare_n")
    if not (t is None or _is_num(t) or
            (isinstance(t, list) and all(x is None or _is_num(x) for x in t))):
        raise fail("tare_n", "must be a number, null or a list of them")

    eff = section(doc, "effects", "effects")
    if eff is not None:
        dw = section(eff, "dwell_relaxation", "effects.dwell_relaxation")
        if dw is not None:
            for k in ("tau_fast_s", "tau_slow_s"):
                v = number(dw, k, f"effects.dwell_relaxation.{k}", 0.0, 3600.0, True, False)
                if v is not None:
                    out.m3[k] = v
            rd = dw.get("relative_decay_median")
            if rd is not None:
                if not (_is_num(rd) and 0 < rd < 1):  # type: ignore[operator]
                    raise fail("effects.dwell_relaxation.relative_decay_median",
                               "must be a number > 0 and < 1, or null")
                total = sum(RELAX_NOMINAL.values())
                out.strengths = {nm: float(rd) * RELAX_NOMINAL[nm] / total  # type: ignore
                                 for nm in RELAX_NAMES}
        pr = section(eff, "reversal_presliding", "effects.reversal_presliding")
        if pr is not None:
            v = number(pr, "presliding_mm", "effects.reversal_presliding.presliding_mm",
                       0.0, 1000.0, True, False)
            if v is not None:
                out.m3["presliding_mm"] = v

    m3 = section(doc, "model3", "model3")
    if m3 is not None:
        for k in ("direction_memory", "relaxation"):
            if k in m3 and m3[k] is not None:
                if not isinstance(m3[k], bool):
                    raise fail(f"model3.{k}", "must be true or false")
                out.m3[k] = m3[k]
        if "relax_branches" in m3 and m3["relax_branches"] is not None:
            if not (_is_num(m3["relax_branches"]) and m3["relax_branches"] in (1, 2)):
                raise fail("model3.relax_branches", "must be 1 or 2")
            out.m3["relax_branches"] = int(m3["relax_branches"])  # type: ignore[arg-type]
        for k, hi in (("presliding_mm", 1000.0), ("tau_fast_s", 3600.0), ("tau_slow_s", 3600.0)):
            v = number(m3, k, f"model3.{k}", 0.0, hi, True, False)
            if v is not None:
                out.m3[k] = v
        if m3.get("layer_sets") is not None:
            out.m3["layer_sets"] = _layer_sets(m3["layer_sets"], params, fail)
        st = section(m3, "strengths", "model3.strengths")
        if st is not None:
            g = dict(out.strengths)
            for nm in RELAX_NAMES:
                if nm in st and st[nm] is not None:
                    v = st[nm]
                    if not (_is_num(v) and 0 < v < 1):  # type: ignore[operator]
                        raise fail(f"model3.strengths.{nm}", "must be a number > 0 and < 1")
                    g[nm] = float(v)  # type: ignore[arg-type]
            out.strengths = g
    if out.strengths:
        g = {nm: out.strengths.get(nm, RELAX_NOMINAL[nm]) for nm in RELAX_NAMES}
        if not g["g_fast"] + g["g_slow"] < 1:
            raise fail("model3.strengths", "g_fast + g_slow must be < 1")
        out.strengths = g
    return out


def _layer_sets(items: object, params: list[float], fail: "Callable[[str, str], Exception]"
                ) -> tuple[LayerSet, ...]:
    """``model3.layer_sets``: at most LAYER_MAX - 1 objects in depth order, each with
    ``start_mm`` (> 0, <= the depth range, above the previous start) and the LAYER_SET_NAMES
    values (positive, <= PARAM_MAX, g(0) = f1 + f2 > 0 with the file's f2)."""
    if not isinstance(items, list) or len(items) > LAYER_MAX - 1:
        raise fail("model3.layer_sets", f"must be a list of at most {LAYER_MAX - 1} objects")
    f2 = params[PARAM_NAMES.index("f2")]
    out = []
    previous = 0.0
    for k, item in enumerate(items):
        key = f"model3.layer_sets[{k}]"
        if not isinstance(item, dict):
            raise fail(key, "must be an object")
        start = item.get("start_mm")
        if not (_is_num(start) and 0 < start <= SURFACE_MAX_MM):  # type: ignore[operator]
            raise fail(f"{key}.start_mm", f"must be a number > 0 and <= {SURFACE_MAX_MM:g}")
        if not start > previous:  # type: ignore[operator]
            raise fail(f"{key}.start_mm", "must be above the previous layer's start_mm")
        previous = float(start)  # type: ignore[arg-type]
        values = []
        for nm in LAYER_SET_NAMES:
            v = item.get(nm)
            if not (_is_num(v) and 0 < v <= PARAM_MAX):  # type: ignore[operator]
                raise fail(f"{key}.{nm}", f"must be a positive number <= {PARAM_MAX:g}")
            values.append(float(v))  # type: ignore[arg-type]
        if f2 < 0 and not values[LAYER_SET_NAMES.index("f1")] + f2 > 0:
            raise fail(f"{key}.f1", "g(0) = f1 + f2 must be > 0")
        out.append(LayerSet(previous, tuple(values)))
    return tuple(out)


__all__ = ["CONFIG_SCHEMA", "ConfigFileError", "FileConfig", "read_config_file"]
