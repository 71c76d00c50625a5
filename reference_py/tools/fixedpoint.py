"""Fixed-point readiness of the bank: the range of every variable and the Q-format that holds it.

The bank runs (float64, every filter every sample) over two sets of scenarios and every value
each variable takes is recorded:

* paper: the five presets along their paper trajectory (LSPB to 50 mm at the preset's speed, 1 s
  dwell, back out, 200 Hz, 2 mN noise), started at the preset and within a factor 5 of it;
* random plausible: a preset's parameters each scaled by a log-uniform factor in [1/2, 2] (g(l)
  kept positive), speed log-uniform in 0.4-10 mm/s, depth 10-60 mm (at most 6 s of travel,
  at least 5 mm), dwell 0-3 s, 100-200 Hz, noise 1-5 mN, started within a factor 5 of the truth.

Variables: the inputs (depth, velocity, force, dt), the state z and the log-parameters u, the
physical parameters theta, the model's intermediates (exp(-alpha l), g, 1/g, b = sigma0/g,
m = beta - b z, fr, s l, the predicted force h), the RK3 transition (dz/dz0, dz/du), each
filter's predicted and updated covariance entries, its measurement row H, gain K, innovation,
innovation variance S and NIS.

Q-format.  A signed 32-bit word holding x * 2^F represents |x| < 2^I with I = 31 - F.  I is the
smallest integer with max|x| < 2^I (negative for small variables: Q-4.35 holds |x| < 1/16).
The variable fits 32 bits when that format still resolves its small values: its 1st percentile
of the non-zero |x| (exact zeros are representable) keeps at least SIG significant bits
(``--sig-bits``, default 12), i.e. I + SIG - floor(log2(p1)) <= 31.  Values below the 1st
percentile (crossings through zero) are not counted against the format.

Log-parameters (log_parameter_format).  theta = nominal e^u, so an error in u is theta's
relative error: u is judged by its format's step (at most 2^-SIG), not by its small values.

Scaled forms (SCALED_FORMS).  sigma0's and f1's sensitivities (the transition's dz/du and the
measurement row's H[u]) carry the factor z: at the surface, where z starts from 0, their small
values are z's.  They are recorded again over z as well; a variable whose scaled form fits is
reported as held in that form (times z, whose own format resolves it) instead of as a misfit.
"""
from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..bank import FilterBank
from ..config import profile_config
from ..ekf import Matrix
from ..fmath import F64, Array
from ..model import DepthTerms, output, output_du, output_dz
from ..params import PARAM_NAMES, PRESETS, ParamSet
from ..rk3 import Rk3Result
from ..starts import start_values
from ..sim.simulate import simulate_force
from ..sim.trajectory import TrajectorySpec, lspb_profile

#: log2 histogram bins: |x| in [2^(e-1), 2^e) goes to bin e + EXP_OFFSET (frexp's exponent)
EXP_OFFSET = 1100
EXP_BINS = 2 * EXP_OFFSET
WORD_BITS = 32


@dataclass
class Range:
    """Running range of one variable: min, max, and a log2 histogram of its non-zero |x|."""

    lo: float = math.inf
    hi: float = -math.inf
    count: int = 0
    zeros: int = 0
    hist: Array = field(default_factory=lambda: np.zeros(EXP_BINS, dtype=np.int64))

    def add(self, x: Array) -> None:
        x = np.asarray(x, dtype=np.float64).ravel()
        if x.size == 0:
            return
        if not np.all(np.isfinite(x)):
            raise ValueError("a bank variable went non-finite")
        self.lo = min(self.lo, float(x.min()))
        self.hi = max(self.hi, float(x.max()))
        self.count += x.size
        nz = x[x != 0.0]
        self.zeros += x.size - nz.size
        if nz.size:
            _, e = np.frexp(np.abs(nz))
            self.hist += np.bincount(e + EXP_OFFSET, minlength=EXP_BINS)

    def max_abs(self) -> float:
        return max(abs(self.lo), abs(self.hi))

    def small(self, q: float = 0.01) -> float:
        """Lower edge of the log2 bin holding the q-quantile of the non-zero |x| (0 if none)."""
        n = int(self.hist.sum())
        if n == 0:
            return 0.0
        k = int(np.searchsorted(np.cumsum(self.hist), max(1, math.ceil(q * n))))
        return math.ldexp(0.5, k - EXP_OFFSET)


