"""What a configuration identifies: the parameters in CSV column order and which filter of the
bank identifies each (the paper's Table I, with Model III's switches applied).

C twin: the tables and relax_count, identifies_delta, subset_count, identified_ids at the top
of firmware/src/nte_bank.c (the C library has no module of its own for them).  Here they are
apart from the bank because they are a function of the configuration alone: the estimate
file's columns and the node mirror ask for them without running a filter, and bank.py keeps to
the filters.  bank.py imports them, so ``from reference_py.bank import identified_names,
filter_subsets`` still works.
"""
from __future__ import annotations

from .config import EstimatorConfig
from .params import DIR_NAMES, FILTER_SUBSETS, MODEL_PARAMS, PARAM_NAMES


def relax_count(cfg: EstimatorConfig) -> int:
    """Model III's relaxation branches in use (0 when relaxation is off or for Models I, II)."""
    return cfg.relax_branches if (cfg.model == 3 and cfg.relaxation) else 0


def identifies_delta(cfg: EstimatorConfig) -> bool:
    """Model III identifies its turn-over length delta whenever the direction memory is on."""
    return cfg.model == 3 and cfg.direction_memory


def identified_names(cfg: EstimatorConfig) -> tuple[str, ...]:
    """The parameters a configuration identifies, in CSV column order (Model III: Model II's,
    the strengths of the branches in use, and delta with the direction memory on)."""
    if cfg.model != 3:
        return MODEL_PARAMS[cfg.model]
    return (MODEL_PARAMS[3][:len(MODEL_PARAMS[2]) + relax_count(cfg)] +
            (DIR_NAMES if identifies_delta(cfg) else ()))


def filter_subsets(cfg: EstimatorConfig) -> tuple[tuple[str, ...], ...]:
    """Table I for a configuration: Model III's filter 1 takes the strengths in use, filter 2
    delta when the direction memory is on."""
    subsets = FILTER_SUBSETS[cfg.model]
    if cfg.model != 3:
        return subsets
    second = subsets[1] if identifies_delta(cfg) else subsets[1][:2]
    return (subsets[0][:1 + relax_count(cfg)], second, subsets[2])


def dynamic(names: tuple[str, ...]) -> tuple[str, ...]:
    """The parameters of the state equation among names (the relaxation strengths act on the
    output only: dz/du_g = 0)."""
    return tuple(nm for nm in names if nm in PARAM_NAMES)


__all__ = ["relax_count", "identifies_delta", "identified_names", "filter_subsets", "dynamic"]
