"""Figures of estimation runs (matplotlib, no pyplot state): ``nte-ref plot`` and ``estimate --plot``.

One figure for one or several estimate files on one insertion: the reference's (``nte-ref
estimate --out``) or the C twin's (``nte-run``, the same columns), overlaid in one colour each.

* force against time: the measured force and the true force (``force_true_n``) when the input
  carries them, each file's prediction (``force_hat_n``, plus ``tare_n`` when the contact front
  end ran, so it sits on the measured force); the dwell shaded, the reversals and the truth's
  ruptures marked;
* error against time: each file's prediction less the true force (tare excluded: the true force
  has no sensor offset) when the input has ``force_true_n``, otherwise its ``innovation_n`` (the
  measured force less the one-step prediction);
* the same two against depth (the input's ``depth_mm``: the stage position when the front end
  ran), with ``--input``;
* every identified parameter against time with its ±3σ band (the paper's Figs. 4-10), the true
  value as a dashed line when a truth gives it.

Every data series is a Line2D with gid ``"series"``, a truth value one with gid ``"truth"``,
markers (zero line, reversal, rupture) gid ``"marker"``; each axes is named (``get_label()``):
``force_time``, ``error_time``, ``force_depth``, ``error_depth``, ``param:NAME``.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from .csvio import CsvError, Limits, Trial, Units, central_difference, read_table, read_trial

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from .estimate import EstimateRun

#: the columns every estimate file has (estimate.estimate_csv_lines, nte-run)
ESTIMATE_COLUMNS = ("t_s", "force_hat_n", "innovation_n", "status")
#: columns an estimate file may write as nan (the surface before it is found)
NAN_COLUMNS = ("surface_mm",)
#: figure formats, from the output's suffix
FORMATS = ("png", "pdf", "svg")
#: phases of an insertion cycle, as drawn and summarised
PHASES = ("insertion", "dwell", "retraction")
ROMAN = {1: "I", 2: "II", 3: "III"}


@dataclass
class Series:
    """One estimate file (or one run of the estimator)."""
    label: str
    source: str                 # the file it came from ("" for a run in memory)
    t_s: np.ndarray
    force_hat_n: np.ndarray
    innovation_n: np.ndarray
    names: tuple[str, ...]
    params: np.ndarray          # (samples, parameters)
    params_sd: np.ndarray
    tare_n: np.ndarray | None = None
    lines: list[int] = field(default_factory=list)   # the file's line of every row

    @property
    def prediction_n(self) -> np.ndarray:
        """The prediction on the scale of the measured force (the tare added back)."""
        return self.force_hat_n if self.tare_n is None else self.force_hat_n + self.tare_n


@dataclass
class Truth:
    """What a truth gives the figure: parameter values, the phases, the ruptures, the noise."""
    source: str
    params: dict[str, tuple[float, str]] = field(default_factory=dict)   # name: (value, label)
    spans: list[tuple[str, float, float]] = field(default_factory=list)  # (phase, t0, t1)
    ruptures_s: list[float] = field(default_factory=list)
    noise_n: float | None = None
    samples: int | None = None   # samples of the record it belongs to (None: not known)


def model_label(names: Sequence[str]) -> str:
    """'Model I', 'II' or 'III' from the identified parameters' names."""
    if "g_fast" in names or "g_slow" in names:
        return "Model III"
    return "Model I" if "f2" in names else "Model II"


# -- reading ----------------------------------------------------------------------------

def read_estimate(path: str | os.PathLike[str], label: str | None = None) -> Series:
    """An estimate file by the one reader (csvio): the columns of ESTIMATE_COLUMNS and at least
    one identified parameter NAME with its NAME_sd; refusals are CsvError (one line)."""
    table = read_table(path, required=ESTIMATE_COLUMNS, nan_ok=NAN_COLUMNS)
    header = table.header
    names = tuple(c for c in header if c + "_sd" in header and c not in ESTIMATE_COLUMNS)
    if not names:
        raise CsvError(f"{table.path}:{table.lines[0] - 1}: no parameter columns (NAME and "
                       f"NAME_sd): not an estimate file (have: {', '.join(header)})")
    cols = table.columns
    return Series(label if label is not None else model_label(names), table.path, cols["t_s"],
                  cols["force_hat_n"], cols["innovation_n"], names,
                  np.column_stack([cols[n] for n in names]),
                  np.column_stack([cols[n + "_sd"] for n in names]),
                  cols.get("tare_n"), table.lines)


