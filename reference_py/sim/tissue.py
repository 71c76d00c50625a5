"""The realistic phantom's tissue force: multi-layer tissue, relaxation, pre-sliding.

Everything is physical state driven by the stage motion (no curve patches):

* stage      :func:`reference_py.sim.motion.stage_motion`'s LSPB cycles; each cycle enters a
             fresh site of the tissue (a :class:`reference_py.sim.spec.Tissue`).
* membrane   the intact membrane at the top of layer i is pushed u = d - b_i mm past its rest
             position (d tip depth below the undeformed surface, b_i the layer's top):
             F_m = R_i [a u/u_i + (1-a) (exp(k u/u_i) - 1)/(exp(k) - 1)], a stiffening tent that
             reaches the rupture force R_i at u = u_i; it then ruptures and its force is released
             as R_i exp(-(t - t_r)/tau_r).
* cutting    while the tip advances through an opened layer j it carries the cutting force C_j;
             it unloads linearly over delta_c mm when the tip backs away from the cut front.
* friction   Coulomb friction per length of shaft inside each cut layer, mu_j L_j, times the
             Dahl direction state s (ds/dx = (sign(dx) - s)/delta_p over stage travel x): it holds
             in a dwell and turns over across a few mm after a reversal; retraction friction is
             rho times insertion friction.
* relaxation a generalized Maxwell (Prony) element of the engaged tissue: branch k has the
             stress sigma_k(t) = int_0^t (beta_k/tau_k) exp(-(t-s)/tau_k) phi(v(s)) ds, with
             phi = sign(v)|v/(1 mm/s)|^n max(0, s sign(v)) (the tissue shears only once the
             contact slides), and the force w(t) sum_k sigma_k, where the engagement
             w = min(d, ell_tip) + sum_j r_j L_j (mm) grows with depth.  In steady sliding it is a
             velocity-dependent friction beta_k phi(v) w; in a dwell it decays with tau_1 (fast)
             and tau_2 (slow).
* elastic    the tent, cutting and grip forces relax with the same time constants (quasi-linear
             viscoelastic: int G(t - s) dE(s), G = g_inf + sum_k g_k exp(-t/tau_k)); a torn
             membrane releases its relaxed force and keeps no memory, the cutting force stays
             >= 0 when the tip backs away, and the grip relaxes per engaged piece of shaft (a
             withdrawn piece takes its own grip away).

The code follows the list: :class:`_Sliding` holds what outlives a cycle (the Dahl state and
the Maxwell branches); :class:`_Site` one site's membranes (``advance``, ``membrane``), cutting
(``cutting``) and shaft (``shaft``, ``grip_force``); :func:`tissue_force` steps them sample by
sample, in that order, and records the components.

Units: mm, s, N throughout.  The sensor that records this force is
:mod:`reference_py.sim.phantom`'s.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np
from scipy.signal import lfilter

from ..fmath import Array
from .spec import PhantomSpec

_BLEND_MM = 3.0       # cutting-force transition into a layer that has no membrane, mm


def _tent(u: float, R: float, ur: float, a: float, k: float) -> float:
    if u <= 0.0:
        return 0.0
    return R * (a * u / ur + (1.0 - a) * math.expm1(k * u / ur) / math.expm1(k))


class _Numbers:
    """The tissue's numbers as plain floats and lists, read once from the spec (the loop below
    runs per sample in pure Python, where attribute chains and numpy scalars cost time)."""

    def __init__(self, spec: PhantomSpec) -> None:
        ti = spec.tissue
        self.layers = ti.layers
        self.nl = len(ti.layers)
        self.tops = [float(b) for b in
                     np.concatenate([[0.0], np.cumsum([ly.thickness_mm for ly in ti.layers])])]
        self.beta = [float(b) for b in ti.maxwell_n_mm]
        self.tau = [float(x) for x in ti.maxwell_tau_s]
        self.nb = len(self.tau)
        self.mu = [ly.friction_n_mm for ly in ti.layers]
        self.rvis = [ly.viscous for ly in ti.layers]
        self.a_t, self.k_t = ti.tent_linear, ti.tent_curvature
        self.rho, self.dp, self.dc = ti.retraction_ratio, ti.presliding_mm, ti.unload_mm
        self.tr_s, self.tip = ti.rupture_s, ti.tip_mm
        self.n_exp, self.surf = ti.rate_exponent, spec.surface_mm
        self.g = [float(v) for v in ti.relax_g]
        self.g_inf = 1.0 - sum(self.g)


class _Sliding:
    """The sliding contact's hereditary state, which a new cycle does not reset: the Dahl
    direction state s and the Maxwell branches' stresses sigma_k."""

    def __init__(self, p: _Numbers) -> None:
        self.p = p
        self.s = 0.0
        self.sig = [0.0] * p.nb
        self.dt_cached, self.decay = -1.0, [0.0] * p.nb

    def step(self, dt: float, dx: float) -> list[float]:
        """Advance by dt s and a stage travel dx mm; returns exp(-dt/tau_k), which the site's
        relaxing forces share (computed again only when the step changes)."""
        p = self.p
        if dt != self.dt_cached:
            self.dt_cached, self.decay = dt, [math.exp(-dt / tk) for tk in p.tau]
        if dx != 0.0:
            sg = 1.0 if dx > 0 else -1.0
            self.s = sg + (self.s - sg) * math.exp(-abs(dx) / p.dp)
        vbar = dx / dt
        # the tissue shears only once the contact slides: during pre-sliding (s not yet
        # turned to the new direction) the Maxwell branches are not driven
        slide = max(self.s * (1.0 if vbar > 0 else -1.0), 0.0) if vbar != 0.0 else 0.0
        phi = math.copysign(abs(vbar) ** p.n_exp, vbar) * slide
        for b in range(p.nb):
            target = p.beta[b] * phi
            self.sig[b] = target + (self.sig[b] - target) * self.decay[b]
        return self.decay


