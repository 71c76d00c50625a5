"""The paper's bank of three joint state-parameter EKFs in switching mode (§IV, Fig. 1, Table I).

Each filter i estimates z together with its own subset of the scaled parameters (Table I); the
other parameters are held at their latest estimates.  All filters share one model: z and every u.

Schedule "all" (default), per sample k:  for i = 1, 2, 3 in turn, filter i predicts z from the
shared z(k-1) with the *current* shared parameters (which already hold the updates of filters
< i at this sample), predicts its covariance, updates with the force f(k), and writes its
parameter estimates into the shared model; the shared z(k) is the last filter's posterior.

Schedule "rotate": filter (k mod 3) alone updates at sample k; one prediction (with the
sensitivities to every identified parameter) serves all three, and the two idle filters only
propagate their covariances.

Each filter of a sample runs _predict -> _measure -> _update_and_guard (the C library's
predict, measure and update_and_guard in nte_bank.c, one for one).

Everything runs on a batch axis: element b of every array is an independent run.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .config import EstimatorConfig, check_nominal
from .contact import ContactFrontEnd
from .ekf import Matrix, joseph_update, positive_definite, predict_covariance
from .fmath import Array, Real
from .identified import dynamic, filter_subsets, identified_names, relax_count
from .layers import (STATUS_DROP, STATUS_RUPTURE, LayerSets, RuptureDetector, tear_prior,
                     tear_rescale)
from .model import (BatchScaled, DepthTerms, Theta, clamp_depth, depth_terms, exact_sign,
                    output, output_du, output_dz, smooth_sign, steady_state_z)
from .params import ALL_NAMES, IDX, PARAM_NAMES, RELAX_NAMES, RELAX_NOMINAL
from .relax import relax_fractions, relax_odds, relax_output, relax_terms
from .rk3 import Rk3Result, rk3_step

# Status bits of one sample (the C library uses the same values)
STATUS_INIT = 1 << 0            # first sample: nothing to predict from, estimate not yet updated
STATUS_REJECTED = 1 << 1        # the sample was invalid and ignored; outputs hold
STATUS_GATED = 1 << 2           # a filter's innovation failed the gate; its update was skipped
STATUS_FILTER_RESET = 1 << 3    # a filter lost positive-definiteness / finiteness and was reset
STATUS_GAP = 1 << 4             # time gap > dt_max: z restarted at its steady state
STATUS_OUT_OF_TISSUE = 1 << 5   # depth <= 0: z held at 0
STATUS_CLIPPED = 1 << 6         # a scaled parameter hit |u| = u_max
STATUS_FLOORED = 1 << 7         # a variance was raised to its floor
STATUS_SIGN_UNCERTAIN = 1 << 8  # R inflated: the smooth sign may disagree with the motion
# bits 9, 10 and 15 are the robust estimator's (robust.py), 12 and 16 the layers' (layers.py)
STATUS_DIVERGED = 1 << 11       # a predicted force or z left its range (_in_range): filter
#                                 reset, z at its steady state; never published out of range
STATUS_NAMES = ("init", "rejected", "gated", "filter_reset", "gap", "out_of_tissue", "clipped",
                "floored", "sign_uncertain")
STATUS_PREDICT_ONLY = 1 << 13   # processed in predict-only mode (cfg.predict_only or
#                                 set_predict_only): the model alone, force not read
STATUS_FROZEN = 1 << 14         # the parameters were held (set_frozen): z updated, no u moved
#: the bits one filter can raise (StepOutput.filter_status; nte.h NTE_STATUS_FILTER_BITS)
FILTER_BITS = (STATUS_GATED | STATUS_FILTER_RESET | STATUS_DIVERGED | STATUS_CLIPPED
               | STATUS_FLOORED | STATUS_SIGN_UNCERTAIN)

# Counters of rejected samples, by cause
REJECT_NONFINITE, REJECT_RANGE, REJECT_TIME = 0, 1, 2

#: the data's bound on the published force: at most this many times the largest |force|
#: accepted in the current insertion (at least the configured noise sd, sqrt(r_n2)).  A model
#: whose parameters cannot describe the data (a sensor mounted the other way round, starts
#: far off) otherwise published up to 70x the largest force it was ever given
#: (nte-ref plausible); beyond it the published estimate is treated as diverged (z to its
#: steady state, the force limited to the bound, STATUS_DIVERGED).  Not in predict-only mode:
#: no force is read there.
DATA_BOUND = 10.0


@dataclass
class StepOutput:
    force_hat: Array     # posterior force estimate, N
    z: Array             # posterior internal state
    innovation: Array    # first filter's one-step-ahead innovation f - h(prior), N
    nis: Array           # its normalised innovation squared
    status: Array        # uint32 bit set (STATUS_*)
    params: Array        # (n_identified, batch) physical estimates
    params_sd: Array     # (n_identified, batch) standard deviations
    # the contact front end (contact.py; all 0 when it is off): the surface found (stage mm,
    # NaN until found), the tare (N) and the state (contact.CONTACT_AIR / CONTACT_TISSUE)
    surface_mm: Array | None = None
    tare_n: Array | None = None
    contact: Array | None = None
    # Model III's layer index (layers.py; 0 for Models I and II and with the layers off)
    layer: Array | None = None
    # (3, batch) uint32: the FILTER_BITS each filter raised (0 at a rejected and a first sample)
    filter_status: Array | None = None


class FilterBank:
    """The bank for a batch of runs.  ``nominal``: per-run list of the seven start values (or
    nine: Model III's relaxation strengths g_fast, g_slow appended; default RELAX_NOMINAL)."""

    def __init__(self, R: Real, cfg: EstimatorConfig, nominal: list[list[float]],
                 layer_values: list[list[list[float]]] | None = None,
                 layer_starts: list[list[float]] | None = None) -> None:
        """``layer_values``: per run, the values of each of cfg.layer_sets (LAYER_SET_NAMES
        order); ``layer_starts``: per run, their starts (mm); default: the configuration's own
        for every run."""
        cfg.validate()
        check_nominal(nominal)
        self.R, self.cfg = R, cfg
        self.batch = len(nominal)
        self.identified = identified_names(cfg)
        self.subsets = filter_subsets(cfg)
        self.m3 = cfg.model == 3
        self.n_relax = relax_count(cfg)
        # Model III's turn-over length starts at the configured presliding_mm
        nominal = [list(row) + [RELAX_NOMINAL[nm] for nm in RELAX_NAMES[len(row) -
                                                                        len(PARAM_NAMES):]]
                   + [cfg.presliding_mm] for row in nominal]
        if cfg.model == 1:
            # Model I: beta is the fixed normalising constant beta0 of the configuration
            nominal = [row[:IDX["beta"]] + [cfg.beta0] + row[IDX["beta"] + 1:] for row in nominal]
        # per-parameter nominal arrays: nominal[b][j] -> column j over b
        cols = list(zip(*nominal))
        self.scaled = BatchScaled(R, cols, self.batch)
        if self.n_relax:
            idx = [IDX[nm] for nm in RELAX_NAMES[:self.n_relax]]
            for j, Gk in zip(idx, relax_odds(R, [self.scaled.nominal[j] for j in idx])):
                self.scaled.nominal[j] = Gk
        self._nominal0 = ([x.copy() for x in self.scaled.nominal], self.scaled.ex_nominal.copy())
        self.c = _Constants(R, cfg)
        # the surface and tare front end, at the start of every sample's processing
        # Model III's works in units of the sensor's own noise (contact.NOISE_REF_N), and so
        # does the bank (_scale_to_sensor)
        self.contact = (ContactFrontEnd(R, cfg.contact, cfg.r_n2, cfg.v_still_mm_s, self.batch,
                                        sensor_units=self.m3)
                        if cfg.contact.enabled else None)
        # Model III's layer index: a rupture detector on filter 1's innovations
        self.layers = (RuptureDetector(R, self.batch, cfg.v_still_mm_s)
                       if self.m3 and cfg.layers else None)
        # Model III's layer sets (layers.py): the values the model switches to in predict-only
        # mode below each set's start (no sets: nothing switches)
        self.layer_sets = LayerSets(R, self.batch, cfg.layer_sets, layer_values, layer_starts,
                                    self._nominal0, self.scaled.kappa)
        self.frozen = False     # set_frozen: the parameters held (kept by reset)
        self.scale_to_sensor = self.m3 and self.contact is not None
        self.reset()
        self.initial_theta = self.th

    # ------------------------------------------------------------------------------------
    def reset(self) -> None:
        """Back to the configured nominal parameters, the initial covariances, no history."""
        R, B = self.R, self.batch
        self.scaled.nominal = [x.copy() for x in self._nominal0[0]]
        self.scaled.ex_nominal = self._nominal0[1].copy()
        self.u = [R.full(B, 0.0) for _ in ALL_NAMES]
        self.th = self.scaled.theta(self.u)
        self.z = R.full(B, 0.0)
        self.P = [self._p0(len(s) + 1) for s in self.subsets]
        self.initialised = np.zeros(B, dtype=bool)
        # Model III: the direction state and the relaxation memories (MODEL.md §3b)
        self.sdir = R.full(B, 0.0)
        # its sensitivity to delta's log-ratio, ds/du_delta, and whether the motion has gone
        # against it since the surface (delta is learned from turn-overs only)
        self.sdir_du = R.full(B, 0.0)
        self.turned = np.zeros(B, dtype=bool)
        self.delta = self.scaled.nominal[IDX["delta"]] * R.exp(self.u[IDX["delta"]])
        self.mrel = [R.full(B, 0.0) for _ in range(self.n_relax)]
        self.G = [self.scaled.nominal[IDX[nm]] * R.exp(self.u[IDX[nm]])
                  for nm in RELAX_NAMES[:self.n_relax]]
        self.t_prev = np.zeros(B, dtype=np.int64)
        self.l_prev = R.full(B, 0.0)
        # the largest |force| accepted in this insertion (0 out of tissue), N: DATA_BOUND's base
        self.y_max = R.full(B, 0.0)
        self.k = np.zeros(B, dtype=np.int64)   # accepted samples since reset (rotation index)
        self.kf = R.full(B, 1.0)   # the bank's force unit, units per N (contact.unit())
        self.rejects = np.zeros((3, B), dtype=np.int64)
        self.gated_run = [np.zeros(B, dtype=np.int64) for _ in self.subsets]
        if self.contact is not None:
            self.contact.reset()
        if self.layers is not None:
            self.layers.reset()
        self.layer_sets.reset()
        self.last = StepOutput(R.full(B, 0.0), R.full(B, 0.0), R.full(B, 0.0), R.full(B, 0.0),
                               np.zeros(B, dtype=np.uint32),
                               R.arr(np.zeros((len(self.identified), B))),
                               R.arr(np.zeros((len(self.identified), B))))

    def _p0(self, n: int, p0_u: Array | None = None) -> Matrix:
        R, B, c = self.R, self.batch, self.c
        P: Matrix = [[R.full(B, 0.0) for _ in range(n)] for _ in range(n)]
        P[0][0] = R.full(B, 0.0) + c.p0_z
        for i in range(1, n):
            P[i][i] = R.full(B, 0.0) + (c.p0_u if p0_u is None else p0_u)
        return P

    def restart_from(self, theta: list[Array], mask: Array, p0_u: Array) -> None:
        """Re-centre the scaled parameters on ``theta`` (seven physical arrays) where ``mask``:
        u = 0 there, covariances P0 with var(u) = p0_u; z and the sample history carry on."""
        R = self.R
        for j in range(len(PARAM_NAMES)):
            self.scaled.nominal[j] = np.where(mask, theta[j], self.scaled.nominal[j])
        ex = theta[IDX["f1"]] - self.scaled.kappa * (-theta[IDX["f2"]])
        self.scaled.ex_nominal = np.where(mask, ex, self.scaled.ex_nominal)
        self.u = [np.where(mask, R.c(0.0), u) for u in self.u]
        fresh = self.scaled.theta(self.u)
        self.th = Theta(*(np.where(mask, getattr(fresh, f), getattr(self.th, f))
                          for f in Theta.__dataclass_fields__))
        for i, names in enumerate(self.subsets):
            P0 = self._p0(len(names) + 1, p0_u)
            self.P[i] = [[np.where(mask, P0[a][b], self.P[i][a][b]) for b in range(len(P0))]
                         for a in range(len(P0))]
            self.gated_run[i] = np.where(mask, 0, self.gated_run[i])

    # ------------------------------------------------------------------------------------
    def set_predict_only(self, on: bool) -> None:
        """Predict-only mode on or off from the next sample, for every run of the batch (the
        C library's nte_set_predict_only, nte.h THE PREDICT-ONLY MODE): on, every filter
        predicts and none updates, the parameters stay as identified so far, the force is not
        read; off, the filters update again from the state reached.  Nothing else changes here
        (z, memories, parameters, covariances kept).  Writes cfg.predict_only, so the mode
        persists across reset()."""
        self.cfg = replace(self.cfg, predict_only=bool(on))

    @property
    def predict_only(self) -> bool:
        return bool(self.cfg.predict_only)

    def set_frozen(self, on: bool) -> None:
        """Hold the parameters (on) or let them adapt again from the next sample, for every
        run of the batch (nte_set_frozen, nte.h HELD PARAMETERS): every filter still updates
        z, with its gain's parameter rows 0.  Kept by reset()."""
        self.frozen = bool(on)

    def step(self, t_us: Array, depth: Array, velocity: Array, force: Array) -> StepOutput:
        """One sample: time in integer microseconds, depth mm, velocity mm/s, force N."""
        R, c = self.R, self.c
        t_us = np.asarray(t_us, dtype=np.int64)
        l_in = np.asarray(depth, dtype=R.dtype)
        v = np.asarray(velocity, dtype=R.dtype)
        y = np.asarray(force, dtype=R.dtype)
        po = self.cfg.predict_only
        if po:
            # the force is not read (a broken sensor's value rejects nothing)
            y = R.full(self.batch, 0.0)
        if self.contact is not None:
            self.contact.predict_only = po
        with np.errstate(all="ignore"):
            finite = np.isfinite(l_in) & np.isfinite(v) & np.isfinite(y)
            if self.contact is None:
                in_depth = (l_in >= c.depth_min) & (l_in <= c.depth_max)
            else:
                # the stage position: its origin is arbitrary and the air gap is no error
                in_depth = (l_in >= -c.depth_max) & (l_in <= c.depth_max)
            in_range = in_depth & (np.abs(v) <= c.speed_max) & (np.abs(y) <= c.force_max)
            later = ~self.initialised | (t_us > self.t_prev)
            valid = finite & in_range & later
            self.rejects[REJECT_NONFINITE] += ~finite
            self.rejects[REJECT_RANGE] += finite & ~in_range
            self.rejects[REJECT_TIME] += finite & in_range & ~later
            first = valid & ~self.initialised
            run = valid & self.initialised
            if self.contact is not None:
                # stage and raw force -> tissue depth and tare-free force (valid samples only)
                l_in, y = self.contact.step(valid, l_in, v, y)
                if self.scale_to_sensor:
                    self._scale_to_sensor()
                    y = y * self.kf
            # invalid samples are computed on harmless stand-ins, then discarded
            l_in = np.where(valid, l_in, self.l_prev)
            v = np.where(valid, v, R.c(0.0))
            y = np.where(valid, y, R.c(0.0))
            dt = (np.where(run, t_us - self.t_prev, 1)).astype(R.dtype) / c.us_per_s
            out = self._advance(first, run, dt, l_in, v, y)
            self.fed = (l_in, y)   # what the bank was given (the robust estimator records it)
        status = np.where(valid, out.status, np.uint32(STATUS_REJECTED))
        status = status | np.where(first, np.uint32(STATUS_INIT), np.uint32(0))
        if po:
            status = status | np.uint32(STATUS_PREDICT_ONLY)
        if self.frozen:
            status = status | np.uint32(STATUS_FROZEN)
        if self.scale_to_sensor:
            out = self._unscaled(out)
        held = ("force_hat", "z", "innovation", "nis", "params", "params_sd")  # when rejected
        out = StepOutput(**{n: np.where(valid, getattr(out, n), getattr(self.last, n))
                            for n in held}, status=status,
                         filter_status=np.where(valid, out.filter_status, np.uint32(0)))
        if self.contact is not None:
            out.surface_mm, out.tare_n, out.contact = self.contact.published()
        else:
            out.surface_mm, out.tare_n = R.full(self.batch, 0.0), R.full(self.batch, 0.0)
            out.contact = np.zeros(self.batch, dtype=np.uint32)
        if po and self.layer_sets.starts:
            out.layer = self.layer_sets.layer.copy()   # predict-only: the layer of the set in use
        elif self.layers is not None:
            out.layer = self.layers.layer.copy()
        else:
            out.layer = np.zeros(self.batch, dtype=np.uint32)
        self.t_prev = np.where(valid, t_us, self.t_prev)
        self.l_prev = np.where(valid, l_in, self.l_prev)
        self.initialised = self.initialised | valid
        self.k = self.k + run
        self.last = out
        return out

    def _scale_to_sensor(self) -> None:
        """In contact, the bank's force unit is the front end's (contact.unit(), from the noise
        learned in the air); where it changes (the first sample of an insertion) z, the
        relaxation memories and the data's bound carry over to the new unit (times the ratio;
        z and the memories are 0 at the surface).  The nominal values are not converted: the
        paper's starts are tuned relative to forces measured in units of an 8-50 mN sensor's
        noise, and converted (a start at the data's scale) they brought the reversal's tail
        back (phantom x0.03, select set: reversal peak 4.6 -> 7.6, 90th percentile 6 -> 23).
        C twin: nte_bank.c nte_bank_set_unit."""
        k = np.where(self.contact.contact, self.contact.unit(), self.kf)
        change = k != self.kf
        if not np.any(change):
            return
        r = k / self.kf
        self.z = np.where(change, self.z * r, self.z)
        self.mrel = [np.where(change, m * r, m) for m in self.mrel]
        self.y_max = np.where(change, self.y_max * r, self.y_max)
        self.kf = k

    def _unscaled(self, out: StepOutput) -> StepOutput:
        """``out`` in newtons (and z, beta, sigma2 in their units per N): divided by kf."""
        kf = self.kf
        params, sds = out.params.copy(), out.params_sd.copy()
        for nm in ("beta", "sigma2"):
            if nm in self.identified:
                j = self.identified.index(nm)
                params[j] = params[j] / kf
                sds[j] = sds[j] / kf
        return replace(out, force_hat=out.force_hat / kf, z=out.z / kf,
                       innovation=out.innovation / kf, params=params, params_sd=sds)

    # ------------------------------------------------------------------------------------
    def _advance(self, first: Array, run: Array, dt: Array, l_in: Array, v: Array,
                 y: Array) -> StepOutput:
        R, c, cfg = self.R, self.c, self.cfg
        B = self.batch
        status = np.zeros(B, dtype=np.uint32)
        fstat = np.zeros((len(self.subsets), B), dtype=np.uint32)
        l = clamp_depth(R, l_in)
        l_prev = clamp_depth(R, self.l_prev)
        surface = ~(l > R.c(0.0))
        gap = run & (dt > c.dt_max)
        if self.layer_sets.starts:
            self.th = self.layer_sets.enter(cfg.predict_only, run | first, l, surface,
                                            self.scaled, self.u, self.th)
        if self.m3 and cfg.direction_memory:
            s, s_du, turned = self._direction(l, l_prev, surface | first)
        else:
            s = smooth_sign(R, v, c.eps)
            s_du = turned = None
        # Model III: each relaxation branch's decay over this sample (exact for an input held
        # over the sample: stable at every rate)
        self._a_rel = [R.exp(-(dt / c.tau[k])) for k in range(self.n_relax)]
        status |= np.where(surface, np.uint32(STATUS_OUT_OF_TISSUE), np.uint32(0))
        status |= np.where(gap, np.uint32(STATUS_GAP), np.uint32(0))
        z_prev = self.z
        z_post = z_prev
        innovation0 = R.full(B, 0.0)
        nis0 = R.full(B, 0.0)
        rotate = cfg.schedule == "rotate"
        tear = z_prior0 = innovation_raw0 = None
        if rotate:
            # one prediction, with every identified parameter's sensitivity, serves all three
            shared_pred = rk3_step(R, self.th, z_prev, l_prev, l, dt, cfg.substeps,
                                   dynamic(self.identified))
        for i, names in enumerate(self.subsets):
            if rotate:
                pred = shared_pred
                active = run & ((self.k % 3) == i)
            else:
                pred = rk3_step(R, self.th, z_prev, l_prev, l, dt, cfg.substeps,
                                dynamic(names))
                active = run
            if cfg.predict_only:
                # the model alone: no filter updates (z is filter 0's prior, below)
                active = run & False
            d = depth_terms(R, self.th, l)
            x, P_pred, z_ss = self._predict(i, names, pred, d, gap | surface, surface)
            innovation, hrow, r_eff, in_range, st = self._measure(names, d, x[0], s, s_du, v,
                                                                  y, active)
            fstat[i] |= st
            if i == 0 and self.layers is not None:
                z_prior0, innovation_raw0 = x[0], innovation    # for tear_rescale, below
                # the innovation in units of the sensor noise: the front end's, or sqrt(r_n2)
                sigma = (self.contact.noise_sigma(in_unit=True) if self.contact is not None
                         else np.sqrt(R.full(B, 0.0) + c.r))
                found = self.layers.watch(first, run, l, v, innovation, in_range, sigma,
                                          cfg.predict_only)   # STATUS_RUPTURE, _DROP or 0
                tear = found != 0
                status |= found
            u_delta = self.u[IDX["delta"]]
            z_i, nis, st = self._update_and_guard(i, names, x, P_pred, hrow, innovation, r_eff,
                                                  active, run, in_range, z_ss, tear)
            fstat[i] |= st
            status |= fstat[i]
            if "delta" in names:
                # the direction state of this sample follows its update of delta (first order)
                s = self._direction_update(s, s_du, self.u[IDX["delta"]] - u_delta)
            z_post = np.where(active, z_i, z_post)
            if cfg.predict_only and i == 0:
                z_post = np.where(run, z_i, z_post)   # the prior, guarded: no update ran
            if rotate or i == 0:
                # a diverged prior's innovation is not published (it may not be finite)
                innovation0 = np.where(active, np.where(in_range, innovation, R.c(0.0)),
                                       innovation0)
                # an overflowed NIS (tiny R) is published saturated at COST_HUGE
                nis = np.where(nis <= R.c(1.0e30), nis, R.c(1.0e30))
                nis0 = np.where(active, np.where(in_range, nis, R.c(0.0)), nis0)

        if tear is not None and np.any(tear) and not self.frozen:   # layers.tear_rescale
            z_post, self.mrel, self.th = tear_rescale(R, tear, y, innovation_raw0, z_prior0,
                                                      z_post, self.scaled, self.mrel, self.th)
        z_post = np.where(surface & run, R.c(0.0), z_post)
        # posterior output with the final shared model
        d = depth_terms(R, self.th, l)
        # the first sample's z: its steady state, as after a gap (MODEL.md §2, "The first sample")
        z_first = steady_state_z(R, self.th, d)
        self.z = np.where(run, z_post, np.where(first & np.isfinite(z_first), z_first,
                                                np.where(first, R.c(0.0), self.z)))
        o = output(self.th, d, self.z, s)
        force = o.h
        fe = o.h   # Model III: the elastic force the relaxation memories follow
        if self.n_relax:
            force = fe - relax_terms(R, self.G, self._a_rel, self.mrel, fe)[2]
        fed = run | first
        limit = c.force_max * self.kf
        if not cfg.predict_only:
            # the data's bound (DATA_BOUND): the largest |force| of this insertion so far,
            # this sample's included; after a sample out of tissue it starts again
            ay = np.abs(y)
            y_max = np.where(ay > self.y_max, ay, self.y_max)
            self.y_max = np.where(fed, np.where(surface, R.c(0.0), y_max), self.y_max)
            base = np.where(y_max > c.noise_sd, y_max, c.noise_sd)
            bound = c.data_bound * base
            limit = np.where(bound < limit, bound, limit)
        bad = fed & ~(self._in_range(d, self.z, force) & (np.abs(force) <= limit))
        if np.any(bad):
            # never publish a force or z outside their range (nor beyond the data's bound): z
            # to its steady state, and if the parameters still put the force out of range, the
            # force saturated at the limit (NaN: 0)
            z_ss = steady_state_z(R, self.th, d)
            z_fix = np.where(np.isfinite(z_ss), z_ss, R.c(0.0))
            self.z = np.where(bad, z_fix, self.z)
            o_fix = output(self.th, d, z_fix, s)
            fmax = limit
            h = o_fix.h
            if self.n_relax:
                fe = np.where(bad, o_fix.h, fe)
                h = o_fix.h - relax_terms(R, self.G, self._a_rel, self.mrel, o_fix.h)[2]
            h = np.where(np.abs(h) <= fmax, h,
                         np.where(h > fmax, fmax, np.where(h < -fmax, -fmax, R.c(0.0))))
            force = np.where(bad, h, force)
            status |= np.where(bad, np.uint32(STATUS_DIVERGED), np.uint32(0))
        if self.n_relax:
            # commit the memories with the posterior elastic force (0 out of tissue and at the
            # first sample, like z)
            mp = relax_terms(R, self.G, self._a_rel, self.mrel, fe)[1]
            self.mrel = [np.where(run & ~surface, mp[k],
                                  np.where(run | first, R.c(0.0), self.mrel[k]))
                         for k in range(self.n_relax)]
        if self.m3:
            self.sdir = np.where(run | first, s, self.sdir)
            if cfg.direction_memory:
                self.sdir_du = np.where(run | first, s_du, self.sdir_du)
                self.turned = np.where(run | first, turned, self.turned)
        innov = np.where(run, innovation0, y - force)
        nis = np.where(run, nis0, R.c(0.0))
        params, sds = self.parameter_estimates()
        return StepOutput(force, self.z, innov, nis, status, params, sds, filter_status=fstat)

    def _predict(self, i: int, names: tuple[str, ...], pred: Rk3Result, d: DepthTerms,
                 restart: Array, surface: Array) -> tuple[list[Array], Matrix, Array]:
        """Filter i's prior state (z restarted at the surface or after a gap), its predicted
        covariance F P F^T + Q, and z's steady state (0 out of tissue or where not finite)."""
        R, c = self.R, self.c
        zero = R.c(0.0)
        # out of tissue z is 0; after a gap it has relaxed to its steady state: either way
        # the prior z carries no memory of z(k-1)
        z_ss = steady_state_z(R, self.th, d)
        z_restart = np.where(surface, zero, z_ss)
        zp = np.where(restart, z_restart, pred.z)
        # z's row of the transition (the parameters' rows are a random walk: predict_covariance)
        f = [np.where(restart, zero, pred.dz_dz0)] + \
            [np.where(restart, zero, pred.dz_du[nm] if nm in pred.dz_du else zero)
             for nm in names]
        q = [c.q_z] + [c.q_u[nm] for nm in names]
        P_pred = predict_covariance(self.P[i], f, q)
        x = [zp] + [self.u[IDX[nm]] for nm in names]
        return x, P_pred, np.where(np.isfinite(z_ss), z_ss, zero)

    def _measure(self, names: tuple[str, ...], d: DepthTerms, zp: Array, s: Array,
                 s_du: Array | None, v: Array, y: Array, active: Array
                 ) -> tuple[Array, list[Array], Array, Array, Array]:
        """The predicted force's innovation, its Jacobian row, the effective R, and whether
        the prior z and its force are within their physical range (_in_range).  ``s_du``:
        the direction state's sensitivity ds/du_delta (Model III with the direction memory)."""
        R, c, cfg = self.R, self.c, self.cfg
        zero = R.c(0.0)
        status = np.zeros(self.batch, dtype=np.uint32)
        o = output(self.th, d, zp, s)
        hrow = [output_dz(self.th, d, o)] + [output_du(self.th, d, zp, o, nm)
                                             for nm in dynamic(names)]
        if "delta" in names:
            # the elastic force's s l fr moves with s: dfe/du_delta = l fr ds/du_delta
            hrow.append((d.l * o.fr) * s_du)
        h = o.h
        if self.n_relax:
            h, hrow = relax_output(self.R, self.G, self._a_rel, self.mrel, names, o.h, hrow)
        r_eff = c.r
        # Model III's direction state is known from the depth: no sign to be wrong about
        if cfg.sign_inflation and not (self.m3 and cfg.direction_memory):
            # the data follow the true direction sign(v), the model tanh(v/eps): their
            # difference is at most (1 - |s|) l fr, treated as extra measurement noise
            w = (R.c(1.0) - np.abs(s)) * (d.l * o.fr)
            moving = np.abs(v) >= c.v_still
            r_eff = c.r + np.where(moving, w * w, zero)
            status |= np.where(active & moving & (w * w > c.r), np.uint32(STATUS_SIGN_UNCERTAIN),
                               np.uint32(0))
        innovation = y - h
        return innovation, hrow, r_eff, self._in_range(d, zp, h), status

    def _direction(self, l: Array, l_prev: Array, restart: Array
                   ) -> tuple[Array, Array, Array]:
        """The direction state after the depth step l - l_prev: ds/dl = (1 - s sign(dl))/delta
        integrated exactly, s' = sigma + (s - sigma) E, E = exp(-|dl|/delta), sigma = sign(dl)
        (s held when dl = 0); 0 at the surface and at the first sample, like z.

        Also its sensitivity to u_delta (delta = nominal e^u, JACOBIANS.md §8), carried from
        sample to sample: dE/du = E |dl|/delta, so ds'/du = E ds/du + (s - sigma) E |dl|/delta.
        The second term (the drive) counts only once the motion has gone against s since the
        surface (sigma s < 0 at some sample: a turn-over): at the entry the force rises with
        the tissue's contact, not with a Dahl turn-over, and learning delta there drove it to
        a tenth of the true length (measured on the phantom).  Returns s', ds'/du, turned."""
        R = self.R
        zero = R.c(0.0)
        dl = l - l_prev
        sig = exact_sign(R, dl)
        adl = np.abs(dl) / self.delta
        E = R.exp(-adl)
        s = sig + (self.sdir - sig) * E
        turned = self.turned | ((sig * self.sdir) < zero)
        s_du = E * self.sdir_du + np.where(turned, ((self.sdir - sig) * E) * adl, zero)
        return (np.where(restart, zero, s), np.where(restart, zero, s_du),
                turned & ~restart)

    def _direction_update(self, s: Array, s_du: Array, du: Array) -> Array:
        """The direction state after its filter changed u_delta by du: s + ds/du du, within
        [-1, 1] (an exact s never leaves it)."""
        R = self.R
        one = R.c(1.0)
        s = s + s_du * du
        return np.where(s > one, one, np.where(s < -one, -one, s))

    def _in_range(self, d: DepthTerms, z: Array, h: Array) -> Array:
        """The physical range of a predicted force h = sigma0 z l + ... and of z: both |h| and
        the elastic part |sigma0 z l| within force_max_n (|z| <= force_max_n / (sigma0 l)).
        NaN is out of range."""
        fmax = self.c.force_max * self.kf
        return (np.abs(h) <= fmax) & (np.abs((self.th.sigma0 * z) * d.l) <= fmax)

    def _update_and_guard(self, i: int, names: tuple[str, ...], x: list[Array], P_pred: Matrix,
                          hrow: list[Array], innovation: Array, r_eff: Array, active: Array,
                          run: Array, in_range: Array, z_ss: Array, tear: Array | None = None
                          ) -> tuple[Array, Array, Array]:
        """The gated Joseph update (active filters), the guard, and the commit of filter i's
        covariance and parameters to the shared model.  Returns its posterior z, the NIS and
        the status bits."""
        R, c, cfg = self.R, self.c, self.cfg
        zero = R.c(0.0)
        status = np.zeros(self.batch, dtype=np.uint32)
        # a gate that has refused too many samples in a row would lock the filter out for
        # good (its collapsed covariance never admits the data again): open it once
        open_gate = self.gated_run[i] >= cfg.gate_reopen_after
        if tear is not None:
            # a layer tore: the drop is the tissue's, not the parameters' (layers.tear_prior)
            P_pred, hrow = tear_prior(R, P_pred, hrow, tear, self._p0(len(hrow)))
            open_gate = open_gate | tear
        upd = joseph_update(R, x, P_pred, hrow, innovation, r_eff, c.gate2, open_gate,
                            c.u_step_max if cfg.u_step_max > 0.0 else None, self.frozen)
        gated = active & ~upd.accepted
        status |= np.where(gated, np.uint32(STATUS_GATED), np.uint32(0))
        self.gated_run[i] = np.where(gated, self.gated_run[i] + 1,
                                     np.where(active, 0, self.gated_run[i]))
        newx = [np.where(active, upd.x[a], x[a]) for a in range(len(x))]
        newP = [[np.where(active, upd.P[a][b], P_pred[a][b]) for b in range(len(x))]
                for a in range(len(x))]
        # a prior that is not positive definite (or a non-positive innovation variance)
        # can still yield a plausible-looking posterior: judge the filter on both
        # and a prior whose force left its physical range has diverged
        prior_ok = positive_definite(R, P_pred) & (upd.s > zero) & in_range
        newx, newP, st = self._guard(newx, newP, x, prior_ok, ~in_range, z_ss)
        status |= np.where(run, st, np.uint32(0))
        # commit: every filter of a running sample keeps its propagated covariance
        self.P[i] = [[np.where(run, newP[a][b], self.P[i][a][b]) for b in range(len(x))]
                     for a in range(len(x))]
        for a, nm in enumerate(names):
            self.u[IDX[nm]] = np.where(run, newx[a + 1], self.u[IDX[nm]])
        self.th = self.scaled.refresh(self.th, self.u, dynamic(names))
        for k, nm in enumerate(RELAX_NAMES[:self.n_relax]):
            if nm in names:
                self.G[k] = self.scaled.nominal[IDX[nm]] * R.exp(self.u[IDX[nm]])
        if "delta" in names:
            self.delta = self.scaled.nominal[IDX["delta"]] * R.exp(self.u[IDX["delta"]])
        return newx[0], upd.nis, status

    def _guard(self, x: list[Array], P: Matrix, x_prior: list[Array], prior_ok: Array,
               diverged: Array, z_ss: Array) -> tuple[list[Array], Matrix, Array]:
        """Clip |u|, floor variances, and reset the filter when P or x went bad.

        Reset: P back to its initial value, the state back to the prior (0 where not finite);
        z of a diverged filter (its predicted force out of range) to its steady state z_ss.
        """
        R, c = self.R, self.c
        n = len(x)
        status = np.zeros(self.batch, dtype=np.uint32)
        for a in range(1, n):
            clipped = np.abs(x[a]) > c.u_max
            x[a] = np.where(x[a] > c.u_max, c.u_max, np.where(x[a] < -c.u_max, -c.u_max, x[a]))
            status |= np.where(clipped, np.uint32(STATUS_CLIPPED), np.uint32(0))
        ok = prior_ok & positive_definite(R, P)
        for a in range(n):
            ok = ok & np.isfinite(x[a])
        floors = [c.var_floor_z] + [c.var_floor_u] * (n - 1)
        for a in range(n):
            low = P[a][a] < floors[a]
            P[a][a] = np.where(low, floors[a], P[a][a])
            status |= np.where(ok & low, np.uint32(STATUS_FLOORED), np.uint32(0))
        P0 = self._p0(n)
        x = [np.where(ok, x[a], np.where(np.isfinite(x_prior[a]), x_prior[a], R.c(0.0)))
             for a in range(n)]
        x[0] = np.where(diverged, z_ss, x[0])
        P = [[np.where(ok, P[a][b], P0[a][b]) for b in range(n)] for a in range(n)]
        status |= np.where(ok, np.uint32(0), np.uint32(STATUS_FILTER_RESET))
        status |= np.where(diverged, np.uint32(STATUS_DIVERGED), np.uint32(0))
        return x, P, status

    # ------------------------------------------------------------------------------------
    def owner(self, name: str) -> tuple[int, int]:
        """(filter index, index in its state vector) of an identified parameter."""
        for i, names in enumerate(self.subsets):
            if name in names:
                return i, names.index(name) + 1
        raise KeyError(name)

    def parameter_estimates(self) -> tuple[Array, Array]:
        """Physical estimates and standard deviations (delta method on u) of the identified set."""
        th = self.th
        vals, sds = [], []
        g = relax_fractions(self.R, self.G) if self.n_relax else []
        for name in self.identified:
            i, a = self.owner(name)
            sd_u = np.sqrt(self.P[i][a][a])
            if name == "delta":
                vals.append(self.delta)
                sds.append(self.delta * sd_u)
                continue
            if name in RELAX_NAMES:
                # g = G / (1 + sum G): dg_k/du_k = g_k (1 - g_k)
                gk = g[RELAX_NAMES.index(name)]
                vals.append(gk)
                sds.append(np.abs(gk * (self.R.c(1.0) - gk)) * sd_u)
                continue
            vals.append(getattr(th, name))
            sds.append(np.abs(self.scaled.dtheta_du(th, name)) * sd_u)
        return np.stack(vals), np.stack(sds)


class _Constants:
    """Every configuration number in the working precision, rounded once."""

    def __init__(self, R: Real, cfg: EstimatorConfig) -> None:
        self.eps = R.c(cfg.eps_mm_s)
        self.r = R.c(cfg.r_n2)
        self.q_z = R.c(cfg.q_z)
        self.q_u = {n: R.c(cfg.q_for(n)) for n in ALL_NAMES}
        self.p0_z = R.c(cfg.p0_z)
        self.p0_u = R.c(cfg.p0_u)
        self.gate2 = R.c(cfg.gate_sigma) * R.c(cfg.gate_sigma)
        self.u_max = R.c(cfg.u_max)
        self.u_step_max = R.c(cfg.u_step_max)
        self.var_floor_z, self.var_floor_u = R.c(cfg.var_floor_z), R.c(cfg.var_floor_u)
        self.v_still = R.c(cfg.v_still_mm_s)
        self.dt_max = R.c(cfg.dt_max_s)
        self.depth_min, self.depth_max = R.c(cfg.depth_min_mm), R.c(cfg.depth_max_mm)
        self.speed_max = R.c(cfg.speed_max_mm_s)
        self.force_max = R.c(cfg.force_max_n)
        self.noise_sd = np.sqrt(self.r)
        self.data_bound = R.c(DATA_BOUND)
        self.tau = [R.c(cfg.tau_fast_s), R.c(cfg.tau_slow_s)]
        self.us_per_s = R.c(1.0e6)