def q_format(r: Range, sig_bits: int) -> tuple[int, int, bool]:
    """(I, F, fits): the signed 32-bit format Q<I>.<F> (I + F = 31) holding max|x|, and whether
    it keeps ``sig_bits`` significant bits at the variable's small values."""
    m = r.max_abs()
    if m == 0.0:
        return 0, WORD_BITS - 1, True
    _, e = math.frexp(m)            # m in [2^(e-1), 2^e)
    I = e
    F = WORD_BITS - 1 - I
    small = r.small()
    if small == 0.0:
        return I, F, True
    _, es = math.frexp(small)       # small = 2^(es-1) exactly (a bin edge)
    need_f = sig_bits - (es - 1)    # lsb 2^-need_f <= small * 2^-sig_bits
    return I, F, need_f <= F


class RecordingBank(FilterBank):
    """The bank, unchanged, with every intermediate of an active filter recorded."""

    def __init__(self, *args: object, ranges: dict[str, Range], **kw: object) -> None:
        self.ranges = ranges
        self._pending: dict[str, Array] = {}
        super().__init__(*args, **kw)  # type: ignore[arg-type]

    def _put(self, name: str, x: Array, mask: Array) -> None:
        x = np.broadcast_to(np.asarray(x, dtype=np.float64), mask.shape)
        self.ranges.setdefault(name, Range()).add(x[mask])

    def _predict(self, i: int, names: tuple[str, ...], pred: Rk3Result, d: DepthTerms,
                 restart: Array, surface: Array) -> tuple[list[Array], Matrix, Array]:
        x, P_pred, z_ss = super()._predict(i, names, pred, d, restart, surface)
        p = self._pending
        p.clear()
        p["rk3 dz/dz0"] = pred.dz_dz0
        for nm in names:
            p[f"rk3 dz/du.{nm}"] = pred.dz_du[nm]
        p["e = exp(-alpha l)"], p["g"], p["1/g"], p["b = sigma0/g"] = d.e, d.g, d.inv_g, d.b
        labels = ["z"] + list(names)
        for a in range(len(labels)):
            for b in range(a, len(labels)):
                p[f"P{i + 1} predicted [{labels[a]},{labels[b]}]"] = P_pred[a][b]
        return x, P_pred, z_ss

    def _measure(self, names: tuple[str, ...], d: DepthTerms, zp: Array, s: Array,
                 s_du: Array | None, v: Array, y: Array, active: Array
                 ) -> tuple[Array, list[Array], Array, Array, Array]:
        res = super()._measure(names, d, zp, s, s_du, v, y, active)
        o = output(self.th, d, zp, s)
        p = self._pending
        p["z prior"] = zp
        p["m = beta - b z"], p["fr = sigma1 e m + sigma2"], p["s l"], p["h (force)"] = (
            o.m, o.fr, o.sl, o.h)
        p["H[z]"] = output_dz(self.th, d, o)
        for nm in names:
            p[f"H[u.{nm}]"] = output_du(self.th, d, zp, o, nm)
        # the scaled forms (SCALED_FORMS): a sensitivity over the prior z, 0 where z is 0 (the
        # sensitivity is 0 there too: the factor b z / g is)
        nonzero = zp != 0.0
        safe_z = np.where(nonzero, zp, 1.0)
        for raw, scaled in SCALED_FORMS.items():
            if raw in p:
                p[scaled] = np.where(nonzero, p[raw] / safe_z, 0.0)
        return res

    def _update_and_guard(self, i: int, names: tuple[str, ...], x: list[Array], P_pred: Matrix,
                          hrow: list[Array], innovation: Array, r_eff: Array, active: Array,
                          run: Array, in_range: Array, z_ss: Array, tear: Array | None = None
                          ) -> tuple[Array, Array, Array]:
        n = len(x)
        pht = [sum((P_pred[a][b] * hrow[b] for b in range(1, n)), P_pred[a][0] * hrow[0])
               for a in range(n)]
        s = sum((hrow[a] * pht[a] for a in range(1, n)), hrow[0] * pht[0]) + r_eff
        z_i, nis, st = super()._update_and_guard(i, names, x, P_pred, hrow, innovation, r_eff,
                                                 active, run, in_range, z_ss, tear)
        labels = ["z"] + list(names)
        for name, val in self._pending.items():
            self._put(name, val, active)
        for a in range(n):
            self._put(f"K{i + 1}[{labels[a]}]", pht[a] / s, active)
            for b in range(a, n):
                self._put(f"P{i + 1} updated [{labels[a]},{labels[b]}]", self.P[i][a][b], active)
        self._put(f"innovation{i + 1}", innovation, active)
        self._put(f"S{i + 1} = H P H' + R", s, active)
        # the gate's two sides (ekf.joseph_update decides y^2 <= gate2 S, no division)
        self._put(f"gate{i + 1} y^2", innovation * innovation, active)
        self._put(f"gate{i + 1} gate^2 S", self.c.gate2 * s, active)
        self._put(f"NIS{i + 1}", nis, active)
        self._put("z", z_i, active)
        for nm in names:
            j = PARAM_NAMES.index(nm)
            self._put(f"u.{nm}", self.u[j], active)
            self._put(f"theta.{nm}", getattr(self.th, nm), active)
        return z_i, nis, st


