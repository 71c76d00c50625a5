"""Physical parameters, the paper's presets, and the scaled (log) form the filters identify.

Units (MODEL.md §1): depth l in mm, time in s, force in N, z dimensionless.  The parameters
carry whatever units make f in N with l in mm; they are given here exactly as the paper reports them.

Scaled form.  The filters never see a physical parameter directly.  Each identified parameter j is
written relative to a configured nominal value (the user's prior guess, which is also the
filter's starting point) as a log-ratio u_j:

    theta_j = nominal_j * exp(u_j)            for sigma0, sigma1, sigma2, f2, alpha, beta
    f1      = kappa * (-f2) + excess_nominal * exp(u_f1)

with kappa = 1 when the nominal f2 is negative (then f1 > |f2| keeps g(l) = f1 + f2 exp(-alpha l)
positive at every depth; its minimum is at l = 0) and kappa = 0 otherwise (f1 > 0 suffices), and
excess_nominal = nominal_f1 - kappa * (-nominal_f2).  Every u starts at 0, every physical parameter
keeps its sign, g(l) can never cross zero, and u stays O(1) — a range float32 (and a later Q-format
port) represents well, whatever the magnitude of theta.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

PARAM_NAMES: tuple[str, ...] = ("sigma0", "sigma1", "sigma2", "f1", "f2", "alpha", "beta")
#: Model III's relaxation strengths (MODEL.md §3b): the fraction of the elastic force each
#: Maxwell branch takes away once the tissue has relaxed.  Not force-model parameters of the
#: paper (the presets and simulators know only PARAM_NAMES); the bank indexes them after them.
RELAX_NAMES: tuple[str, ...] = ("g_fast", "g_slow")
#: Model III's turn-over length delta, mm (MODEL.md §3b): identified with the direction memory
#: on, starting from the configured presliding_mm; indexed after the strengths
DIR_NAMES: tuple[str, ...] = ("delta",)
ALL_NAMES: tuple[str, ...] = PARAM_NAMES + RELAX_NAMES + DIR_NAMES
IDX = {name: i for i, name in enumerate(ALL_NAMES)}
#: Model III's layer sets (predict-only; MODEL.md §3b part 3): the values that set one layer's
#: force-depth curve — its stiffness sigma0, its cutting level g(l) through f1 and beta, its
#: friction slope sigma2.  The rest (sigma1, the strengths, delta) shape dwells and reversals,
#: which happen at one depth in one layer: a record cannot tell them apart per layer.
LAYER_SET_NAMES: tuple[str, ...] = ("sigma0", "f1", "beta", "sigma2")
#: nominal (starting) strengths, fractions of the elastic force; their sum must be < 1
#: (measured dwells lose 24-49 % in 5 s, a third of it within 0.3 s)
RELAX_NOMINAL: dict[str, float] = {"g_fast": 0.15, "g_slow": 0.25}

#: parameters each model identifies, in CSV column order (Model III: with both relaxation
#: branches; identified.identified_names drops the strengths a configuration switches off)
MODEL_PARAMS: dict[int, tuple[str, ...]] = {
    1: ("sigma0", "sigma1", "sigma2", "f1", "f2", "alpha"),
    2: ("sigma0", "sigma1", "sigma2", "f1", "beta"),
    3: ("sigma0", "sigma1", "sigma2", "f1", "beta", "g_fast", "g_slow", "delta"),
}

#: the bank of three filters (paper Table I): the parameter subset each one identifies with z.
#: Model III is Model II with the relaxation strengths beside sigma0 in filter 1 (both scale
#: the held force in a dwell, where sigma0 z l is all that is left of the friction-free force)
#: and the turn-over length beside the friction's f1, sigma1 in filter 2 (it shapes how the
#: friction term turns over; with the friction filter the turn-over's innovation reaches it
#: before filter 3's prediction from the updated friction does)
FILTER_SUBSETS: dict[int, tuple[tuple[str, ...], ...]] = {
    1: (("f2", "sigma0"), ("f1", "sigma1"), ("alpha", "sigma2")),
    2: (("sigma0",), ("f1", "sigma1"), ("beta", "sigma2")),
    3: (("sigma0", "g_fast", "g_slow"), ("f1", "sigma1", "delta"), ("beta", "sigma2")),
}

#: Model I's fixed normalising constant beta0 when no preset supplies one (MODEL.md §2)
BETA0_DEFAULT = 2.55e-2


@dataclass(frozen=True)
class ParamSet:
    """One tissue/needle/speed parameter set (Model II values with fixed f2, alpha; §3)."""

    sigma0: float
    sigma1: float
    sigma2: float
    f1: float
    f2: float
    alpha: float
    beta: float

    def as_list(self) -> list[float]:
        return [getattr(self, n) for n in PARAM_NAMES]

    def with_values(self, **kw: float) -> "ParamSet":
        return replace(self, **kw)

    def g_min(self) -> float:
        """Smallest value of g(l) = f1 + f2 exp(-alpha l) over l >= 0."""
        return self.f1 + min(self.f2, 0.0)


@dataclass(frozen=True)
class Preset:
    name: str
    params: ParamSet
    speed_mm_s: float
    description: str


PRESETS: dict[str, Preset] = {
    p.name: p
    for p in (
        Preset("paper-10mms", ParamSet(7.9e-3, 2.46, 4.14e-3, 5.59e-2, -2.11e-2, 5.25e-2, 2.55e-2),
               10.0, "needle A, tissue A, 10 mm/s (paper §V.B, Model II)"),
        Preset("paper-6mms", ParamSet(3.91e-3, 2.25, 3.55e-3, 3.25e-2, -1.17e-2, 3.63e-2, 2.43e-2),
               6.0, "needle A, tissue A, 6 mm/s (paper §V.B, Model II)"),
        Preset("needleB-tissueB-10mms",
               ParamSet(9.2e-4, 0.448, 1.63e-3, 2.7e-2, -9.96e-3, 1.11e-2, 1.53e-2),
               10.0, "needle B, tissue B, 10 mm/s (paper Table III)"),
        Preset("needleB-tissueB-6mms",
               ParamSet(8.37e-4, 0.927, 1.79e-3, 9.21e-3, 0.249, 5.84e-2, 1.36e-2),
               6.0, "needle B, tissue B, 6 mm/s (paper Table III)"),
        Preset("needleB-tissueA-10mms",
               ParamSet(7.96e-4, 0.535, 7.63e-4, 2.15e-2, -1.19e-2, 1.08e-2, 1.58e-2),
               10.0, "needle B, tissue A, 10 mm/s (paper Table III)"),
    )
}


def get_preset(name: str) -> Preset:
    try:
        return PRESETS[name]
    except KeyError:
        known = ", ".join(PRESETS)
        raise ValueError(f"unknown preset {name!r} (known: {known})") from None


def f1_kappa(f2_nominal: float) -> float:
    """1 when f1 must exceed -f2 to keep g(0) > 0 (nominal f2 < 0), else 0."""
    return 1.0 if f2_nominal < 0.0 else 0.0


def f1_excess(f1: float, f2: float) -> float:
    """The part of f1 the filters scale: f1 - kappa * (-f2); must be > 0."""
    return f1 - f1_kappa(f2) * (-f2)
