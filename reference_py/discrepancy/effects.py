"""The effect library: extensions of the force model for effects it leaves out (MODEL.md §8).

Every effect is a documented extension of the base model with its own parameters and units, and
every extended model can be simulated (:func:`simulate_extended`).  Written in the normalised form
the discrepancy fit uses (see DISCREPANCY.md §2): with zh = z / beta, the base model is

    dzh/dt = l (1 - b(l) zh),          b(l) = 1 / (p + q exp(-alpha l)),  p = f1/sigma0, q = f2/sigma0
    f      = A zh l + s l (C e(l) (1 - b zh)) + sigma2 s l + offset_i
             A = sigma0 beta,  C = sigma1 beta,  e(l) = exp(-alpha l),  s = sign(v)

so the force is linear in (A, C, sigma2, offset_i) once the nonlinear (p, g0 = p + q, alpha) and
each trial's surface position are fixed.  l = stage depth - surface (mm, clamped at 0).  Each
effect adds columns (linear parameters) and/or changes the inputs the base model sees (nonlinear
parameters):

``dwell_relaxation`` (viscoelastic stress relaxation while the needle rests)
    f += H_i - sum_k R_k,i (1 - exp(-(t - t0)/tau_k)),  k in {fast, slow}, during each dwell of
    trial i (t0 = start of the dwell).  H_i is the stress the tissue still holds when the needle
    stops (the base model drops its friction the instant s = 0; measured force is continuous at
    the stop), the R terms its two-element Prony relaxation.  Parameters: tau_fast_s in
    [0.05, 1] s, tau_slow_s in [1, 30] s, H_i, R_fast,i, R_slow,i in N (per trial: the force that
    relaxes depends on the dwell depth).  After the dwell (in the tissue, until the needle
    advances again) the share relax_memory in [0, 1] of what relaxed stays and fades in time:
    f -= relax_memory sum_k R_k,i (1 - exp(-T/tau_k)) exp(-(t - t1)/tau_k), T the dwell's length,
    t1 its end (DISCREPANCY.md section 4: fitted last, once the effects are named).
    Reported drop fraction = force lost by the end of the dwell / force at its start.
``reversal_presliding`` (friction needs travel to build up after a reversal: Dahl-like pre-sliding)
    s -> s (1 - exp(-d/delta)), d = tissue depth travelled (mm) since the direction last changed,
    plus the force carried over from before the reversal, fading over the same travel:
    f += K_i exp(-d/delta) on each retraction (a Dahl bristle turning over from the old
    direction: the measured force is continuous through the reversal).  Parameters:
    presliding_mm = delta in [0.05, 10] mm; presliding_carry K_i >= 0 N per trial.
``velocity_friction`` (viscous shaft friction, b v l)
    f += b_visc v l.  Parameter: b_visc in N s / mm^2 (bovine liver ~ 2e-4).  Needs >= 2 speeds.
``direction_asymmetry`` (friction differs between insertion and retraction)
    f += [v < 0] s l (dC e (1 - b zh) + dsigma2): extra retraction friction.  Parameters:
    dC_out (N/mm, like C), dsigma2_out (N/mm); reported ratio = retraction / insertion friction.
``layer_puncture`` (an extra membrane: a loading ramp then a sudden drop when it is pierced)
    f += F_layer exp((l - d_layer)/w) while inserting and the layer is not yet pierced (l < d_layer
    for the first time), 0 afterwards.  Parameters: d_layer (mm below the surface), w (mm) in
    [0.2, 10], F_layer = drop (N).
``sensor_drift`` (sensor bias that changes slowly after tare)
    f += c_drift,i (t - t_ref,i), t_ref,i where trial i's tare is taken.  Parameter: c_drift,i
    in N/s, one per trial: a sensor's drift differs from trial to trial (thermal state, time
    since the tare), and one slope for all of them cannot follow a warm-up or a random walk
    whose levels in the air part differently in each trial.
``tissue_motion`` (periodic tissue displacement, e.g. breathing, not tied to commanded motion)
    l -> l - m_i(t), v -> v - m_i'(t), m_i(t) = a_i sin(2 pi f t) + b_i cos(2 pi f t).
    Parameters: motion_freq_hz in [0.1, 0.6] Hz, a_i, b_i in mm (per trial: phase differs).

A known-additive-term form (:func:`known_force_term`) lets the reference EKF bank run with an
effect: subtract the term from the measurement before the update (bank.py is left unchanged).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from typing import Any

import numpy as np

from ..fmath import Array
from ..params import BETA0_DEFAULT, ParamSet
from .fastsim import Stages, stage_depths, state_on_stages

#: the fixed vocabulary of effect names (report.json and text); "none" when nothing is missing
VOCABULARY: tuple[str, ...] = ("dwell_relaxation", "reversal_presliding", "velocity_friction",
                               "direction_asymmetry", "layer_puncture", "sensor_drift",
                               "tissue_motion")
NONE = "none"

#: stage speed below which the needle is at rest (mm/s)
V_REST_MM_S = 0.02
#: shortest rest that counts as a dwell (s)
MIN_DWELL_S = 0.2


@dataclass(frozen=True)
class NLParam:
    """A nonlinear parameter: name, unit, bounds, whether it is searched in log, per trial."""

    name: str
    unit: str
    lo: float
    hi: float
    init: float
    log: bool = True
    per_trial: bool = False
    doc: str = ""
    #: moved when the effect is screened, refined and judged as a candidate; False: a value
    #: that refines the effect's form (``init`` is the plain form), moved only in the last fit
    #: of the named model (workflow._polish)
    screened: bool = True
    #: False when both bounds are values the parameter can mean (a share in [0, 1]): sitting on
    #: one is a finding, not a fit held back, so the report does not flag it
    flag_bounds: bool = True


BASE_NL: tuple[NLParam, ...] = (
    NLParam("p", "1", 0.05, 1e4, 7.0, doc="f1/sigma0: g(l)/sigma0 deep in the tissue"),
    NLParam("g0", "1", 0.05, 1e4, 4.4, doc="(f1+f2)/sigma0: g(l)/sigma0 at the surface"),
    NLParam("alpha", "1/mm", 1e-3, 1.0, 0.05, doc="decay rate of e(l) = exp(-alpha l)"),
    NLParam("surface", "mm", -1.5, 1.5, 0.0, log=False, per_trial=True,
            doc="correction to the detected surface position"),
)

EFFECT_NL: dict[str, tuple[NLParam, ...]] = {
    "dwell_relaxation": (NLParam("tau_fast_s", "s", 0.05, 1.0, 0.3),
                         NLParam("tau_slow_s", "s", 1.0, 30.0, 3.0),
                         NLParam("relax_memory", "1", 0.0, 1.0, 0.0, log=False,
                                 doc="share of what relaxed in a dwell that the tissue still "
                                     "remembers after it (fading with tau)", screened=False,
                                 flag_bounds=False)),
    "reversal_presliding": (NLParam("presliding_mm", "mm", 0.05, 10.0, 1.0),),
    "velocity_friction": (),
    "direction_asymmetry": (),
    "layer_puncture": (NLParam("layer_depth_mm", "mm", 0.5, 200.0, 20.0),
                       NLParam("layer_width_mm", "mm", 0.2, 10.0, 1.5)),
    "sensor_drift": (),
    "tissue_motion": (NLParam("motion_freq_hz", "Hz", 0.1, 0.6, 0.25),
                      NLParam("motion_a_mm", "mm", -6.0, 6.0, 0.0, log=False, per_trial=True),
                      NLParam("motion_b_mm", "mm", -6.0, 6.0, 0.0, log=False, per_trial=True)),
}

#: phases (see discrepancy.phases) each effect acts on: where its gap is measured
EFFECT_PHASES: dict[str, tuple[str, ...]] = {
    "dwell_relaxation": ("dwell",),
    "reversal_presliding": ("reversal",),
    "velocity_friction": ("loading", "insertion", "reversal", "retraction"),
    "direction_asymmetry": ("reversal", "retraction"),
    "layer_puncture": ("loading", "insertion"),
    "sensor_drift": ("out_of_tissue", "loading", "insertion", "dwell", "reversal", "retraction",
                     "after_exit"),
    "tissue_motion": ("loading", "insertion", "dwell", "reversal", "retraction"),
}

EFFECT_MEANING: dict[str, str] = {
    "dwell_relaxation": "viscoelastic stress relaxation: force decays while the needle rests",
    "reversal_presliding": "pre-sliding: friction needs millimetres of travel to reverse",
    "velocity_friction": "viscous friction: shaft force grows with speed (b v l)",
    "direction_asymmetry": "friction differs between insertion and retraction",
    "layer_puncture": "an extra tissue layer: its own loading ramp and puncture drop",
    "sensor_drift": "sensor bias drifting slowly after tare",
    "tissue_motion": "periodic tissue motion (breathing) not tied to the commanded motion",
    NONE: "the base model explains the data",
}


@dataclass
class TrialGrid:
    """One trial as the model sees it: times (s), stage depth (mm), stage velocity (mm/s) and the
    detected surface (mm, stage coordinate).  ``dwells`` are (start, stop) index ranges."""

    t_s: Array
    stage_mm: Array
    v_mm_s: Array
    surface_mm: float
    dwells: list[tuple[int, int]] = field(default_factory=list)
    #: tissue depths (mm below the detected surface) of the ruptures seen in this trial: the
    #: multi-layer base model switches to the next layer's parameters at each
    ruptures: list[float] = field(default_factory=list)
    #: time (s) the tare refers to (middle of the samples before contact): drift is 0 there
    t_ref: float | None = None
    #: the trial's largest force (N, tare removed, every sample): a layer's tenting terms k1 u
    #: and k2 u^2 (u in [0, 1]) are each at most this (LAYER_LOAD_MAX_X times it)
    peak_n: float = float("inf")

    @property
    def t_mid(self) -> float:
        return 0.5 * float(self.t_s[0] + self.t_s[-1])

    @cached_property
    def stage_direction(self) -> Array:
        """direction(v_mm_s), made once: every simulation of the trial without tissue motion
        needs it (read only)."""
        s = direction(self.v_mm_s)
        s.flags.writeable = False
        return s


def find_dwells(t_s: Array, depth_mm: Array, v_mm_s: Array) -> list[tuple[int, int]]:
    """Index ranges [i0, i1) where the needle rests inside the tissue for >= MIN_DWELL_S."""
    rest = (np.abs(v_mm_s) <= V_REST_MM_S) & (depth_mm > 0.0)
    out: list[tuple[int, int]] = []
    n = len(rest)
    i = 0
    while i < n:
        if rest[i]:
            j = i
            while j < n and rest[j]:
                j += 1
            if t_s[j - 1] - t_s[i] >= MIN_DWELL_S:
                out.append((i, j))
            i = j
        else:
            i += 1
    return out


def direction(v_mm_s: Array) -> Array:
    """Exact sign of the velocity with a rest dead-band (the model's s(v); 0 at rest)."""
    return np.where(v_mm_s > V_REST_MM_S, 1.0, np.where(v_mm_s < -V_REST_MM_S, -1.0, 0.0))


def travel_since_reversal(l_mm: Array, s: Array) -> Array:
    """Tissue depth travelled (mm) since the direction of motion last changed (rests skipped)."""
    n = len(s)
    idx = np.where(s != 0.0, np.arange(n), 0)
    np.maximum.accumulate(idx, out=idx)
    last = s[idx]                      # last non-zero direction (0 before any motion)
    change = np.zeros(n, dtype=bool)
    change[1:] = (last[1:] != last[:-1])
    change[0] = True
    cum = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(l_mm)))])
    seg_start = np.where(change, np.arange(n), 0)
    np.maximum.accumulate(seg_start, out=seg_start)
    return cum - cum[seg_start]