def read_input(path: str | os.PathLike[str], units: Units | None = None) -> Trial:
    """The insertion the estimates were made from (t_s, depth_mm, force_n, optionally
    force_true_n), converted as ``estimate`` converts it; the depth may be a stage position."""
    return read_trial(path, units=units, limits=Limits(depth_min_mm=-Limits.depth_max_mm))


def check_same_record(series: Series, trial: Trial) -> None:
    """Refuse (CsvError) an estimate file that is not one row per sample of ``trial``."""
    n, m = len(series.t_s), len(trial.t_s)
    if n != m:
        raise CsvError(f"{series.source}: {n} rows, but the input {trial.path} has {m} samples: "
                       f"not an estimate of that input (one row per input sample)")
    tol = 1e-9 * np.maximum(1.0, np.abs(trial.t_s))
    bad = np.flatnonzero(np.abs(series.t_s - trial.t_s) > tol)
    if len(bad):
        k = int(bad[0])
        where = f":{series.lines[k]}" if series.lines else ""
        there = f":{trial.lines[k]}" if trial.lines else ""
        raise CsvError(f"{series.source}{where}: column 't_s': {series.t_s[k]!r} is not the "
                       f"input's {trial.t_s[k]!r} ({trial.path}{there}): not an estimate of "
                       f"that input")


def _get(doc: Any, path: str, keys: Sequence[str | int]) -> Any:
    """doc[k0][k1]... or ValueError naming the key."""
    cur = doc
    for k in keys:
        try:
            cur = cur[k]
        except (KeyError, IndexError, TypeError):
            dotted = ".".join(str(x) for x in keys)
            raise ValueError(f"{path}: key '{dotted}': missing or not of the expected "
                             f"kind") from None
    return cur


def _real(doc: Any, path: str, keys: Sequence[str | int]) -> float:
    value = _get(doc, path, keys)
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(float(value)):
        dotted = ".".join(str(x) for x in keys)
        raise ValueError(f"{path}: key '{dotted}': not a finite number: {value!r}")
    return float(value)


def read_truth(path: str) -> Truth:
    """A truth file: the phantom's ``FILE.truth.json`` (``nte-ref phantom``: its cycles give the
    phases, its ruptures the marks, its Maxwell shares g_k lines on g_fast and g_slow, its noise
    the unit of the summary) or an estimator configuration (schema nte-estimator-config/1: its
    params and strengths as lines).  Bad files raise ValueError with one line."""
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except OSError as exc:
        raise ValueError(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        doc = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, ValueError):
        raise ValueError(f"{path}: not valid JSON") from None
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: not a JSON object")
    if "schema" in doc:
        from ..params import PARAM_NAMES
        from .estconfig import read_config_file
        fc = read_config_file(path)
        params = {n: (float(v), "config") for n, v in zip(PARAM_NAMES, fc.params)}
        params.update({n: (float(v), "config") for n, v in fc.strengths.items()})
        return Truth(path, params)
    if "spec" not in doc or "cycles" not in doc:
        raise ValueError(f"{path}: not a truth file: expected a phantom's truth (keys 'spec', "
                         f"'cycles': nte-ref phantom) or an estimator configuration (key "
                         f"'schema')")
    truth = Truth(path)
    cycles = _get(doc, path, ["cycles"])
    if not isinstance(cycles, list):
        raise ValueError(f"{path}: key 'cycles': not a list")
    for i in range(len(cycles)):
        t1, t2, t3 = (_real(doc, path, ["cycles", i, k]) for k in
                      ("insertion_end_s", "retraction_start_s", "retraction_end_s"))
        truth.spans += [("insertion", _real(doc, path, ["cycles", i, "start_s"]), t1),
                        ("dwell", t1, t2), ("retraction", t2, t3)]
    ruptures = _get(doc, path, ["ruptures"])
    if not isinstance(ruptures, list):
        raise ValueError(f"{path}: key 'ruptures': not a list")
    truth.ruptures_s = [_real(doc, path, ["ruptures", i, "time_s"]) for i in range(len(ruptures))]
    truth.noise_n = _real(doc, path, ["spec", "sensor", "noise_n"])
    g = _get(doc, path, ["spec", "tissue", "relax_g"])
    tau = _get(doc, path, ["spec", "tissue", "maxwell_tau_s"])
    if isinstance(g, list) and isinstance(tau, list) and len(g) == len(tau) == 2:
        order = sorted(range(2), key=lambda k: _real(doc, path, ["spec", "tissue",
                                                                 "maxwell_tau_s", k]))
        for name, k in zip(("g_fast", "g_slow"), order):
            truth.params[name] = (_real(doc, path, ["spec", "tissue", "relax_g", k]),
                                  f"phantom g (τ {float(tau[k]):.2g} s)")
    if "presliding_mm" in _get(doc, path, ["spec", "tissue"]):
        # the phantom's Dahl length of the friction: what Model III's delta identifies
        truth.params["delta"] = (_real(doc, path, ["spec", "tissue", "presliding_mm"]),
                                 "phantom δ")
    phase = doc.get("samples", {}).get("phase") if isinstance(doc.get("samples"), dict) else None
    if isinstance(phase, list):
        truth.samples = len(phase)
    return truth