class _Site:
    """One fresh site of the tissue (one cycle): its membranes (the next intact one k, their
    rest positions), the cut front, the ruptures still releasing, and the grip of the engaged
    shaft; the tent and grip forces relax with the Maxwell time constants (QLV)."""

    def __init__(self, p: _Numbers) -> None:
        self.p = p
        self.k, self.cut, self.n_rupt = 0, 0.0, 0
        self.released: list[tuple[float, float]] = []
        self.recoil: list[tuple[float, float]] = []
        self.origin = list(p.tops)
        self.tent_h = [0.0] * p.nb              # relaxing parts of the intact membrane's tent
        self.tent_prev = 0.0
        self.grip: list[list[float]] = []       # engaged shaft pieces, deepest last: [length, mu L, t]
        self.grip_h = [0.0] * p.nb              # relaxing parts of the grip (sum of g_k mu L e^..)
        self.grip_w = 0.0                       # sum of mu L over the engaged pieces
        self.reach_prev = 0.0

    def relax(self, decay: Sequence[float]) -> None:
        for b in range(self.p.nb):
            self.tent_h[b] *= decay[b]
            self.grip_h[b] *= decay[b]

    def advance(self, d: float, d_prev: float, t_prev: float | None, t_now: float,
                cycle: int) -> list[dict[str, Any]]:
        """Membranes and the cut front at tip depth d (only an advancing tip cuts or
        ruptures); returns the ruptures of this step."""
        p = self.p
        events = []
        while True:
            k = self.k
            if k < p.nl and p.layers[k].rupture_n == 0.0 and d >= p.tops[k]:
                self.k += 1                     # a layer without membrane opens at its top
                continue
            limit = p.tops[k] if k < p.nl else math.inf
            if d > self.cut:
                self.cut = min(d, limit)
            if k < p.nl and d > self.origin[k] and d > d_prev and \
                    d - self.origin[k] >= p.layers[k].tent_mm:
                events.append(self._rupture(d, d_prev, t_prev, t_now, cycle))
                continue
            break
        return events

    def _rupture(self, d: float, d_prev: float, t_prev: float | None, t_now: float,
                 cycle: int) -> dict[str, Any]:
        """Membrane k tears (the tip has pushed it tent_mm past its rest position)."""
        p, k = self.p, self.k
        ly, o = p.layers[k], self.origin[k]
        u = d - o
        u0 = max(d_prev - o, 0.0)
        frac = min(max((ly.tent_mm - u0) / (u - u0), 0.0), 1.0) if u > u0 else 1.0
        tr = t_prev + frac * (t_now - t_prev) if t_prev is not None else t_now
        # the tent has relaxed while it was loaded: the force released is the relaxed one, and
        # the torn membrane keeps no memory of its loading
        f_rel = p.g_inf * ly.rupture_n + sum(
            self.tent_h[b] + p.g[b] * (ly.rupture_n - self.tent_prev) for b in range(p.nb))
        self.tent_h, self.tent_prev = [0.0] * p.nb, 0.0
        self.released.append((tr, f_rel))
        self.recoil.append((tr, max(min(d, p.tops[k + 1] if k + 1 < p.nl else math.inf)
                                    - max(self.cut, 0.0), 0.0)))
        self.n_rupt += 1
        # the tip springs through; a deeper membrane it has already pushed past its rest
        # position wraps the tip and tents from where the tip now is
        for q in range(k + 1, p.nl):
            self.origin[q] = max(self.origin[q], d)
        self.k += 1
        return {"cycle": cycle, "layer": k, "name": ly.name, "time_s": float(tr),
                "tip_depth_mm": float(o + ly.tent_mm), "stage_mm": float(p.surf + o + ly.tent_mm),
                "rupture_n": float(ly.rupture_n)}

    def membrane(self, d: float, t_now: float) -> tuple[float, float, float]:
        """(relaxed membrane force, its instantaneous value, N; the cut length, mm, the tissue
        recoiling after a rupture has not yet gripped): the intact membrane's tent and the
        releasing ruptures."""
        p, k = self.p, self.k
        f_tent = 0.0
        if k < p.nl and d > self.origin[k]:
            ly = p.layers[k]
            f_tent = _tent(d - self.origin[k], ly.rupture_n, ly.tent_mm, p.a_t, p.k_t)
        for b in range(p.nb):                   # quasi-linear viscoelastic tent (same tau_k)
            self.tent_h[b] += p.g[b] * (f_tent - self.tent_prev)
        self.tent_prev = f_tent
        f_inst = f_tent
        f_mem = max(p.g_inf * f_tent + sum(self.tent_h), 0.0)   # an unloaded tent loses contact
        pending = 0.0
        if self.released:
            for (tr, R) in self.released:
                if t_now >= tr:
                    f_mem += R * math.exp(-(t_now - tr) / p.tr_s)
                    f_inst += R * math.exp(-(t_now - tr) / p.tr_s)
            for (tr, ln) in self.recoil:
                pending += ln * math.exp(-max(t_now - tr, 0.0) / p.tr_s)
            if t_now - self.released[-1][0] > 40.0 * p.tr_s:
                self.released, self.recoil = [], []
        return f_mem, f_inst, pending

    def cutting(self, d: float) -> tuple[int, float]:
        """(the layer of the cut front, -1 above the first; the cutting force at the tip, N)."""
        p, cut = self.p, self.cut
        j = self.k - 1
        while j >= 0 and p.tops[j] > cut:
            j -= 1
        f_cut = 0.0
        if d > 0.0 and j >= 0 and cut > 0.0:
            c_j = p.layers[j].cutting_n
            if j > 0 and p.layers[j].rupture_n == 0.0:
                # no membrane between the layers: the tip's cutting force changes over the
                # first blend_mm of the new layer (a cut front is not a point)
                c_j = p.layers[j - 1].cutting_n + (c_j - p.layers[j - 1].cutting_n) * \
                    min((cut - p.tops[j]) / _BLEND_MM, 1.0)
            # the load builds over the first delta_c of tissue (contact), unloads over delta_c
            # when the tip backs away from the front
            f_cut = c_j * min(max(1.0 - (cut - d) / p.dc, 0.0), 1.0, cut / p.dc)
        return j, f_cut

    def shaft(self, d: float, pending: float) -> tuple[float, float, float]:
        """(shaft length inside the cut layers, mm; its Coulomb friction sum mu_j L_j, N; the
        Maxwell engagement w, mm)."""
        p = self.p
        reach = max(min(max(d, 0.0), self.cut) - pending, 0.0)
        fmu = 0.0
        w = min(max(d, 0.0), p.tip)             # tissue engaged around the tip
        for q in range(p.nl):
            if reach <= p.tops[q]:
                break
            Lq = min(reach, p.tops[q + 1]) - p.tops[q]
            fmu += p.mu[q] * Lq
            w += p.rvis[q] * Lq
        return reach, fmu, w

    def grip_force(self, reach: float, fmu: float, t_now: float, dt: float) -> float:
        """The relaxed friction grip, N, with the shaft reaching `reach` mm (friction fmu):
        the grip of each engaged piece of shaft relaxes from the time it was engaged."""
        p = self.p
        if reach > self.reach_prev:
            piece = fmu - self.grip_w
            t_mid = t_now - 0.5 * dt
            self.grip.append([reach - self.reach_prev, piece, t_mid])
            self.grip_w = fmu
            for b in range(p.nb):
                self.grip_h[b] += p.g[b] * piece * math.exp(-(t_now - t_mid) / p.tau[b])
        elif reach < self.reach_prev:
            self._withdraw(self.reach_prev - reach, fmu, t_now)
        self.reach_prev = reach
        return max(p.g_inf * self.grip_w + sum(self.grip_h), 0.0) if self.grip else 0.0

    def _withdraw(self, gone: float, fmu: float, t_now: float) -> None:
        """A withdrawn length `gone` of shaft takes its own (least relaxed, deepest) grip."""
        p, grip = self.p, self.grip
        while grip and gone > 0.0:
            top = grip[-1]
            share = min(gone / top[0], 1.0) if top[0] > 0.0 else 1.0
            wq = top[1] * share
            for b in range(p.nb):
                self.grip_h[b] -= p.g[b] * wq * math.exp(-(t_now - top[2]) / p.tau[b])
            if share >= 1.0:
                gone -= top[0]
                grip.pop()
            else:                               # part of this piece: nothing more goes
                top[0] -= gone
                top[1] -= wq
                gone = 0.0
        if not grip:
            self.grip_h = [0.0] * p.nb
        self.grip_w = fmu if grip else 0.0