def nl_defaults(effects: tuple[str, ...], n_trials: int) -> dict[str, Array]:
    """Default nonlinear values for the base model plus ``effects`` (per-trial ones as arrays)."""
    out: dict[str, Array] = {}
    for par in BASE_NL + tuple(p for e in effects for p in EFFECT_NL[e]):
        out[par.name] = np.full(n_trials, par.init) if par.per_trial else np.array(par.init)
    return out


def nl_specs(effects: tuple[str, ...]) -> list[NLParam]:
    return list(BASE_NL) + [p for e in effects for p in EFFECT_NL[e]]


class StateCache:
    """Remembers the last few zh per trial so fits that move only output parameters skip the ODE.

    A few per trial, not one: a finite-difference Jacobian moves one trial's surface, then the
    next one's, and every move returns the others to the values before it."""

    #: states kept per trial (most recent first)
    KEEP = 4

    def __init__(self, substeps: int = 10) -> None:
        #: RK3 sub-steps per sample for the fits (fewer than the reference's 10 is accurate to
        #: ~1e-5 relative on the strided fitting grid and 2.5x faster)
        self.substeps = substeps
        self._val: dict[object, list[tuple[tuple, object]]] = {}

    def get(self, i: object, key: tuple) -> Any:
        """The value kept for slot ``i`` (a trial index; ("design", i) for its design rows)
        under ``key``, or None."""
        kept = self._val.get(i, [])
        for j, (k, v) in enumerate(kept):
            if k == key:
                if j:
                    kept.insert(0, kept.pop(j))
                return v
        return None

    def put(self, i: object, key: tuple, val: object) -> None:
        kept = self._val.setdefault(i, [])
        kept.insert(0, (key, val))
        del kept[self.KEEP:]