def truth_from_preset(name: str) -> Truth:
    """The parameters of a preset (the truth of ``nte-ref simulate --preset NAME``)."""
    from ..params import PARAM_NAMES, get_preset
    p = get_preset(name).params
    return Truth(f"preset {name}",
                 {n: (float(getattr(p, n)), f"true ({name})") for n in PARAM_NAMES})


def check_truth(truth: Truth, n: int, what: str) -> None:
    """Refuse a phantom truth whose record has another number of samples."""
    if truth.samples is not None and truth.samples != n:
        raise ValueError(f"{truth.source}: the truth of a record of {truth.samples} samples, but "
                         f"{what} has {n}: not the truth of this record")


def spans_from_motion(trial: Trial) -> list[tuple[str, float, float]]:
    """Insertion, dwell and retraction spans from the input's velocity (depth's central
    differences when absent): moving in, held deep, moving out (5 % of the top speed)."""
    t, d, v = trial.t_s, trial.depth_mm, trial.velocity_mm_s
    top = float(np.max(np.abs(v))) if len(v) else 0.0
    if top <= 0.0 or len(t) < 2:
        return []
    still = np.abs(v) <= 0.05 * top
    deep = d > float(np.min(d)) + 0.5 * float(np.max(d) - np.min(d))
    kind = np.where(v > 0.05 * top, 1, np.where(v < -0.05 * top, 3, np.where(still & deep, 2, 0)))
    spans = []
    start = 0
    for k in range(1, len(t) + 1):
        if k == len(t) or kind[k] != kind[start]:
            if kind[start]:
                spans.append((PHASES[kind[start] - 1], float(t[start]), float(t[k - 1])))
            start = k
    return spans


def phase_of(t_s: np.ndarray, spans: Sequence[tuple[str, float, float]]) -> np.ndarray:
    """The phase name of every time ('' outside every span)."""
    out = np.full(len(t_s), "", dtype=object)
    for name, t0, t1 in spans:
        out[(t_s >= t0) & (t_s <= t1)] = name
    return out


# -- the figure -------------------------------------------------------------------------

@dataclass
class FigureData:
    """What one figure draws."""
    series: list[Series]
    trial: Trial | None = None
    truth: Truth | None = None

    @property
    def force_true(self) -> np.ndarray | None:
        return None if self.trial is None else self.trial.columns.get("force_true_n")

    @property
    def spans(self) -> list[tuple[str, float, float]]:
        if self.truth is not None and self.truth.spans:
            return self.truth.spans
        return spans_from_motion(self.trial) if self.trial is not None else []

    def error(self, s: Series) -> np.ndarray:
        """Prediction less the true force (tare-free), or the innovation without a truth."""
        ft = self.force_true
        return s.innovation_n if ft is None else s.force_hat_n - ft

    @property
    def error_label(self) -> str:
        return ("prediction − true force (N)" if self.force_true is not None
                else "innovation: measured − one-step prediction (N)")


