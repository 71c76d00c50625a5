"""The surface and tare front end: contact found online from the force onset.

Records as measured start with the needle in the air: the depth column is the stage position
(its origin anywhere, the tissue touched 2-15 mm along the stroke) and the force carries a small
tare (a few mN) and noise.  The bank needs the depth below the tissue surface and the force of
the tissue alone.  This front end sits at the start of a sample's processing
(FilterBank.step; the C library's nte_step via nte_contact.c, operation for operation) and turns
(stage x mm, velocity v mm/s, force f N) into (tissue depth l mm, tissue force f - tare N):

In the air (state AIR) it learns
  * the tare: a running mean of f, weight w = 1/min(n, tare_samples) for the n-th learned
    sample (a plain mean at first, then an exponential average of about tare_samples samples);
  * the noise: a running mean square of f about the tare with the same weight
    (ms <- ms + w (e (f - tare_new) - ms), e = f - tare_old), sigma = sqrt(max(ms, r_n2)), so the
    noise is never taken below the bank's own measurement noise.
  A one-sided CUSUM of the standardised residual, S <- max(0, S + e/sigma - cusum_drift_sigma),
  pauses the learning while it is above learn_gate_sigma: the slow force rise of a tented
  surface is then not averaged into the tare and the noise (which would raise the threshold as
  fast as the force and never let contact be seen).  The gate reads S before the sample, so
  whether a sample is learned does not depend on its own value (no bias of the tare).

Contact (AIR -> CONTACT) once learn_samples samples were learned: e = f - tare above
thr = max(k_sigma sigma, floor_n) for run_samples consecutive samples while the stage moves
inward (v > v_still_mm_s).

The surface, back-extrapolated: the onset segment is the run of samples, moving inward, with
e > 0 that ends at the detection (it starts where the force left the noise for good, later
than the true contact when the onset is a slow tent).  A straight line e = b0 + b1 h is fitted
to it by least squares, h = x - x0 from the segment's first stage position x0, and the surface
is where the line crosses the tare, x0 - b0/b1, kept within [x0 - (x - x0), x] (at most the
segment's own length back, never deeper than the detection).  A segment that gives no rising
line (fewer than two distinct positions, b1 <= 0 or not finite) puts the surface at x0.  On
the phantom this is within 0.5 mm of the truth at 1-3 mm/s (tests/python/test_contact.py).

In contact the tare and the noise are held; the bank gets l = max(0, x - surface) and f - tare.
Contact ends (CONTACT -> AIR) at a sample with the stage not below the surface (x <= surface)
and the force back near the tare (|e| <= thr).  The learning then starts again from nothing
(n = 0, S = 0): every insertion learns its own tare and finds its own surface.

A known surface (surface_mm finite, e.g. a robot registered to the tissue) replaces the
detection: CONTACT while x > surface_mm, AIR otherwise; the tare is learned in the air as above.

In predict-only mode (the bank's predict_only: the force is not read) nothing here looks at the
force: the tare and the noise are held, no contact is looked for (unless the surface is known),
and a contact ends when the stage is back at the surface, whatever the force.

Model III works in units of its sensor's own noise (unit(); sensor_units): with u =
max(1, NOISE_REF_N / sqrt(ms)), at most UNIT_MAX, the noise floor is r_n2 in units of u
(sigma = sqrt(max(ms u^2, r_n2)) / u) and the threshold's floor floor_n / u, and the bank takes
the force times u (FilterBank._scale_to_sensor): a sensor quieter than NOISE_REF_N is read as if
it were that noisy, where the defaults were chosen.  Models I and II: u = 1, as before.

Limits: a record must start in the air (what is learned first is the tare), contact is looked
for only while the stage moves inward, and a record whose stage never returns to the surface
stays in contact.

Everything is element-wise on a batch axis, like the bank.
"""
from __future__ import annotations

import math

import numpy as np

from .config import ContactConfig
from .fmath import Array, Real

#: published contact states (nte.h nte_contact_state_t)
CONTACT_AIR, CONTACT_TISSUE = 0, 1
#: the onset segment's sample count saturates here (no overflow in the C library's int32)
SEG_MAX = 1 << 30