def depths_below_fitted_surface(depths_mm: list[float], nl: dict[str, Array], i: int
                                ) -> list[float]:
    """Trial i's depths (mm) measured from the prepared surface -- the evidence's ruptures, the
    deepest point -- as depths below the fitted surface, which the fit moves by its correction
    nl["surface"][i] (deeper when the fitted surface is higher).  The layer columns and the
    report's one-density friction (report.one_layer_friction) both read them here."""
    corr = float(np.atleast_1d(nl["surface"])[i])
    return [d - corr for d in depths_mm]


def trial_inputs(tr: TrialGrid, i: int, effects: tuple[str, ...], nl: dict[str, Array],
                 cache: StateCache | None = None) -> tuple[Array, Array, Array, Array, Array]:
    """Depth l (mm), direction s, zh, b(l) and e(l) = exp(-alpha l) the model sees in trial i
    (tissue motion applied)."""
    surf = tr.surface_mm + float(np.atleast_1d(nl["surface"])[i])
    key: tuple[float, ...] = (float(nl["p"]), float(nl["g0"]), float(nl["alpha"]), surf)
    moving = "tissue_motion" in effects
    if moving:
        key += (float(nl["motion_freq_hz"]), float(nl["motion_a_mm"][i]),
                float(nl["motion_b_mm"][i]))
    if cache is not None:
        hit = cache.get(i, key)
        if hit is not None:
            return hit
    substeps = cache.substeps if cache is not None else 10
    l, s, stages = _trial_where(tr, i, nl, moving, surf, substeps, cache)
    p, q, alpha = float(nl["p"]), float(nl["g0"]) - float(nl["p"]), float(nl["alpha"])
    # exp(-alpha l) at the samples and at the stages: kept while only p or g0 move
    decay_key = (id(tr), len(tr.t_s), substeps) + key[2:]
    decays = cache.get(("decay", i), decay_key) if cache is not None else None
    if decays is None:
        decays = (np.exp(-alpha * l), np.exp(-alpha * stages.ls))
        if cache is not None:
            cache.put(("decay", i), decay_key, decays)
    e = decays[0]                       # the friction column C needs it too
    bl = 1.0 / (p + q * e)
    # RK3 is stable for |lambda h| up to ~2.5 (lambda = l b): where a fit wanders into stiff
    # parameters, the samples whose sub-steps see lambda h > 1 step exactly instead
    zh = state_on_stages(stages, p, q, alpha, stiff_from=1.0, decay=decays[1])
    val = (l, s, zh, bl, e)
    if cache is not None:
        cache.put(i, key, val)
    return val