def _series(ax: "Axes", x: np.ndarray, y: np.ndarray, *args: Any, **kw: Any) -> None:
    (line,) = ax.plot(x, y, *args, **kw)
    line.set_gid("series")


def _phase_marks(ax: "Axes", data: FigureData, legend: bool) -> None:
    """Dwell shaded, reversals (retraction starts) and the truth's ruptures as vertical lines."""
    first = {"dwell": legend, "reversal": legend, "rupture": legend}
    for name, t0, t1 in data.spans:
        if name == "dwell":
            ax.axvspan(t0, t1, color="gold", alpha=0.18, lw=0,
                       label="dwell" if first["dwell"] else "_dwell")
            first["dwell"] = False
        elif name == "retraction":
            ax.axvline(t0, color="0.35", ls="--", lw=0.8, gid="marker",
                       label="reversal" if first["reversal"] else "_reversal")
            first["reversal"] = False
    for t in (data.truth.ruptures_s if data.truth is not None else []):
        ax.axvline(t, color="C3", ls=":", lw=0.9, gid="marker",
                   label="rupture (truth)" if first["rupture"] else "_rupture")
        first["rupture"] = False


def _clip_note(ax: "Axes", values: Sequence[tuple[str, np.ndarray]], lo: float,
               hi: float) -> None:
    """When a value lies beyond [lo, hi], limit the y axis to it (a diverged sample of one
    file would flatten every other curve) and say in the panel which file has how many samples
    beyond it; otherwise leave the axis to matplotlib."""
    pad = 0.05 * (hi - lo) if hi > lo else 1.0
    lo, hi = lo - pad, hi + pad
    notes = []
    for label, y in values:
        out = np.isfinite(y) & ((y < lo) | (y > hi))
        if np.any(out):
            notes.append(f"{label}: {int(np.count_nonzero(out))} samples beyond the axis "
                         f"({float(np.min(y)):.3g} to {float(np.max(y)):.3g})")
    if notes:
        ax.set_ylim(lo, hi)
        ax.text(0.01, 0.02, "\n".join(notes), transform=ax.transAxes, fontsize=6.5,
                va="bottom", ha="left", color="0.25")


def _robust_range(ys: Sequence[np.ndarray], q: float = 0.5) -> tuple[float, float]:
    """The widest [q, 100-q] percentile range of the arrays (finite values only)."""
    lo, hi = math.inf, -math.inf
    for y in ys:
        y = y[np.isfinite(y)]
        if len(y):
            lo = min(lo, float(np.percentile(y, q)))
            hi = max(hi, float(np.percentile(y, 100.0 - q)))
    return (lo, hi) if lo <= hi else (-1.0, 1.0)


def _force_panel(ax: "Axes", data: FigureData, x_of: str) -> None:
    tr = data.trial
    if tr is not None:
        x = tr.t_s if x_of == "time" else tr.depth_mm
        _series(ax, x, tr.force_n, ".", ms=1.2, color="0.6", label="measured", zorder=1)
        if data.force_true is not None:
            _series(ax, x, data.force_true, "-", lw=0.9, color="k", label="true force", zorder=2)
    for i, s in enumerate(data.series):
        x = s.t_s if x_of == "time" else tr.depth_mm  # type: ignore[union-attr]
        _series(ax, x, s.prediction_n, "-", lw=1.0, color=f"C{i}", label=f"{s.label} prediction",
                zorder=3)
    ax.set_ylabel("force (N)")
    # the axis spans the measured (and true) force when there is one, else the predictions
    ref = ([tr.force_n] + ([data.force_true] if data.force_true is not None else [])
           if tr is not None else [s.prediction_n for s in data.series])
    lo, hi = _robust_range(ref, 0.0)
    span = hi - lo
    _clip_note(ax, [(s.label, s.prediction_n) for s in data.series],
               lo - 0.5 * span, hi + 0.5 * span)