#: Model III's front end and bank work in units of the sensor's own noise (unit()): where the
#: noise learned in the air is below NOISE_REF_N (N), the force is taken in units of that noise
#: times 1 / NOISE_REF_N.  The defaults (R = (2 mN)^2 and this front end's floors, z's noises,
#: the paper's starts) were chosen on sensors of 8-50 mN; on a quieter one R exceeded the noise
#: itself, the floors hid it, and the filters lagged (config_loop_figures.py --scaled).
NOISE_REF_N = 0.008
#: the largest unit: a sensor whose noise reads below NOISE_REF_N / UNIT_MAX (8 uN) is taken
#: as that quiet
UNIT_MAX = 1000.0


class ContactFrontEnd:
    """The front end for a batch of runs (see the module docstring)."""

    def __init__(self, R: Real, cfg: ContactConfig, r_n2: float, v_still_mm_s: float,
                 batch: int, sensor_units: bool = False) -> None:
        """``sensor_units`` (Model III): the floors work in the unit of the sensor's own noise
        (unit(); the module docstring)."""
        self.R, self.cfg, self.batch = R, cfg, batch
        self.sensor_units = sensor_units
        self.unit_ref = R.c(NOISE_REF_N)
        self.unit_floor = R.c(NOISE_REF_N / UNIT_MAX)
        self.known = math.isfinite(cfg.surface_mm)
        self.k_sigma = R.c(cfg.k_sigma)
        self.floor = R.c(cfg.floor_n)
        self.gate = R.c(cfg.learn_gate_sigma)
        self.drift = R.c(cfg.cusum_drift_sigma)
        self.r = R.c(r_n2)
        self.v_still = R.c(v_still_mm_s)
        self.surface_cfg = R.c(cfg.surface_mm)
        #: predict-only mode (set by the bank before each step): the force is not looked at
        self.predict_only = False
        self.reset()

    def reset(self) -> None:
        R, B = self.R, self.batch
        self.contact = np.zeros(B, dtype=bool)
        self.n = np.zeros(B, dtype=np.int64)      # samples learned since the last re-arm
        self.tare = R.full(B, 0.0)
        self.ms = R.full(B, 0.0)
        self.cusum = R.full(B, 0.0)
        self.run = np.zeros(B, dtype=np.int64)    # consecutive samples above the threshold
        self.seg_n = np.zeros(B, dtype=np.int64)  # the onset segment and its sums
        self.x0 = R.full(B, 0.0)
        self.sh = R.full(B, 0.0)
        self.se = R.full(B, 0.0)
        self.shh = R.full(B, 0.0)
        self.she = R.full(B, 0.0)
        self.surface = R.full(B, math.nan)        # NaN until a surface is found

    def unit(self) -> Array:
        """The force unit the bank works in, units per N: 1, or with ``sensor_units``
        NOISE_REF_N over the noise learned so far (its rms about the tare; held in contact),
        where that is below NOISE_REF_N, at most UNIT_MAX; 1 in predict-only mode and before
        any sample was learned."""
        R = self.R
        if not self.sensor_units or self.predict_only:
            return R.full(self.batch, 1.0)     # predict-only: no force read, no noise learned
        lo = self.unit_floor * self.unit_floor
        k = self.unit_ref / np.sqrt(np.where(self.ms > lo, self.ms, lo))
        # nothing learned yet (a record that starts in the tissue): unit 1
        return np.where((k > R.c(1.0)) & (self.n > 0), k, R.c(1.0))

    def noise_sigma(self, in_unit: bool = False) -> Array:
        """The force noise's standard deviation learned in the air (held in contact), N, or
        with ``in_unit`` in the bank's unit (unit()); never below the bank's sqrt(r_n2) in the
        bank's unit."""
        u = self.unit()
        ms = self.ms * (u * u)
        sigma = np.sqrt(np.where(ms > self.r, ms, self.r))
        return sigma if in_unit else sigma / u

    def _threshold(self, sigma: Array) -> Array:
        thr = self.k_sigma * sigma
        floor = self.floor / self.unit()
        return np.where(thr > floor, thr, floor)

    def step(self, mask: Array, x: Array, v: Array, f: Array) -> tuple[Array, Array]:
        """One sample where ``mask`` (elsewhere nothing changes): stage x mm, velocity v mm/s,
        force f N.  Returns the tissue depth (mm, >= 0) and the tare-free force (N)."""
        R, cfg = self.R, self.cfg
        zero = R.c(0.0)
        sigma = self.noise_sigma()
        thr = self._threshold(sigma)
        e = f - self.tare
        air = mask & ~self.contact
        po = bool(self.predict_only)
        if self.known:
            below = x > self.surface_cfg
            enter = air & below
            learn = air & ~below & (not po)
            leave = mask & self.contact & ~below
        else:
            # predict-only: nothing of the air branch runs (no learning, no detection)
            air = air & (not po)
            inward = v > self.v_still
            armed = self.n >= cfg.learn_samples
            # the onset segment: inward samples above the tare, up to this one
            pos = air & inward & (e > zero)
            start = pos & (self.seg_n == 0)
            self.x0 = np.where(start, x, self.x0)
            h = x - self.x0
            self.sh = np.where(start, zero, self.sh)
            self.se = np.where(start, zero, self.se)
            self.shh = np.where(start, zero, self.shh)
            self.she = np.where(start, zero, self.she)
            self.seg_n = np.where(pos, np.minimum(self.seg_n + 1, SEG_MAX),
                                  np.where(air, 0, self.seg_n))
            self.sh = np.where(pos, self.sh + h, self.sh)
            self.se = np.where(pos, self.se + e, self.se)
            self.shh = np.where(pos, self.shh + h * h, self.shh)
            self.she = np.where(pos, self.she + h * e, self.she)
            # learning pauses while the CUSUM (before this sample) is above the gate
            learn = air & ~(armed & (self.cusum > self.gate))
            s_new = (self.cusum + e / sigma) - self.drift
            s_new = np.where(s_new > zero, s_new, zero)
            self.cusum = np.where(air, np.where(armed, s_new, zero), self.cusum)
            above = armed & inward & (e > thr)
            self.run = np.where(air, np.where(above, self.run + 1, 0), self.run)
            enter = air & (self.run >= cfg.run_samples)
            leave = mask & self.contact & ~(x > self.surface) & ((np.abs(e) <= thr) | po)
        # learn the tare and the noise
        n_new = np.minimum(self.n + 1, cfg.tare_samples)
        self.n = np.where(learn, n_new, self.n)
        w = R.c(1.0) / n_new.astype(R.dtype)
        tare_new = self.tare + w * e
        ms_new = self.ms + w * (e * (f - tare_new) - self.ms)
        self.tare = np.where(learn, tare_new, self.tare)
        self.ms = np.where(learn, ms_new, self.ms)
        # contact begins: the surface
        if self.known:
            self.surface = np.where(enter, self.surface_cfg, self.surface)
        elif np.any(enter):
            self.surface = np.where(enter, self._extrapolate(x), self.surface)
        # contact ends: re-arm
        self.contact = (self.contact | enter) & ~leave
        for name in ("n", "run", "seg_n"):
            setattr(self, name, np.where(leave, 0, getattr(self, name)))
        self.cusum = np.where(leave, zero, self.cusum)
        depth = x - self.surface
        depth = np.where(self.contact & (depth > zero), depth, zero)
        return depth, f - self.tare

    def _extrapolate(self, x: Array) -> Array:
        """Where the line fitted to the onset segment crosses the tare (module docstring)."""
        R = self.R
        zero = R.c(0.0)
        with np.errstate(all="ignore"):
            nn = self.seg_n.astype(R.dtype)
            det = nn * self.shh - self.sh * self.sh
            b1 = (nn * self.she - self.sh * self.se) / det
            b0 = (self.se - b1 * self.sh) / nn
            s = self.x0 - b0 / b1
            lo = self.x0 - (x - self.x0)
            s = np.where(s < lo, lo, np.where(s > x, x, s))
            ok = (det > zero) & (b1 > zero) & np.isfinite(s)
            return np.where(ok, s, self.x0)

    def published(self) -> tuple[Array, Array, Array]:
        """surface_mm (NaN until found), tare_n, contact state (CONTACT_*)."""
        state = np.where(self.contact, np.uint32(CONTACT_TISSUE), np.uint32(CONTACT_AIR))
        return self.surface.copy(), self.tare.copy(), state