def _trial_where(tr: TrialGrid, i: int, nl: dict[str, Array], moving: bool, surf: float,
                 substeps: int, cache: StateCache | None) -> tuple[Array, Array, Stages]:
    """Depth l, direction s and the simulation's Stages of trial i: where the needle is in the
    tissue, which only the surface and the tissue motion change (kept while p, g0, alpha or
    another effect's values move)."""
    key: tuple = (id(tr), len(tr.t_s), substeps, surf)
    if moving:
        key += (float(nl["motion_freq_hz"]), float(nl["motion_a_mm"][i]),
                float(nl["motion_b_mm"][i]))
    if cache is not None:
        hit = cache.get(("where", i), key)
        if hit is not None:
            return hit
    l_raw = tr.stage_mm - surf
    v = tr.v_mm_s
    if moving:
        w = 2.0 * np.pi * float(nl["motion_freq_hz"])
        a, b = float(nl["motion_a_mm"][i]), float(nl["motion_b_mm"][i])
        l_raw = l_raw - (a * np.sin(w * tr.t_s) + b * np.cos(w * tr.t_s))
        v = v - w * (a * np.cos(w * tr.t_s) - b * np.sin(w * tr.t_s))
    l = np.maximum(l_raw, 0.0)
    s = (direction(v) if moving else tr.stage_direction) * (l > 0.0)
    val = (l, s, stage_depths(tr.t_s, l, substeps))
    if cache is not None:
        l.flags.writeable = s.flags.writeable = False     # shared by the entries that use it
        cache.put(("where", i), key, val)
    return val


