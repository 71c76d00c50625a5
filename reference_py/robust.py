"""The robust estimator: the paper's bank plus a batch output-error refinement after each insertion.

Why.  Started within a factor 5 the bank locks into the valley where sigma0, sigma1, f1 and beta
compensate one another (README, "Beyond the paper").  The data hold enough information — a batch
output-error fit over one insertion finds the parameters — so the robust estimator keeps the bank
for the online estimate and, once per insertion, fits the model to a decimated record of it:

1. While the needle is in the tissue, every D-th sample (t, l, v, f) goes into a buffer of
   ``buffer_len`` entries, starting with the last sample at the surface.  When the buffer fills,
   every other entry is dropped and D doubles, so any insertion fits in bounded memory.
2. When the depth returns to 0 (the insertion is over), a Levenberg–Marquardt fit of the model's
   identified log-parameters minimises the squared output error over the buffer (z simulated from
   0 with ``fit_substeps`` RK3 sub-steps between entries, the same sensitivities as the filters).
   It runs from two starts — the bank's current estimate and the previous refinement (at first,
   the configured nominal) — for ``fit_iterations`` iterations each, and keeps the better fit.
3. The bank restarts from the refined parameters (u = 0 around them, P(u) = ``restart_p0_u``).

Work is bounded: each refinement costs 2 * (fit_iterations + 1) simulations of ``buffer_len``
entries; nothing is allocated.  The fit's residual RMS gives the confidence
c = sqrt(R) / max(rms, sqrt(R)) in (0, 1], and the CONVERGED status bit is set when c >= 0.75
and the fit moved the parameters by less than 5 % (log) since the previous refinement.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .bank import STATUS_REJECTED, FilterBank, StepOutput
from .config import (ROBUST_INT_RANGES, ROBUST_POSITIVE_FIELDS, ROBUST_UPPER_BOUNDS,
                     EstimatorConfig)
from .fmath import Array, Real
from .model import (ScaledParams, Theta, clamp_depth, depth_terms, output, output_du, output_dz,
                    smooth_sign)
from .params import IDX, MODEL_PARAMS, PARAM_NAMES
from .rk3 import rk3_step

STATUS_REFINED = 1 << 9      # a batch refinement ran at this sample and restarted the bank
STATUS_CONVERGED = 1 << 10   # the last refinement agreed with the data and with the previous one
STATUS_REFINING = 1 << 15    # a slice of a refinement ran at this sample (C: nte_robust.c)
COST_HUGE = 1.0e30           # cost of a diverged trial (finite in float32 too)


@dataclass(frozen=True)
class RobustConfig:
    buffer_len: int = 96          # decimated samples kept per insertion (4 reals each)
    fit_substeps: int = 2         # RK3 sub-steps between buffer entries
    fit_iterations: int = 8       # LM iterations per start
    min_entries: int = 24         # a shorter insertion is not refined
    restart_p0_u: float = 0.01    # bank covariance of u after a restart, log^2
    lm_lambda0: float = 1e-2      # initial LM damping
    converged_confidence: float = 0.75
    converged_change: float = 0.05
    slice_entries: int = 1        # buffer entries the C library simulates per sample (0: all)

    def slices(self) -> int:
        """Samples a refinement takes in the C library (nte_robust.c refine_slice), from the
        one that ends the insertion to the one that adopts the fit: its 2 (fit_iterations + 1)
        simulations of buffer_len - 1 entries, slice_entries a sample (0: all at once)."""
        entries = 2 * (self.fit_iterations + 1) * (self.buffer_len - 1)
        return 1 if self.slice_entries == 0 else -(-entries // self.slice_entries)

    def validate(self) -> None:
        """Raise ValueError naming the first invalid field.  The ranges are config.py's
        ROBUST_INT_RANGES, ROBUST_POSITIVE_FIELDS and ROBUST_UPPER_BOUNDS, from which the C
        checks are generated."""
        lo, hi = ROBUST_INT_RANGES["buffer_len"]
        if not (lo <= self.buffer_len <= hi and self.buffer_len % 2 == 0):
            raise ValueError(f"robust buffer_len must be even and in {lo}..{hi}")
        for name in ("fit_substeps", "fit_iterations", "slice_entries"):
            lo, hi = ROBUST_INT_RANGES[name]
            if not lo <= getattr(self, name) <= hi:
                raise ValueError(f"robust {name} must be in {lo}..{hi}")
        lo, hi = ROBUST_INT_RANGES["min_entries"]
        if not lo <= self.min_entries <= min(hi, self.buffer_len):
            raise ValueError(f"robust min_entries must be in {lo}..buffer_len")
        for name in ROBUST_POSITIVE_FIELDS:
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"robust {name} must be finite and > 0 (got {v!r})")
        for name, hi in ROBUST_UPPER_BOUNDS.items():
            if getattr(self, name) > hi:
                v = getattr(self, name)
                raise ValueError(f"robust {name} must be <= {hi:g} (got {v!r})")


class RobustEstimator:
    """Bank + per-insertion refinement, on a batch axis like the bank."""

    def __init__(self, R: Real, cfg: EstimatorConfig, nominal: list[list[float]],
                 rcfg: RobustConfig | None = None) -> None:
        self.R, self.cfg = R, cfg
        self.rcfg = rcfg or RobustConfig()
        self.rcfg.validate()
        if cfg.model == 3:
            # its batch fit simulates Models I and II only; Model III would need the direction
            # state and the relaxation memories in that simulation and their sensitivities
            raise ValueError("the robust estimator supports Models I and II only (Model III: "
                             "use the bank)")
        self.bank = FilterBank(R, cfg, nominal)
        self.batch = self.bank.batch
        self.names = MODEL_PARAMS[cfg.model]
        self.reset_record()

    def set_predict_only(self, on: bool) -> None:
        """Predict-only mode on or off from the next sample (the bank's; nte.h
        nte_set_predict_only)."""
        self.bank.set_predict_only(on)

    @property
    def predict_only(self) -> bool:
        return self.bank.predict_only

    def set_frozen(self, on: bool) -> None:
        """The parameters held or adapting from the next sample (the bank's; nte_set_frozen)."""
        self.bank.set_frozen(on)

    @property
    def frozen(self) -> bool:
        return self.bank.frozen

    def reset(self) -> None:
        """Back to the configured nominal: the bank's reset plus an empty record."""
        self.bank.reset()
        self.reset_record()

    def reset_record(self) -> None:
        R, B = self.R, self.batch
        n = self.rcfg.buffer_len
        self.buf = np.zeros((4, n, B), dtype=R.dtype)     # t_rel s, depth, velocity, force
        self.count = np.zeros(B, dtype=np.int64)          # entries in the buffer
        self.decim = np.ones(B, dtype=np.int64)           # keep every decim-th sample
        self.phase = np.zeros(B, dtype=np.int64)          # samples seen since the buffer start
        self.t0 = np.zeros(B, dtype=np.int64)             # buffer start time, us
        self.inside = np.zeros(B, dtype=bool)             # needle in tissue
        self.prev_theta = self._theta_list(self.bank.th)  # start (b) of the next refinement
        self.has_refined = np.zeros(B, dtype=bool)
        self.converged = np.zeros(B, dtype=bool)
        # predict-only was on during this insertion: not recorded further, not refined
        self.tainted = np.zeros(B, dtype=bool)
        self.confidence = R.full(B, 0.0)
        # a refinement in progress (the C library slices it across samples): samples left
        # until its result is adopted, and that result (theta, confidence, convergence)
        self.refining = np.zeros(B, dtype=bool)
        self.slices_left = np.zeros(B, dtype=np.int64)
        self.pending: tuple[list[Array], Array, Array] | None = None
        # the latest sample at the surface: the anchor (z = 0) of the next insertion's record
        self.last_surface = (np.zeros(B, dtype=np.int64), R.full(B, 0.0), R.full(B, 0.0),
                             R.full(B, 0.0))

    # ------------------------------------------------------------------------------------
    def step(self, t_us: Array, depth: Array, velocity: Array, force: Array) -> StepOutput:
        R = self.R
        out = self.bank.step(t_us, depth, velocity, force)
        valid = (out.status & np.uint32(STATUS_REJECTED)) == 0
        po = self.bank.predict_only
        if self.bank.contact is not None:
            # the record holds what the bank was given: tissue depth, tare-free force
            depth, force = self.bank.fed
        elif po:
            force = R.full(self.batch, 0.0)   # predict-only: the force is not read
        l = R.arr(depth)
        at_surface = valid & ~(l > R.c(0.0))
        entering = valid & (l > R.c(0.0)) & ~self.inside
        leaving = at_surface & self.inside
        # a new insertion starts from the last surface sample (z = 0 there), unless the last
        # one's refinement still runs on the buffer
        busy = self.refining
        self._restart_buffer(entering & ~busy, t_us)
        # an insertion during which predict-only was on, or the parameters were held, is
        # neither recorded further nor refined (nte.h THE PREDICT-ONLY MODE, HELD PARAMETERS);
        # nor is one that began while the last one was being fitted
        self.tainted = np.where(entering, busy, self.tainted) | po | self.bank.frozen
        self._record(valid & (self.inside | entering) & ~self.tainted, t_us, depth, velocity,
                     force)
        self.inside = (self.inside | entering) & ~at_surface
        begin = leaving & ~self.tainted & (self.count >= self.rcfg.min_entries)
        if np.any(begin):
            with np.errstate(all="ignore"):   # trial steps may overflow; they are rejected
                self._fit(begin)
        # the C library works on the fit over slices() samples from this one on and adopts it
        # at the last, unless the parameters are held or predict-only is on by then
        slicing = self.refining.copy()
        self.slices_left = np.where(slicing, self.slices_left - 1, self.slices_left)
        done = slicing & (self.slices_left == 0)
        self.refining = self.refining & ~done
        refined = done & ~po & ~self.bank.frozen
        if np.any(refined):
            self._adopt(refined)
        self.count = np.where(leaving, 0, self.count)
        # remember the surface sample as the anchor of the next insertion
        self._anchor(at_surface, t_us, depth, velocity, force)
        status = out.status | np.where(refined, np.uint32(STATUS_REFINED), np.uint32(0))
        status = status | np.where(slicing, np.uint32(STATUS_REFINING), np.uint32(0))
        status = status | np.where(self.converged, np.uint32(STATUS_CONVERGED), np.uint32(0))
        params, sds = self.bank.parameter_estimates()
        out = replace(out, status=status,
                      params=np.where(refined[None, :], params, out.params),
                      params_sd=np.where(refined[None, :], sds, out.params_sd))
        self.bank.last = out
        return out

    # --- the decimated buffer ------------------------------------------------------------
    def _anchor(self, mask: Array, t_us: Array, depth: Array, v: Array, f: Array) -> None:
        R = self.R
        ts, ls, vs, fs = self.last_surface
        self.last_surface = (np.where(mask, t_us, ts), np.where(mask, R.arr(depth), ls),
                             np.where(mask, R.arr(v), vs), np.where(mask, R.arr(f), fs))

    def _restart_buffer(self, mask: Array, t_us: Array) -> None:
        if not np.any(mask):
            return
        ts, ls, vs, fs = self.last_surface
        R = self.R
        self.t0 = np.where(mask, ts, self.t0)
        self.count = np.where(mask, 1, self.count)
        self.decim = np.where(mask, 1, self.decim)
        self.phase = np.where(mask, 1, self.phase)
        for row, val in ((0, R.full(self.batch, 0.0)), (1, ls), (2, vs), (3, fs)):
            self.buf[row, 0] = np.where(mask, val, self.buf[row, 0])

    def _record(self, mask: Array, t_us: Array, depth: Array, v: Array, f: Array) -> None:
        R = self.R
        take = mask & ((self.phase % self.decim) == 0)
        full = take & (self.count >= self.rcfg.buffer_len)
        if np.any(full):
            # keep entries 0, 2, 4, ...: the buffer stays uniformly decimated
            half = self.rcfg.buffer_len // 2
            comp = self.buf[:, 0::2, :]
            self.buf[:, :half, :] = np.where(full[None, None, :], comp, self.buf[:, :half, :])
            self.count = np.where(full, half, self.count)
            self.decim = np.where(full, self.decim * 2, self.decim)
            take = take & ((self.phase % self.decim) == 0)
        t_rel = (t_us - self.t0).astype(R.dtype) / R.c(1.0e6)
        idx = np.minimum(self.count, self.rcfg.buffer_len - 1)
        cols = np.arange(self.batch)
        for row, val in ((0, t_rel), (1, R.arr(depth)), (2, R.arr(v)), (3, R.arr(f))):
            cur = self.buf[row, idx, cols]
            self.buf[row, idx, cols] = np.where(take, val, cur)
        self.count = np.where(take, self.count + 1, self.count)
        self.phase = np.where(mask, self.phase + 1, self.phase)

    # --- the refinement ------------------------------------------------------------------
    def _theta_list(self, th: Theta) -> list[Array]:
        return [getattr(th, name).copy() for name in PARAM_NAMES]

    def slices(self) -> int:
        """Samples a refinement takes (RobustConfig.slices)."""
        return self.rcfg.slices()

    def _fit(self, mask: Array) -> None:
        """The refinement of the runs in ``mask`` from their buffers as they are now: the
        better of the two starts' fits, its confidence and convergence, kept in ``pending``
        until the sample that adopts them (_adopt)."""
        R, cfg = self.R, self.cfg
        starts = [self._theta_list(self.bank.th),
                  [np.where(self.has_refined, p, q) for p, q in
                   zip(self.prev_theta, self._theta_list(self.bank.initial_theta))]]
        best_theta, best_cost = None, None
        for theta0 in starts:
            theta, cost = self._lm(theta0)
            if best_cost is None:
                best_theta, best_cost = theta, cost
            else:
                better = cost < best_cost
                best_theta = [np.where(better, a, b) for a, b in zip(theta, best_theta)]
                best_cost = np.where(better, cost, best_cost)
        n_used = np.maximum(self.count, 1).astype(R.dtype)
        rms = np.sqrt(best_cost / n_used)
        sq_r = np.sqrt(R.c(cfg.r_n2))
        conf = sq_r / np.where(rms > sq_r, rms, sq_r)
        change = R.full(self.batch, 0.0)
        for name in self.names:
            j = IDX[name]
            rel = np.abs(best_theta[j] - self.prev_theta[j]) / np.abs(self.prev_theta[j])
            change = np.where(rel > change, rel, change)
        conv = self.has_refined & (conf >= R.c(self.rcfg.converged_confidence)) & (
            change <= R.c(self.rcfg.converged_change))
        if self.pending is not None:
            old_theta, old_conf, old_conv = self.pending
            best_theta = [np.where(mask, a, b) for a, b in zip(best_theta, old_theta)]
            conf, conv = np.where(mask, conf, old_conf), np.where(mask, conv, old_conv)
        self.pending = (best_theta, conf, conv)
        self.refining = self.refining | mask
        self.slices_left = np.where(mask, self.slices(), self.slices_left)

    def _adopt(self, mask: Array) -> None:
        """The runs in ``mask`` take their pending refinement: the bank restarts from it."""
        R = self.R
        assert self.pending is not None
        best_theta, conf, conv = self.pending
        self.converged = np.where(mask, conv, self.converged)
        self.confidence = np.where(mask, conf, self.confidence)
        self.prev_theta = [np.where(mask, a, b) for a, b in zip(best_theta, self.prev_theta)]
        self.has_refined = self.has_refined | mask
        self.bank.restart_from(best_theta, mask, R.c(self.rcfg.restart_p0_u))

    def _simulate(self, sp: ScaledParams, v: list[Array], with_jac: bool
                  ) -> tuple[Array, list[Array]]:
        """Squared-error cost and, optionally, the residual Jacobian terms J^T J, J^T r."""
        R, cfg = self.R, self.cfg
        names = self.names
        u = [R.full(self.batch, 0.0) for _ in PARAM_NAMES]
        for a, name in enumerate(names):
            u[IDX[name]] = v[a]
        th = sp.theta(u)
        n = len(names)
        eps = R.c(cfg.eps_mm_s)
        zero = R.c(0.0)
        z = R.full(self.batch, 0.0)
        sz = [R.full(self.batch, 0.0) for _ in names]
        cost = R.full(self.batch, 0.0)
        jtj = [[R.full(self.batch, 0.0) for _ in names] for _ in names]
        jtr = [R.full(self.batch, 0.0) for _ in names]
        for i in range(1, self.rcfg.buffer_len):
            live = i < self.count
            t_a, t_b = self.buf[0, i - 1], self.buf[0, i]
            l_a = clamp_depth(R, self.buf[1, i - 1])
            l_b = clamp_depth(R, self.buf[1, i])
            dt = np.where(live, t_b - t_a, R.c(0.0))
            pred = rk3_step(R, th, z, l_a, l_b, dt, self.rcfg.fit_substeps,
                            names if with_jac else ())
            z = np.where(l_b > zero, pred.z, zero)
            d = depth_terms(R, th, l_b)
            vel = self.buf[2, i]
            s = smooth_sign(R, vel, eps)
            o = output(th, d, z, s)
            r = self.buf[3, i] - o.h
            # samples where the smooth sign may disagree with the true direction carry no weight
            sure = (np.abs(s) > R.c(0.99)) | ~(np.abs(vel) >= R.c(cfg.v_still_mm_s))
            w = live & sure
            cost = cost + np.where(w, r * r, zero)
            if with_jac:
                hz = output_dz(th, d, o)
                jrow = []
                for a, name in enumerate(names):
                    # total derivative through the whole record: chain the step's partials
                    sz[a] = np.where(l_b > zero, pred.dz_dz0 * sz[a] + pred.dz_du[name], zero)
                    jrow.append(output_du(th, d, z, o, name) + hz * sz[a])
                for a in range(n):
                    ja = np.where(w, jrow[a], zero)
                    jtr[a] = jtr[a] + ja * r
                    for b in range(a, n):
                        jtj[a][b] = jtj[a][b] + ja * jrow[b]
        if with_jac:
            for a in range(n):
                for b in range(a):
                    jtj[a][b] = jtj[b][a]
        # a diverged trial (inf or NaN) must compare as the worst possible cost
        huge = R.c(COST_HUGE)
        cost = np.where(cost <= huge, cost, huge)
        return cost, [jtj, jtr]  # type: ignore[list-item]

    def _lm(self, theta0: list[Array]) -> tuple[list[Array], Array]:
        R = self.R
        names = self.names
        n = len(names)
        sp = ScaledParams.__new__(ScaledParams)
        sp.R = R
        sp.nominal = [t.copy() for t in theta0]
        f2 = theta0[IDX["f2"]]
        sp.kappa = self.bank.scaled.kappa
        sp.ex_nominal = theta0[IDX["f1"]] - sp.kappa * (-f2)
        v = [R.full(self.batch, 0.0) for _ in names]
        cost, (A, g) = self._simulate(sp, v, True)
        lam = R.full(self.batch, self.rcfg.lm_lambda0)
        umax = R.c(self.cfg.u_max)
        for _ in range(self.rcfg.fit_iterations):
            M = [[A[a][b] + (lam * A[a][a] if a == b else R.c(0.0)) for b in range(n)]
                 for a in range(n)]
            delta, ok = ldlt_solve(R, M, g)
            v_try = [np.clip(v[a] + delta[a], -umax, umax) for a in range(n)]
            c_try, (A_try, g_try) = self._simulate(sp, v_try, True)
            accept = ok & (c_try < cost)
            v = [np.where(accept, v_try[a], v[a]) for a in range(n)]
            cost = np.where(accept, c_try, cost)
            A = [[np.where(accept, A_try[a][b], A[a][b]) for b in range(n)] for a in range(n)]
            g = [np.where(accept, g_try[a], g[a]) for a in range(n)]
            lam = np.where(accept, lam / R.c(3.0), lam * R.c(4.0))
            lam = np.clip(lam, R.c(1e-7), R.c(1e7))
        u = [R.full(self.batch, 0.0) for _ in PARAM_NAMES]
        for a, name in enumerate(names):
            u[IDX[name]] = v[a]
        th = sp.theta(u)
        return self._theta_list(th), cost


def ldlt_solve(R: Real, M: list[list[Array]], b: list[Array]) -> tuple[list[Array], Array]:
    """Solve M x = b for symmetric positive definite M by M = L D L^T (no square roots).

    Returns x and a mask of the elements whose pivots were all positive (x is 0 elsewhere).
    """
    n = len(b)
    zero = R.c(0.0)
    L = [[zero * b[0] for _ in range(n)] for _ in range(n)]
    D = [zero * b[0] for _ in range(n)]
    ok = np.ones_like(b[0], dtype=bool)
    for j in range(n):
        acc = M[j][j]
        for k in range(j):
            acc = acc - (L[j][k] * L[j][k]) * D[k]
        ok = ok & (acc > zero)
        D[j] = np.where(acc > zero, acc, R.c(1.0))
        for i in range(j + 1, n):
            acc = M[i][j]
            for k in range(j):
                acc = acc - (L[i][k] * L[j][k]) * D[k]
            L[i][j] = acc / D[j]
    y = [zero * b[0] for _ in range(n)]
    for i in range(n):
        acc = b[i]
        for k in range(i):
            acc = acc - L[i][k] * y[k]
        y[i] = acc
    x = [zero * b[0] for _ in range(n)]
    for i in reversed(range(n)):
        acc = y[i] / D[i]
        for k in range(i + 1, n):
            acc = acc - L[k][i] * x[k]
        x[i] = acc
    x = [np.where(ok, xi, zero) for xi in x]
    return x, ok