@dataclass(frozen=True)
class Scenario:
    label: str
    truths: list[ParamSet]           # one per batch element
    starts: list[list[float]]
    spec: TrajectorySpec
    noise_n: float
    noise_seed: int


def paper_scenarios(model: int, seeds: int, spec: TrajectorySpec | None = None
                    ) -> list[Scenario]:
    """The presets on their paper trajectory, started at the preset and within a factor 5."""
    out = []
    for name, p in PRESETS.items():
        sp = replace(spec or TrajectorySpec(), speed_mm_s=p.speed_mm_s)
        truth = p.params
        starts = [truth.as_list()] + [start_values(truth.as_list(), s, 5.0, model)
                                      for s in range(1, seeds + 1)]
        out.append(Scenario(f"paper {name}", [truth] * len(starts), starts, sp, 2e-3, 1))
    return out


def random_scenarios(model: int, count: int, seeds: int, seed: int = 1) -> list[Scenario]:
    """Plausible tissues and trajectories around the presets (module docstring)."""
    rng = np.random.default_rng(seed)
    names = list(PRESETS)
    out = []
    for r in range(count):
        base = PRESETS[names[int(rng.integers(len(names)))]].params
        truths = []
        while len(truths) < seeds:
            f = np.exp(rng.uniform(-math.log(2.0), math.log(2.0), len(PARAM_NAMES)))
            cand = ParamSet(*(v * float(k) for v, k in zip(base.as_list(), f)))
            if cand.g_min() > 0.0:
                truths.append(cand)
        # clinical speeds; the move lasts at most 6 s so that slow runs stay short
        speed = float(np.exp(rng.uniform(math.log(0.4), math.log(10.0))))
        depth = min(float(rng.uniform(10.0, 60.0)), max(5.0, 6.0 * speed))
        spec = TrajectorySpec(depth_mm=depth, speed_mm_s=speed,
                              dwell_s=float(rng.uniform(0.0, 3.0)),
                              rate_hz=float(rng.choice([100.0, 125.0, 200.0])))
        starts = [start_values(t.as_list(), 100 * r + b + 1, 5.0, model)
                  for b, t in enumerate(truths)]
        out.append(Scenario(f"random {r + 1}", truths, starts, spec,
                            float(rng.uniform(1e-3, 5e-3)), 1000 + r))
    return out