def design(trials: list[TrialGrid], effects: tuple[str, ...], nl: dict[str, Array],
           cache: StateCache | None = None) -> tuple[Array, list[str]]:
    """The regressor matrix (all trials stacked) of the extended model, and its column labels.

    force = design @ coefficients; the coefficients are the linear parameters named by the labels.
    """
    parts, cols, labels = design_parts(trials, effects, nl, cache)
    m = np.zeros((sum(len(part) for part in parts), len(labels)))
    row = 0
    for part, c in zip(parts, cols):
        m[row:row + len(part), c] = part
        row += len(part)
    return m, labels


@lru_cache(maxsize=64)
def trial_columns(labels: tuple[str, ...], n_trials: int) -> list[tuple[Array, dict[str, int]]]:
    """Per trial, the columns its rows can fill -- the shared ones (no trial index) and its own
    ("...[i]") -- ascending, and each label's position among them.  Every other column of a
    trial's rows is 0 (another trial's terms): :func:`design_parts` leaves them out."""
    owner = [int(lab[lab.rindex("[") + 1:-1]) if lab.endswith("]") else -1 for lab in labels]
    out = []
    for i in range(n_trials):
        cols = np.array([j for j, o in enumerate(owner) if o in (-1, i)], dtype=np.intp)
        cols.flags.writeable = False
        out.append((cols, {labels[j]: q for q, j in enumerate(cols)}))
    return out


