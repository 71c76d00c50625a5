"""Reproducible starting values away from the truth (``--init-seed K --init-factor F``).

The draw must be repeatable by the C host program to the last bit, so it uses no numpy generator:
a SplitMix64 stream seeded with K gives one uniform double per parameter, r = (x >> 11) * 2^-53,
in PARAM_NAMES order (every parameter consumes a draw, identified or not), and

    w_j = (2 r_j - 1) * log(F),     start_j = value_j * exp(w_j)

evaluated in double with the C library's ``log`` and ``exp`` (Python's math module calls the same
functions on the same machine).  Only the parameters the model identifies are moved; f1 is moved
through its excess over -f2 (the quantity the filters identify), so g(0) > 0 at every start.
Seed 0 returns the values unchanged.
"""
from __future__ import annotations

import math

from .params import IDX, MODEL_PARAMS, PARAM_NAMES, f1_kappa

_MASK64 = (1 << 64) - 1


def splitmix64(state: int) -> tuple[int, int]:
    """One SplitMix64 step: (new state, output)."""
    state = (state + 0x9E3779B97F4A7C15) & _MASK64
    z = state
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK64
    return state, z ^ (z >> 31)


def uniform_draws(seed: int, n: int) -> list[float]:
    state = seed & _MASK64
    out = []
    for _ in range(n):
        state, x = splitmix64(state)
        out.append(float(x >> 11) * (1.0 / 9007199254740992.0))
    return out


def start_values(values: list[float], seed: int, factor: float, model: int) -> list[float]:
    """Seven starting values (PARAM_NAMES order) from the seven given ones."""
    if seed == 0:
        return list(values)
    if not (math.isfinite(factor) and factor >= 1.0):
        raise ValueError(f"init factor must be >= 1 (got {factor!r})")
    log_f = math.log(factor)
    draws = uniform_draws(seed, len(PARAM_NAMES))
    mult = [1.0] * len(PARAM_NAMES)
    for name in MODEL_PARAMS[model]:
        if name not in PARAM_NAMES:
            continue  # Model III's relaxation strengths start at their nominal values
        j = IDX[name]
        mult[j] = math.exp((2.0 * draws[j] - 1.0) * log_f)
    out = [v * m for v, m in zip(values, mult)]
    kappa = f1_kappa(values[IDX["f2"]])
    excess = values[IDX["f1"]] - kappa * (-values[IDX["f2"]])
    out[IDX["f1"]] = kappa * (-out[IDX["f2"]]) + excess * mult[IDX["f1"]]
    return out