def run_scenario(sc: Scenario, model: int, ranges: dict[str, Range]) -> None:
    t, l, v, _ = lspb_profile(sc.spec)
    f_true, _ = simulate_force(sc.truths if len(set(sc.truths)) > 1 else [sc.truths[0]], t, l, v)
    B = len(sc.starts)
    noise = np.random.default_rng(sc.noise_seed).normal(0.0, sc.noise_n, (B, len(t)))
    force = np.broadcast_to(f_true, (B, len(t))) + noise
    cfg = replace(profile_config("default", model), beta0=sc.truths[0].beta)
    bank = RecordingBank(F64, cfg, sc.starts, ranges=ranges)
    t_us = np.floor(t * 1e6 + 0.5).astype(np.int64)
    for name, x in (("input depth_mm", l), ("input velocity_mm_s", v),
                    ("input dt_s", np.diff(t))):
        ranges.setdefault(name, Range()).add(x)
    ranges.setdefault("input force_n", Range()).add(force)
    for k in range(len(t)):
        bank.step(np.full(B, t_us[k]), np.full(B, l[k]), np.full(B, v[k]), force[:, k])


def collect(model: int, scenarios: list[Scenario]) -> dict[str, Range]:
    ranges: dict[str, Range] = {}
    for sc in scenarios:
        run_scenario(sc, model, ranges)
    return ranges


def gate_format(y2: Range, threshold: Range, sig_bits: int) -> tuple[int, int, bool]:
    """The gate's comparison y^2 <= gate2 S in one signed 32-bit format (I, F, fits): the
    format holding the larger side, which fits when it keeps ``sig_bits`` significant bits at
    the threshold's small values.  y^2 needs no resolution of its own: a y^2 below the
    format's step rounds to 0 and is accepted, as it is in floating point (every threshold is
    far above that step when the comparison fits)."""
    both = Range(lo=min(y2.lo, threshold.lo), hi=max(y2.hi, threshold.hi))
    I = q_format(both, sig_bits)[0]
    _, _, fits = q_format(Range(lo=threshold.lo, hi=both.max_abs(), hist=threshold.hist),
                          sig_bits)
    return I, WORD_BITS - 1 - I, fits


#: sensitivities a port holds as multiples of the prior z.  sigma0 and f1 act on the state
#: rate and on the force only through b z / g (model.state_rate_du: -l z / g sigma0 and
#: l b z / g ex; model.output_du: (z l - s l sigma1 e z / g) sigma0 and s l sigma1 e b z / g ex),
#: so their sensitivities vanish with z at the surface, where z starts from 0, and their small
#: values there are z's, which z's own format already resolves (Q2.29).  Over z they keep the
#: rest of the product: raw -> scaled (recorded where z != 0; raw = z * scaled)
SCALED_FORMS = {f"{kind}{name}{end}": f"{kind}{name}{end} / z"
                for name in ("sigma0", "f1")
                for kind, end in (("rk3 dz/du.", ""), ("H[u.", "]"))}


def held_scaled(ranges: dict[str, Range], name: str, sig_bits: int) -> str | None:
    """The scaled form ``name`` is held in (SCALED_FORMS), or None: when ``name`` does not fit
    as it is and its scaled form does."""
    scaled = SCALED_FORMS.get(name)
    if scaled is None or scaled not in ranges or q_format(ranges[name], sig_bits)[2]:
        return None
    return scaled if q_format(ranges[scaled], sig_bits)[2] else None


def log_parameter_format(r: Range, sig_bits: int) -> tuple[int, int, bool]:
    """(I, F, fits) of a log-parameter u (theta = nominal e^u): the format holding max|u|, which
    fits when its step 2^-F is at most 2^-sig_bits.  An error in u is theta's relative error
    (e^(u + du) = e^u (1 + du)), so u needs absolute resolution; its values near 0 (theta near
    its nominal value) need no more than the others.  Judged by its small values instead, u.f1,
    which wanders through 0, needed 33 bits (README, the larger set)."""
    I, F, _ = q_format(r, sig_bits)
    return I, F, F >= sig_bits


#: variables the bank publishes but does not compute with: a port can saturate them or send
#: them in floating point (the NIS: the gate decides on y^2 and gate2 S)
PUBLISHED_ONLY = ("NIS",)