def design_parts(trials: list[TrialGrid], effects: tuple[str, ...], nl: dict[str, Array],
                 cache: StateCache | None = None
                 ) -> tuple[list[Array], list[Array], list[str]]:
    """:func:`design` trial by trial and without the columns that are 0 in a trial's rows: part
    i holds trial i's rows on the columns cols[i] (:func:`trial_columns`), the design's other
    entries in those rows are 0.  A fit reads and copies a fifth of the design this way.  With a
    cache, a trial whose values did not change gets the very array of the last call: callers may
    key work on it by identity (read only)."""
    n_tr = len(trials)
    labels = ["A", "C", "sigma2"]
    for i, tr in enumerate(trials):
        for j in range(len(tr.ruptures)):
            labels += [f"layer{j + 1}_load1[{i}]", f"layer{j + 1}_load2[{i}]",
                       f"layer{j + 1}_cut[{i}]", f"layer{j + 1}_fric[{i}]"]
        if tr.ruptures:
            labels.append(f"layer0_fric[{i}]")
    if "velocity_friction" in effects:
        labels.append("b_visc")
    if "direction_asymmetry" in effects:
        labels += ["dC_out", "dsigma2_out"]
    if "layer_puncture" in effects:
        labels.append("layer_drop")
    if "sensor_drift" in effects:
        labels += [f"drift[{i}]" for i in range(n_tr)]
    if "reversal_presliding" in effects:
        labels += [f"presliding_carry[{i}]" for i in range(n_tr)]
    if "dwell_relaxation" in effects:
        labels += [f"relax_hold[{i}]" for i in range(n_tr)] + \
                  [f"relax_fast[{i}]" for i in range(n_tr)] + \
                  [f"relax_slow[{i}]" for i in range(n_tr)]
    columns = trial_columns(tuple(labels), n_tr)
    blocks = []
    shared_key: tuple = ()
    per_trial_values: list[tuple[str, list[float]]] = []
    if cache is not None:
        # the values every trial's key holds, read once per call, not once per trial
        shared_key = (effects, len(labels)) + tuple(
            (k, float(v)) for k, v in nl.items() if np.ndim(v) != 1)
        per_trial_values = [(k, np.asarray(v, dtype=float).tolist()) for k, v in nl.items()
                            if np.ndim(v) == 1]
    for i, tr in enumerate(trials):
        # a trial's rows depend on the shared values and its own: a fit that moves another
        # trial's surface (a Jacobian column) finds them in the cache
        key: tuple = ()
        if cache is not None:
            key = (id(tr), len(tr.t_s)) + shared_key + tuple(
                (k, v[i]) for k, v in per_trial_values)
            hit = cache.get(("design", i), key)
            if hit is not None:
                blocks.append(hit)
                continue
        l, s, zh, bl, e = trial_inputs(tr, i, effects, nl, cache)
        n = len(l)
        col = columns[i][1]
        m = np.zeros((n, len(col)))
        s, carry, layers = _trial_geometry(tr, i, effects, nl, cache, l, s)
        if carry is not None:
            m[:, col[f"presliding_carry[{i}]"]] = carry
        fric_c = s * l * e * (1.0 - bl * zh)
        m[:, col["A"]] = zh * l
        m[:, col["C"]] = fric_c
        m[:, col["sigma2"]] = s * l
        if layers is not None:       # the trial's layer columns follow one another
            first = col[f"layer1_load1[{i}]"]
            m[:, first:first + layers.shape[1]] = layers
        if "velocity_friction" in effects:
            m[:, col["b_visc"]] = tr.v_mm_s * l
        if "direction_asymmetry" in effects:
            back = tr.v_mm_s < -V_REST_MM_S
            m[:, col["dC_out"]] = np.where(back, fric_c, 0.0)
            m[:, col["dsigma2_out"]] = np.where(back, s * l, 0.0)
        if "layer_puncture" in effects:
            dl, w = float(nl["layer_depth_mm"]), float(nl["layer_width_mm"])
            intact = np.maximum.accumulate(l) < dl
            ramp = np.exp(np.minimum(l - dl, 0.0) / w)
            m[:, col["layer_drop"]] = np.where(intact & (tr.v_mm_s > V_REST_MM_S) & (l > 0),
                                               ramp, 0.0)
        if "sensor_drift" in effects:
            m[:, col[f"drift[{i}]"]] = tr.t_s - (tr.t_ref if tr.t_ref is not None else tr.t_mid)
        if "dwell_relaxation" in effects:
            hold = np.zeros(n)
            for i0, i1 in tr.dwells:
                hold[i0:i1] = 1.0
            m[:, col[f"relax_hold[{i}]"]] = hold
            after = _after_dwells(tr)
            memory = float(nl["relax_memory"])
            for k, tau_name in (("fast", "tau_fast_s"), ("slow", "tau_slow_s")):
                tau = float(nl[tau_name])
                c = np.zeros(n)
                for (i0, i1), (a0, a1) in zip(tr.dwells, after):
                    c[i0:i1] = -(1.0 - np.exp(-(tr.t_s[i0:i1] - tr.t_s[i0]) / tau))
                    # what relaxed is the branch's memory: after the dwell it fades in time
                    c[a0:a1] = memory * c[i1 - 1] * np.exp(-(tr.t_s[a0:a1] - tr.t_s[i1 - 1])
                                                           / tau)
                m[:, col[f"relax_{k}[{i}]"]] = np.where(l > 0.0, c, 0.0)
        if cache is not None:
            m.flags.writeable = False
            cache.put(("design", i), key, m)
        blocks.append(m)
    return blocks, [c for c, _ in columns], labels


def _after_dwells(tr: TrialGrid) -> list[tuple[int, int]]:
    """For each dwell of the trial, the rows [a0, a1) over which what relaxed in it can still be
    remembered (the relax_memory share of it): from the dwell's end while the needle does not
    advance, up to the next dwell (empty when the needle goes on inwards).  The design keeps
    only the rows in the tissue."""
    forward = np.flatnonzero(tr.v_mm_s > V_REST_MM_S)
    out = []
    for k, (_, i1) in enumerate(tr.dwells):
        stop = tr.dwells[k + 1][0] if k + 1 < len(tr.dwells) else len(tr.t_s)
        ahead = forward[np.searchsorted(forward, i1):]
        if len(ahead):
            stop = min(stop, int(ahead[0]))
        out.append((i1, max(i1, stop)))
    return out