def _error_panel(ax: "Axes", data: FigureData, x_of: str) -> None:
    ax.axhline(0.0, color="0.3", lw=0.6, gid="marker")
    for i, s in enumerate(data.series):
        x = s.t_s if x_of == "time" else data.trial.depth_mm  # type: ignore[union-attr]
        _series(ax, x, data.error(s), "-", lw=0.8, color=f"C{i}", label=s.label)
    ax.set_ylabel(data.error_label)
    errors = [data.error(s) for s in data.series]
    lo, hi = _robust_range(errors, 0.5)
    span = max(hi - lo, 1e-9)
    _clip_note(ax, [(s.label, e) for s, e in zip(data.series, errors)],
               lo - 2.0 * span, hi + 2.0 * span)


def _param_panel(ax: "Axes", data: FigureData, name: str) -> None:
    lo, hi = [], []
    for i, s in enumerate(data.series):
        if name not in s.names:
            continue
        j = s.names.index(name)
        est, sd = s.params[:, j], s.params_sd[:, j]
        ax.fill_between(s.t_s, est - 3.0 * sd, est + 3.0 * sd, color=f"C{i}", alpha=0.22, lw=0,
                        label=f"{s.label} ±3σ", gid="band")
        _series(ax, s.t_s, est, "-", lw=1.0, color=f"C{i}", label=s.label)
        # the limits follow the estimates and bands after their start (a band of the first
        # samples can be a hundred times wider than the rest)
        half = len(est) // 10
        lo.append(float(np.nanpercentile((est - 3.0 * sd)[half:], 1)))
        hi.append(float(np.nanpercentile((est + 3.0 * sd)[half:], 99)))
        lo.append(float(np.nanmin(est)))
        hi.append(float(np.nanmax(est)))
    if data.truth is not None and name in data.truth.params:
        value, label = data.truth.params[name]
        ax.axhline(value, color="k", ls="--", lw=1.0, label=label, gid="truth")
        lo.append(value)
        hi.append(value)
    finite = [v for v in lo + hi if math.isfinite(v)]
    if finite:
        a, b = min(finite), max(finite)
        pad = 0.08 * (b - a) if b > a else 0.1 * abs(a) or 1.0
        ax.set_ylim(a - pad, b + pad)
    ax.set_ylabel(name)
    ax.set_xlabel("time (s)")