def tissue_force(spec: PhantomSpec, t: Array, x: Array, cycle: Array
                 ) -> tuple[dict[str, Array], list[dict[str, Any]]]:
    """Noise-free tissue force and its components along the stage motion (one fresh site per
    cycle).  Sequential in time: the membranes, the Dahl state and the Maxwell branches are
    hereditary."""
    p = _Numbers(spec)
    n = len(t)
    out = {k: np.zeros(n) for k in ("membrane", "cutting", "friction_pos", "friction_neg",
                                    "viscous", "dahl", "tip_depth_mm", "cut_depth_mm",
                                    "engagement_mm", "elastic_instant")}
    branch = np.zeros((p.nb, n))
    layer_idx = np.full(n, -1, dtype=np.int16)
    rupt_count = np.zeros(n, dtype=np.int16)
    ruptures: list[dict[str, Any]] = []
    o_mem, o_cut, o_vis = out["membrane"], out["cutting"], out["viscous"]
    o_s, o_d, o_c, o_w = out["dahl"], out["tip_depth_mm"], out["cut_depth_mm"], out["engagement_mm"]
    o_fp, o_fn, o_inst = out["friction_pos"], out["friction_neg"], out["elastic_instant"]
    tl, xl, cl = t.tolist(), x.tolist(), cycle.tolist()
    sliding, site = _Sliding(p), _Site(p)
    cur_cycle = -2
    d_prev = -math.inf
    for i in range(n):
        ti_ = tl[i]
        if cl[i] != cur_cycle:              # a fresh site: intact membranes, nothing cut
            cur_cycle = int(cl[i])
            site = _Site(p)
        d = xl[i] - p.surf
        dt = ti_ - tl[i - 1] if i > 0 else 0.0
        if i > 0:
            site.relax(sliding.step(dt, xl[i] - xl[i - 1]))
        ruptures += site.advance(d, d_prev, tl[i - 1] if i > 0 else None, ti_, cur_cycle)
        f_mem, f_inst, pending = site.membrane(d, ti_)
        j, f_cut = site.cutting(d)
        reach, fmu, w = site.shaft(d, pending)
        f_grip = site.grip_force(reach, fmu, ti_, dt)
        s, sig = sliding.s, sliding.sig
        o_mem[i] = f_mem
        o_cut[i] = f_cut
        o_inst[i] = f_inst + f_cut + fmu * (s if s >= 0.0 else p.rho * s)
        o_fp[i] = f_grip * max(s, 0.0)
        o_fn[i] = f_grip * p.rho * min(s, 0.0)
        sv = 0.0
        for b in range(p.nb):
            branch[b, i] = w * sig[b]
            sv += sig[b]
        o_vis[i] = w * sv
        o_s[i] = s
        o_d[i] = d
        o_c[i] = site.cut
        o_w[i] = w
        layer_idx[i] = j if d > 0.0 else -1
        rupt_count[i] = site.n_rupt
        d_prev = d
    # the cutting load relaxes through the hereditary integral with the same time constants;
    # the tip cannot pull on the tissue ahead of it, so the load ends at 0 once contact is lost
    out["cutting"] = np.maximum(_relax(t, out["cutting"], p.g, p.tau), 0.0)
    out["friction"] = out["friction_pos"] + out["friction_neg"]
    out["total"] = out["membrane"] + out["cutting"] + out["friction"] + out["viscous"]
    for b in range(branch.shape[0]):
        out[f"viscous_branch{b + 1}"] = branch[b]
    out["layer"] = layer_idx
    out["ruptures_so_far"] = rupt_count
    return out, ruptures


def _relax(t: Array, e: Array, g: Sequence[float], tau: Sequence[float]) -> Array:
    """Hereditary integral int G(t - s) de(s), G = g_inf + sum_k g_k exp(-t/tau_k),
    g_inf = 1 - sum g_k, exact for e linear between samples."""
    n = len(t)
    out = (1.0 - float(sum(g))) * e
    if n < 2:
        return out
    dt = np.diff(t)
    de = np.diff(e)
    for gk, tk in zip(g, tau):
        if gk == 0.0:
            continue
        a = np.exp(-dt / tk)
        c = gk * de * (tk / dt) * (1.0 - a)
        h = np.zeros(n)
        if np.ptp(a) <= 1e-12:                    # uniform steps: one linear filter
            h[1:] = lfilter([1.0], [1.0, -float(a[0])], c)
        else:
            hk, al, cl = 0.0, a.tolist(), c.tolist()
            for i in range(n - 1):
                hk = al[i] * hk + cl[i]
                h[i + 1] = hk
        out = out + h
    return out