def _trial_geometry(tr: TrialGrid, i: int, effects: tuple[str, ...], nl: dict[str, Array],
                    cache: StateCache | None, l: Array, s: Array
                    ) -> tuple[Array, Array | None, Array | None]:
    """What trial i's rows take from where the needle is, not from the state: the direction s
    with pre-sliding's fade applied, the pre-sliding carry column (None without the effect) and
    the layer columns (None without ruptures).  They depend on the trial's surface correction,
    its tissue motion and the pre-sliding travel only, so a fit moving the base model's shape
    (p, g0, alpha) or another effect's values finds them in the cache."""
    key: tuple = (id(tr), len(tr.t_s), float(np.atleast_1d(nl["surface"])[i]))
    if "tissue_motion" in effects:
        key += (float(nl["motion_freq_hz"]), float(nl["motion_a_mm"][i]),
                float(nl["motion_b_mm"][i]))
    presliding = "reversal_presliding" in effects
    if presliding:
        key += (float(nl["presliding_mm"]),)
    if cache is not None:
        hit = cache.get(("geometry", i), key)
        if hit is not None:
            return hit
    carry = None
    if presliding:
        d = travel_since_reversal(l, s)
        fade = np.exp(-d / float(nl["presliding_mm"]))
        s = s * (1.0 - fade)
        carry = np.where((tr.v_mm_s < -V_REST_MM_S) & (l > 0), fade, 0.0)
    layers = None
    if tr.ruptures:
        layers = _layer_columns(depths_below_fitted_surface(tr.ruptures, nl, i), tr.v_mm_s, l, s)
    val = (s, carry, layers)
    if cache is not None:
        for a in val:
            if a is not None:
                a.flags.writeable = False
        cache.put(("geometry", i), key, val)
    return val


def _layer_columns(rs: list[float], v: Array, l: Array, s: Array) -> Array:
    """The multi-layer base model's columns for one trial (ruptures at tissue depths r_1 < r_2
    ...), in the order of design's labels: load1, load2, cut and fric of each layer, then fric0.

    Layer j (between r_{j-1}, r_0 = 0, and its rupture r_j) loads as k1 u + k2 u^2, u = (l -
    r_{j-1}) / (r_j - r_{j-1}), while the needle advances (or rests) and the layer is intact (the
    deepest point reached is short of r_j): membrane tenting up to its rupture force k1 + k2, then
    nothing (the drop).  After r_j the tip cuts the next tissue (cut_j while inserting with the tip
    between r_j and r_{j+1}), and the shaft length in that band, clip(l - r_j, 0, r_{j+1} - r_j),
    carries its own friction density fric_j (N/mm, signed by the pre-sliding-aware direction s).
    Once the tip has passed r_1, the first band clip(l, 0, r_1) carries fric_0 as well: the skin
    the shaft went through holds on to it, most visibly in the retraction.
    """
    out = np.zeros((len(l), 4 * len(rs) + 1))
    if not rs:
        return out
    deepest = np.maximum.accumulate(l)
    # every layer at once, one row per layer (layer j spans r0 = r_{j-1} .. r = r_j, the next
    # band ends at r1 = r_{j+1})
    r = np.array(rs, dtype=float)[:, None]
    r0 = np.concatenate([[0.0], rs[:-1]])[:, None]
    r1 = np.concatenate([rs[1:], [np.inf]])[:, None]
    u = np.clip((l - r0) / np.maximum(r - r0, 1e-6), 0.0, 1.0)
    load = (deepest < r) & (l > r0) & (v >= -V_REST_MM_S)
    n_cols = 4 * len(rs)
    out[:, 0:n_cols:4] = np.where(load, u, 0.0).T
    out[:, 1:n_cols:4] = np.where(load, u * u, 0.0).T
    out[:, 2:n_cols:4] = np.where((v > V_REST_MM_S) & (l >= r) & (l < r1)
                                  & (deepest <= l + 1e-9), 1.0, 0.0).T
    out[:, 3:n_cols:4] = (s * np.clip(l - r, 0.0, r1 - r)).T
    out[:, -1] = np.where(deepest >= rs[0], s * np.clip(l, 0.0, rs[0]), 0.0)
    return out