def format_table(ranges: dict[str, Range], sig_bits: int
                 ) -> tuple[list[str], list[str], list[str]]:
    """The markdown table, the names of the variables on the update path that do not fit 32
    bits, and the published-only ones that do not.  A variable of SCALED_FORMS whose scaled
    form fits is held in that form (its row says so) and is not a misfit; its scaled form's
    row is judged like any other."""
    lines = ["| variable | min | max | p1 of non-zero abs (2^k) | Q-format (32 bit) | fits |",
             "|---|---|---|---|---|---|"]
    misfits: list[str] = []
    published: list[str] = []
    for name in sorted(ranges, key=_order):
        r = ranges[name]
        if name.startswith("u."):
            I, F, fits = log_parameter_format(r, sig_bits)
            verdict = "yes (as θ's relative error)" if fits else "**no**"
        elif name.startswith("gate") and name.endswith(" y^2"):
            I, F, fits = gate_format(r, ranges[name[:-len("y^2")] + "gate^2 S"], sig_bits)
            verdict = "yes (as the gate's comparison)" if fits else "**no**"
        else:
            I, F, fits = q_format(r, sig_bits)
            verdict = "yes" if fits else "**no**"
        scaled = held_scaled(ranges, name, sig_bits)
        if not fits and scaled is not None:
            verdict = f"as `{scaled}` (times z)"
        elif not fits and name.startswith(PUBLISHED_ONLY):
            published.append(name)
            verdict = "no (published only)"
        elif not fits:
            misfits.append(name)
        lines.append(f"| {name} | {r.lo:.3g} | {r.hi:.3g} | {r.small():.3g} | Q{I}.{F} | "
                     f"{verdict} |")
    return lines, misfits, published


def _order(name: str) -> tuple[int, str]:
    prefixes = ("input", "z", "u.", "theta.", "e =", "g", "1/g", "b =", "m =", "fr =", "s l",
                "h (", "rk3", "H[", "P", "K", "innovation", "S", "gate", "NIS")
    for i, p in enumerate(prefixes):
        if name.startswith(p):
            return i, name
    return len(prefixes), name


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--model", type=int, choices=(1, 2), action="append",
                   help="model(s) to report (default: both)")
    p.add_argument("--seeds", type=int, default=8, metavar="N",
                   help="factor-5 starts per paper preset and tissues per random scenario "
                        "(default 8)")
    p.add_argument("--random", type=int, default=10, metavar="N",
                   help="random plausible scenarios (default 10)")
    p.add_argument("--sig-bits", type=int, default=12, metavar="B",
                   help="significant bits a variable's small values must keep (default 12)")


def run(a: argparse.Namespace) -> int:
    if a.seeds < 1:
        raise ValueError(f"--seeds must be >= 1 (got {a.seeds})")
    if a.random < 0:
        raise ValueError(f"--random must be >= 0 (got {a.random})")
    if not 1 <= a.sig_bits <= 30:
        raise ValueError(f"--sig-bits must be in 1..30 (got {a.sig_bits})")
    for model in sorted(set(a.model or [1, 2])):
        scen = paper_scenarios(model, a.seeds) + random_scenarios(model, a.random, a.seeds)
        ranges = collect(model, scen)
        lines, misfits, published = format_table(ranges, a.sig_bits)
        print(f"## Model {'I' if model == 1 else 'II'}: {len(scen)} scenarios "
              f"({len(PRESETS)} paper, {a.random} random), {a.sig_bits} significant bits")
        print("\n".join(lines))
        held = [f"{n} as {sc}" for n in SCALED_FORMS if n in ranges
                and (sc := held_scaled(ranges, n, a.sig_bits)) is not None]
        print(f"held in a scaled form ({len(held)}): " + (", ".join(held) or "none"))
        print(f"on the update path, do not fit 32 bits ({len(misfits)}): "
              + (", ".join(misfits) or "none"))
        print(f"published only, do not fit 32 bits ({len(published)}): "
              + (", ".join(published) or "none"))
        print()
    return 0

