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


def tissue_force(spec: PhantomSpec, t: Array, x: Array, cycle: Array
                 ) -> tuple[dict[str, Array], list[dict[str, Any]]]:
    """Noise-free tissue force and its components along the stage motion (one fresh site per
    cycle).  Sequential in time: the membranes, the Dahl state and the Maxwell branches are
    hereditary."""
    ti = spec.tissue
    layers = ti.layers
    nl = len(layers)
    tops = np.concatenate([[0.0], np.cumsum([ly.thickness_mm for ly in layers])])
    n = len(t)
    out = {k: np.zeros(n) for k in ("membrane", "cutting", "friction_pos", "friction_neg",
                                    "viscous", "dahl", "tip_depth_mm", "cut_depth_mm",
                                    "engagement_mm", "elastic_instant")}
    branch = np.zeros((len(ti.maxwell_tau_s), n))
    layer_idx = np.full(n, -1, dtype=np.int16)
    rupt_count = np.zeros(n, dtype=np.int16)
    ruptures: list[dict[str, Any]] = []
    beta = [float(b) for b in ti.maxwell_n_mm]
    tau = [float(x) for x in ti.maxwell_tau_s]
    nb = len(tau)
    mu = [ly.friction_n_mm for ly in layers]
    rvis = [ly.viscous for ly in layers]
    tops_l = [float(b) for b in tops]
    a_t, k_t = ti.tent_linear, ti.tent_curvature
    rho, dp, dc, tr_s, tip = (ti.retraction_ratio, ti.presliding_mm, ti.unload_mm, ti.rupture_s,
                              ti.tip_mm)
    n_exp, surf = ti.rate_exponent, spec.surface_mm
    o_mem, o_cut, o_vis = out["membrane"], out["cutting"], out["viscous"]
    o_s, o_d, o_c, o_w = out["dahl"], out["tip_depth_mm"], out["cut_depth_mm"], out["engagement_mm"]
    o_fp, o_fn, o_inst = out["friction_pos"], out["friction_neg"], out["elastic_instant"]
    tl, xl, cl = t.tolist(), x.tolist(), cycle.tolist()
    cur_cycle = -2
    s = 0.0
    sig = [0.0] * nb
    k = 0
    cut = 0.0
    released: list[tuple[float, float]] = []
    recoil: list[tuple[float, float]] = []
    n_rupt = 0
    d_prev = -math.inf
    dt_cached, decay = -1.0, [0.0] * nb
    origin = list(tops_l)
    g = [float(v) for v in ti.relax_g]
    g_inf = 1.0 - sum(g)
    tent_h = [0.0] * nb                     # relaxing parts of the intact membrane's tent force
    tent_prev = 0.0
    grip: list[list[float]] = []            # engaged shaft pieces, deepest last: [length, mu L, t]
    grip_h = [0.0] * nb                     # relaxing parts of the grip (sum of g_k mu L e^..)
    grip_w = 0.0                            # sum of mu L over the engaged pieces
    reach_prev = 0.0
    for i in range(n):
        ti_ = tl[i]
        if cl[i] != cur_cycle:              # a fresh site: intact membranes, nothing cut
            cur_cycle = int(cl[i])
            k, cut, released, recoil, n_rupt = 0, 0.0, [], [], 0
            origin = list(tops_l)
            tent_h, tent_prev = [0.0] * nb, 0.0
            grip, grip_h, grip_w, reach_prev = [], [0.0] * nb, 0.0, 0.0
        d = xl[i] - surf
        dt = ti_ - tl[i - 1] if i > 0 else 0.0
        if i > 0:
            if dt != dt_cached:
                dt_cached, decay = dt, [math.exp(-dt / tk) for tk in tau]
            for b in range(nb):
                tent_h[b] *= decay[b]
                grip_h[b] *= decay[b]
            dx = xl[i] - xl[i - 1]
            if dx != 0.0:
                sg = 1.0 if dx > 0 else -1.0
                s = sg + (s - sg) * math.exp(-abs(dx) / dp)
            vbar = dx / dt
            # the tissue shears only once the contact slides: during pre-sliding (s not yet
            # turned to the new direction) the Maxwell branches are not driven
            slide = max(s * (1.0 if vbar > 0 else -1.0), 0.0) if vbar != 0.0 else 0.0
            phi = math.copysign(abs(vbar) ** n_exp, vbar) * slide
            for b in range(nb):
                target = beta[b] * phi
                sig[b] = target + (sig[b] - target) * decay[b]
        # membranes and the cut front (only an advancing tip cuts or ruptures)
        while True:
            if k < nl and layers[k].rupture_n == 0.0 and d >= tops_l[k]:
                k += 1                          # a layer without membrane opens at its top
                continue
            limit = tops_l[k] if k < nl else math.inf
            if d > cut:
                cut = min(d, limit)
            if k < nl and d > origin[k] and d > d_prev:
                ly = layers[k]
                u = d - origin[k]
                if u >= ly.tent_mm:
                    u0 = max(d_prev - origin[k], 0.0)
                    frac = min(max((ly.tent_mm - u0) / (u - u0), 0.0), 1.0) if u > u0 else 1.0
                    tr = tl[i - 1] + frac * (ti_ - tl[i - 1]) if i > 0 else ti_
                    # the tent has relaxed while it was loaded: the force released is the
                    # relaxed one, and the torn membrane keeps no memory of its loading
                    f_rel = g_inf * ly.rupture_n + sum(
                        tent_h[b] + g[b] * (ly.rupture_n - tent_prev) for b in range(nb))
                    tent_h, tent_prev = [0.0] * nb, 0.0
                    released.append((tr, f_rel))
                    recoil.append((tr, max(min(d, tops_l[k + 1] if k + 1 < nl else math.inf)
                                           - max(cut, 0.0), 0.0)))
                    n_rupt += 1
                    ruptures.append({"cycle": cur_cycle, "layer": k, "name": ly.name,
                                     "time_s": float(tr),
                                     "tip_depth_mm": float(origin[k] + ly.tent_mm),
                                     "stage_mm": float(surf + origin[k] + ly.tent_mm),
                                     "rupture_n": float(ly.rupture_n)})
                    # the tip springs through; a deeper membrane it has already pushed past
                    # its rest position wraps the tip and tents from where the tip now is
                    for q in range(k + 1, nl):
                        origin[q] = max(origin[q], d)
                    k += 1
                    continue
            break
        # tip: membrane being tented, released ruptures, cutting at the front
        f_tent = 0.0
        if k < nl and d > origin[k]:
            ly = layers[k]
            f_tent = _tent(d - origin[k], ly.rupture_n, ly.tent_mm, a_t, k_t)
        for b in range(nb):                 # quasi-linear viscoelastic tent (same tau_k)
            tent_h[b] += g[b] * (f_tent - tent_prev)
        tent_prev = f_tent
        f_inst = f_tent
        f_mem = max(g_inf * f_tent + sum(tent_h), 0.0)   # an unloaded tent loses contact
        pending = 0.0                           # cut length the recoiling tissue has not yet gripped
        if released:
            for (tr, R) in released:
                if ti_ >= tr:
                    f_mem += R * math.exp(-(ti_ - tr) / tr_s)
                    f_inst += R * math.exp(-(ti_ - tr) / tr_s)
            for (tr, ln) in recoil:
                pending += ln * math.exp(-max(ti_ - tr, 0.0) / tr_s)
            if ti_ - released[-1][0] > 40.0 * tr_s:
                released, recoil = [], []
        j = k - 1                               # layer of the cut front
        while j >= 0 and tops_l[j] > cut:
            j -= 1
        f_cut = 0.0
        if d > 0.0 and j >= 0 and cut > 0.0:
            c_j = layers[j].cutting_n
            if j > 0 and layers[j].rupture_n == 0.0:
                # no membrane between the layers: the tip's cutting force changes over the
                # first blend_mm of the new layer (a cut front is not a point)
                c_j = layers[j - 1].cutting_n + (c_j - layers[j - 1].cutting_n) * \
                    min((cut - tops_l[j]) / _BLEND_MM, 1.0)
            # the load builds over the first delta_c of tissue (contact), unloads over delta_c
            # when the tip backs away from the front
            f_cut = c_j * min(max(1.0 - (cut - d) / dc, 0.0), 1.0, cut / dc)
        # shaft inside the cut layers
        reach = max(min(max(d, 0.0), cut) - pending, 0.0)
        fmu = 0.0
        w = min(max(d, 0.0), tip)              # tissue engaged around the tip
        for q in range(nl):
            if reach <= tops_l[q]:
                break
            Lq = min(reach, tops_l[q + 1]) - tops_l[q]
            fmu += mu[q] * Lq
            w += rvis[q] * Lq
        # the grip of each engaged piece of shaft relaxes from the time it was engaged; a
        # withdrawn piece takes its own (least relaxed, deepest) grip with it
        if reach > reach_prev:
            piece = fmu - grip_w
            t_mid = ti_ - 0.5 * dt
            grip.append([reach - reach_prev, piece, t_mid])
            grip_w = fmu
            for b in range(nb):
                grip_h[b] += g[b] * piece * math.exp(-(ti_ - t_mid) / tau[b])
        elif reach < reach_prev:
            gone = reach_prev - reach
            while grip and gone > 0.0:
                top = grip[-1]
                share = min(gone / top[0], 1.0) if top[0] > 0.0 else 1.0
                wq = top[1] * share
                for b in range(nb):
                    grip_h[b] -= g[b] * wq * math.exp(-(ti_ - top[2]) / tau[b])
                if share >= 1.0:
                    gone -= top[0]
                    grip.pop()
                else:                           # part of this piece: nothing more goes
                    top[0] -= gone
                    top[1] -= wq
                    gone = 0.0
            if not grip:
                grip_h = [0.0] * nb
            grip_w = fmu if grip else 0.0
        reach_prev = reach
        f_grip = max(g_inf * grip_w + sum(grip_h), 0.0) if grip else 0.0
        o_mem[i] = f_mem
        o_cut[i] = f_cut
        o_inst[i] = f_inst + f_cut + fmu * (s if s >= 0.0 else rho * s)
        o_fp[i] = f_grip * max(s, 0.0)
        o_fn[i] = f_grip * rho * min(s, 0.0)
        sv = 0.0
        for b in range(nb):
            branch[b, i] = w * sig[b]
            sv += sig[b]
        o_vis[i] = w * sv
        o_s[i] = s
        o_d[i] = d
        o_c[i] = cut
        o_w[i] = w
        layer_idx[i] = j if d > 0.0 else -1
        rupt_count[i] = n_rupt
        d_prev = d
    # the cutting load relaxes through the hereditary integral with the same time constants;
    # the tip cannot pull on the tissue ahead of it, so the load ends at 0 once contact is lost
    out["cutting"] = np.maximum(_relax(t, out["cutting"], g, tau), 0.0)
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