#: bounds of the linear coefficients (by label prefix), enforced by a bounded least-squares solve
#: whenever the free solution leaves them: stiffness, friction and drops are not negative;
#: sigma0 and sigma1 (A = sigma0 beta, C = sigma1 beta) stay positive, so g(l) > 0 at every depth
LIN_BOUNDS: dict[str, tuple[float, float]] = {
    "A": (1e-9, np.inf), "C": (1e-9, np.inf), "sigma2": (0.0, np.inf),
    "layer_load1": (0.0, np.inf), "layer_load2": (0.0, np.inf), "layer_cut": (0.0, np.inf),
    "layer_fric": (0.0, np.inf), "b_visc": (0.0, np.inf), "layer_drop": (0.0, np.inf),
    "relax_fast": (0.0, np.inf), "relax_slow": (0.0, np.inf), "presliding_carry": (0.0, np.inf),
}


def lin_bound(label: str) -> tuple[float, float]:
    """Bounds of one linear coefficient (label as in :func:`design`)."""
    key = label.split("[")[0]
    if key.startswith("layer") and "_" in key and key != "layer_drop":
        key = "layer_" + key.split("_", 1)[1]
    return LIN_BOUNDS.get(key, (-np.inf, np.inf))


# ------------------------------------------------------------------------------------------
# Physical parameters <-> the normalised form, and simulation of an extended model
# ------------------------------------------------------------------------------------------
def to_paramset(nl: dict[str, Array], coef: dict[str, float],
                beta: float = BETA0_DEFAULT) -> ParamSet:
    """Base-model parameters from the normalised fit (beta is the Model I normaliser).

    Model II (alpha, f2 frozen at these values, beta identified) reaches the same force at the
    same optimum, because only A = sigma0 beta, C = sigma1 beta and b(l) are identifiable.
    """
    sigma0 = coef["A"] / beta
    p, g0 = float(nl["p"]), float(nl["g0"])
    return ParamSet(sigma0=sigma0, sigma1=coef["C"] / beta, sigma2=coef["sigma2"],
                    f1=p * sigma0, f2=(g0 - p) * sigma0, alpha=float(nl["alpha"]), beta=beta)


def from_paramset(params: ParamSet, n_trials: int = 1) -> tuple[dict[str, Array], dict[str, float]]:
    """The normalised nonlinear values and linear coefficients of a base ParamSet."""
    nl = {"p": np.array(params.f1 / params.sigma0),
          "g0": np.array((params.f1 + params.f2) / params.sigma0),
          "alpha": np.array(params.alpha), "surface": np.zeros(n_trials)}
    coef = {"A": params.sigma0 * params.beta, "C": params.sigma1 * params.beta,
            "sigma2": params.sigma2}
    return nl, coef


def simulate_extended(params: ParamSet, effect_params: dict[str, dict[str, float]],
                      t_s: Array, depth_mm: Array, velocity_mm_s: Array) -> Array:
    """Force (N) of the base model ``params`` extended by ``effect_params`` along one trajectory.

    ``effect_params`` maps effect name -> its parameters by the names used in :func:`design`
    (nonlinear: EFFECT_NL names; linear: column labels without the trial index), e.g.
    ``{"dwell_relaxation": {"tau_fast_s": .3, "tau_slow_s": 3, "relax_hold": .05,
    "relax_fast": .02, "relax_slow": .05}}``.  Depth is measured from the surface (surface = 0).
    """
    effects = tuple(e for e in VOCABULARY if e in effect_params)
    nl, coef = from_paramset(params, 1)
    for e in effects:
        for par in EFFECT_NL[e]:
            val = float(effect_params[e].get(par.name, par.init))
            nl[par.name] = np.array([val]) if par.per_trial else np.array(val)
        for k, val in effect_params[e].items():
            if k not in {par.name for par in EFFECT_NL[e]}:
                coef[k] = float(val)
    t = np.asarray(t_s, dtype=float)
    d = np.asarray(depth_mm, dtype=float)
    v = np.asarray(velocity_mm_s, dtype=float)
    grid = TrialGrid(t, d, v, 0.0, find_dwells(t, d, v))
    m, labels = design([grid], effects, nl)
    theta = np.array([coef.get(lab, coef.get(lab.split("[")[0], 0.0)) for lab in labels])
    return m @ theta


def known_force_term(params: ParamSet, effect_params: dict[str, dict[str, float]],
                     t_s: Array, depth_mm: Array, velocity_mm_s: Array) -> Array:
    """The force the effects add to the base model (N): subtract it from a measurement before
    the reference EKF bank's update to run the bank on the extended model."""
    return (simulate_extended(params, effect_params, t_s, depth_mm, velocity_mm_s)
            - simulate_extended(params, {}, t_s, depth_mm, velocity_mm_s))
