"""Model III's relaxation branches (MODEL.md §3b, JACOBIANS.md §7): what the bank takes off the
elastic force for the tissue's stress relaxation, and the output's Jacobian row with it.

Each branch i keeps a memory m_i of the elastic force fe, decaying over a sample by
a_i = exp(-dt / tau_i) (exact for an input held over the sample: stable at every rate):
m_i' = a_i m_i + (1 - a_i) fe.  The output is h = fe - sum g_i m_i'.  The filters scale the
strengths as odds G_i = g_i / (1 - sum g), so that g_i = G_i / (1 + sum G) stays in (0, 1)
with a sum below 1 for every scaled value.  One branch or two (identified.relax_count): the
lists hold one array per branch in use.

C twin: firmware/src/nte_bank.c (relax_fractions, relax_terms, the relaxation block of
measure and the odds in the nominal values' setup), where they are static for the board's
cycle count.
"""
from __future__ import annotations

import numpy as np

from .fmath import Array, Real
from .params import RELAX_NAMES


def relax_odds(R: Real, g: list[Array]) -> list[Array]:
    """The configured strengths g (fractions, each > 0, their sum < 1) as the odds G the
    filters scale, G_i = g_i / (1 - sum g).  ValueError when they are not fractions."""
    total = g[0] if len(g) == 1 else g[0] + g[1]
    den = R.c(1.0) - total
    if not (all(np.all(gk > R.c(0.0)) for gk in g) and np.all(den > R.c(0.0))):
        raise ValueError("nominal relaxation strengths g_fast, g_slow must be > 0 with a "
                         "sum < 1")
    return [gk / den for gk in g]


def relax_fractions(R: Real, G: list[Array]) -> list[Array]:
    """g_i = G_i / (1 + sum G): the strengths, each in (0, 1), their sum below 1."""
    den = R.c(1.0) + (G[0] if len(G) == 1 else G[0] + G[1])
    return [Gk / den for Gk in G]


def relax_terms(R: Real, G: list[Array], a: list[Array], mrel: list[Array], fe: Array
                ) -> tuple[list[Array], list[Array], Array]:
    """The strengths g, each branch's memory after this sample for the elastic force fe,
    m_i' = a_i m_i + (1 - a_i) fe, and what the branches take off, M = sum g_i m_i'."""
    one = R.c(1.0)
    g = relax_fractions(R, G)
    mp = [a[k] * mrel[k] + (one - a[k]) * fe for k in range(len(G))]
    M = g[0] * mp[0] if len(G) == 1 else g[0] * mp[0] + g[1] * mp[1]
    return g, mp, M


def relax_output(R: Real, G: list[Array], a: list[Array], mrel: list[Array],
                 names: tuple[str, ...], fe: Array, hrow: list[Array]
                 ) -> tuple[Array, list[Array]]:
    """h = fe - M and its Jacobian row for a filter identifying ``names``: the elastic row
    ``hrow`` times the fraction a change of fe keeps, 1 - sum g_i (1 - a_i) (the memories'
    past is known, not a state), then dh/du_gk = -g_k (m_k' - M) for the strengths in names
    (g_k = G_k / (1 + sum G) with G_k = nominal e^u_k: dg_k/du_k = g_k (1 - g_k),
    dg_j/du_k = -g_j g_k, so dM/du_k = g_k m_k' - g_k M)."""
    one = R.c(1.0)
    g, mp, M = relax_terms(R, G, a, mrel, fe)
    lost = g[0] * (one - a[0])
    if len(G) == 2:
        lost = lost + g[1] * (one - a[1])
    keep = one - lost
    row = [hj * keep for hj in hrow]
    for k, nm in enumerate(RELAX_NAMES[:len(G)]):
        if nm in names:
            row.append(-(g[k] * (mp[k] - M)))
    return fe - M, row