def build_figure(data: FigureData, title: str = "") -> "Figure":
    """The figure (not saved): see the module's docstring for its panels."""
    from matplotlib.figure import Figure
    names: list[str] = []
    for s in data.series:
        names += [n for n in s.names if n not in names]
    depth = data.trial is not None
    prow = (len(names) + 1) // 2
    fig = Figure(figsize=(10.5, 2.1 * (2 + prow) + 0.6), layout="constrained")
    gs = fig.add_gridspec(2 + prow, 2)
    time_cols = slice(0, 1) if depth else slice(0, 2)
    ax_ft = fig.add_subplot(gs[0, time_cols], label="force_time")
    ax_et = fig.add_subplot(gs[1, time_cols], label="error_time", sharex=ax_ft)
    _phase_marks(ax_ft, data, legend=True)
    _phase_marks(ax_et, data, legend=False)
    _force_panel(ax_ft, data, "time")
    _error_panel(ax_et, data, "time")
    ax_et.set_xlabel("time (s)")
    handles, labels = ax_ft.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside upper center", ncol=min(len(labels), 4),
               fontsize=8, title=title or None)
    if depth:
        ax_fd = fig.add_subplot(gs[0, 1], label="force_depth")
        ax_ed = fig.add_subplot(gs[1, 1], label="error_depth", sharex=ax_fd)
        _force_panel(ax_fd, data, "depth")
        _error_panel(ax_ed, data, "depth")
        ax_ed.set_xlabel("depth (mm)")
        ax_fd.set_xlabel("depth (mm)")
    for j, name in enumerate(names):
        ax = fig.add_subplot(gs[2 + j // 2, j % 2], label=f"param:{name}", sharex=ax_ft)
        _param_panel(ax, data, name)
        if j == 0 or (data.truth is not None and name in data.truth.params
                      and not any(n in data.truth.params for n in names[:j])):
            ax.legend(loc="best", fontsize=7)
    return fig


def save_figure(fig: "Figure", path: str | os.PathLike[str], dpi: float = 100.0) -> None:
    """Write ``fig`` to ``path`` (format from the suffix, png when there is none); the caller
    makes it atomic (safe_write.Outputs)."""
    fmt = Path(path).suffix.lstrip(".").lower() or "png"
    extra: dict[str, Any] = {"pil_kwargs": {"optimize": True}} if fmt == "png" else {}
    fig.savefig(str(path), dpi=dpi, format=fmt, **extra)


# -- summaries --------------------------------------------------------------------------

def phase_summary(data: FigureData) -> list[str]:
    """Per file and phase: the innovation RMS (in units of the noise when it is known: the
    truth's, or the measured less the true force) and the RMS of prediction less true force."""
    noise = data.truth.noise_n if data.truth is not None else None
    ft = data.force_true
    if noise is None and ft is not None and data.trial is not None:
        noise = float(np.std(data.trial.force_n - ft))
        noise = noise if noise > 0.0 else None
    spans = data.spans
    out = []
    for s in data.series:
        phase = phase_of(s.t_s, spans)
        parts = []
        for name in (PHASES if spans else ("all",)):
            sel = phase == name if spans else np.ones(len(s.t_s), dtype=bool)
            if not np.any(sel):
                continue
            rms = float(np.sqrt(np.mean(s.innovation_n[sel] ** 2)))
            text = f"{name} {rms / noise:.3g}" if noise else f"{name} {rms * 1e3:.3g} mN"
            if ft is not None:
                err = float(np.sqrt(np.mean((s.force_hat_n - ft)[sel] ** 2)))
                text += f" (prediction − true {err * 1e3:.3g} mN)"
            parts.append(text)
        unit = "/ noise" if noise else ""
        out.append(f"{s.label}: innovation RMS {unit}".rstrip() + ": " + ", ".join(parts))
    if noise:
        out.append(f"noise: {noise * 1e3:.3g} mN ("
                   + ("the truth's" if data.truth is not None and data.truth.noise_n
                      else "measured − true force") + ")")
    return out


# -- estimate --plot ----------------------------------------------------------------------

def series_from_run(run: "EstimateRun", label: str | None = None) -> Series:
    """A run of the estimator in memory as a Series (what its estimate file would hold)."""
    tare = None if run.contact is None else np.asarray(run.contact[1], dtype=float)
    return Series(label or f"Model {ROMAN.get(run.model, run.model)}", "",
                  np.asarray(run.t_s, dtype=float), np.asarray(run.force_hat_n, dtype=float),
                  np.asarray(run.innovation_n, dtype=float), tuple(run.names),
                  np.asarray(run.params, dtype=float), np.asarray(run.params_sd, dtype=float),
                  tare)


def plot_estimate(run: "EstimateRun", path: str | os.PathLike[str], title: str = "") -> None:
    """``estimate --plot``: the figure of ``nte-ref plot`` for one run and its input.

    Writes ``path`` directly: the caller makes it atomic (``safe_write.Outputs``)."""
    t = np.asarray(run.t_s, dtype=float)
    d = np.asarray(run.depth_mm, dtype=float)
    trial = Trial("", t, d, np.asarray(run.force_n, dtype=float), central_difference(t, d),
                  False, {})
    s = series_from_run(run)
    fig = build_figure(FigureData([s], trial),
                       title or f"{s.label}, {run.precision}")
    save_figure(fig, path, dpi=110)


__all__ = ["Series", "Truth", "FigureData", "read_estimate", "read_input", "read_truth",
           "truth_from_preset", "check_same_record", "check_truth", "build_figure",
           "save_figure", "phase_summary", "plot_estimate", "FORMATS"]
