"""The relaxation's memory after a dwell (effects.py ``relax_memory``, DISCREPANCY.md section 4):
the share of what relaxed in a dwell that the tissue still holds after it, fading with each
branch's tau, fitted only once the effects are named (workflow._polish).

Checked: the design's relaxation columns after a dwell (their value, their decay, where they end);
naming and the plain form are untouched (relax_memory = 0 is the old design, bit for bit); on a
record whose tissue keeps the memory (the measured-like generator: a Maxwell element on the held
stress) the final model follows the retraction much better, and on a phantom record whose tissue
drops it within a fraction of a mm, nothing moves."""
import numpy as np
import pytest

from discrepancy_measured_like import make_case, phantom_trial

from reference_py.discrepancy import workflow
from reference_py.discrepancy.effects import EFFECT_NL, TrialGrid, design, find_dwells, nl_defaults

TAU_FAST, TAU_SLOW = 0.4, 3.0


def _grid() -> TrialGrid:
    """100 Hz: 1 s in the air, in 12 mm at 3 mm/s, a 3 s dwell, out 15 mm at 3 mm/s, 1 s rest."""
    t = np.arange(0.0, 14.0, 0.01)
    x = np.interp(t, [0.0, 1.0, 5.0, 8.0, 13.0, 14.0], [-3.0, -3.0, 9.0, 9.0, -6.0, -6.0])
    v = np.gradient(x, t)
    v[np.abs(v) < 1.0] = 0.0                    # the interpolation's corners: rest or 3 mm/s
    return TrialGrid(t, x, v, 0.0, find_dwells(t, x, v))


def _columns(grid: TrialGrid, memory: float) -> dict[str, np.ndarray]:
    nl = nl_defaults(("dwell_relaxation",), 1)
    nl.update(tau_fast_s=np.array(TAU_FAST), tau_slow_s=np.array(TAU_SLOW),
              relax_memory=np.array(memory))
    m, labels = design([grid], ("dwell_relaxation",), nl)
    return {lab: m[:, j] for j, lab in enumerate(labels)}


def test_memory_is_a_refinement_not_screened_and_not_flagged():
    par = {p.name: p for p in EFFECT_NL["dwell_relaxation"]}["relax_memory"]
    assert (par.lo, par.hi, par.init, par.log) == (0.0, 1.0, 0.0, False)
    assert not par.screened and not par.flag_bounds


def test_the_columns_after_a_dwell_hold_the_share_and_fade_with_tau():
    g = _grid()
    (i0, i1), = g.dwells
    plain, kept = _columns(g, 0.0), _columns(g, 0.7)
    t = g.t_s
    inside = g.stage_mm > 0.0
    back = np.flatnonzero((np.arange(len(t)) >= i1) & inside)
    assert len(back) > 100 and back[0] == i1
    for name, tau in (("relax_fast[0]", TAU_FAST), ("relax_slow[0]", TAU_SLOW)):
        # in the dwell the two are the same; after it the plain form holds nothing
        assert np.array_equal(plain[name][:i1], kept[name][:i1])
        assert np.all(plain[name][i1:] == 0.0)
        end = kept[name][i1 - 1]
        assert end < 0.0
        want = 0.7 * end * np.exp(-(t[back] - t[i1 - 1]) / tau)
        np.testing.assert_allclose(kept[name][back], want, rtol=1e-12)
        # out of the tissue again: nothing is remembered
        assert np.all(kept[name][~inside] == 0.0)
    # the hold H is the dwell's alone
    assert np.array_equal(plain["relax_hold[0]"], kept["relax_hold[0]"])
    assert np.all(kept["relax_hold[0]"][i1:] == 0.0)


def test_the_memory_ends_where_the_needle_advances_again():
    g = _grid()
    (_, i1), = g.dwells
    # half a second into the retraction the needle advances again (the stage held where it was,
    # in the tissue: the memory ends on the velocity, not the depth)
    x = g.stage_mm.copy()
    push = (g.t_s >= g.t_s[i1] + 0.5)
    x[push] = x[push][0]
    v = g.v_mm_s.copy()
    v[push] = 2.0
    g2 = TrialGrid(g.t_s, x, v, 0.0, g.dwells)
    col = _columns(g2, 1.0)["relax_slow[0]"]
    assert np.all(col[i1:][~push[i1:]] != 0.0)
    assert np.all(col[push] == 0.0)


def _retraction_rmse(pred: np.ndarray, truth: np.ndarray, t: np.ndarray, v: np.ndarray,
                     noise: float) -> float:
    back = np.flatnonzero(v < -0.05)
    w = t >= t[back[0]]
    return float(np.sqrt(np.mean((pred - truth)[w] ** 2))) / noise


@pytest.fixture(scope="module")
def measured_like() -> dict[str, object]:
    """Measured-like seed 476 (one trial), with and without the polish."""
    case = make_case(476, trials=1)
    res = workflow.run(case.trials)
    orig = workflow._polish
    try:
        workflow._polish = lambda f, *a: f          # the model without the memory
        plain = workflow.run(case.trials)
    finally:
        workflow._polish = orig
    return {"case": case, "res": res, "plain": plain}


def test_a_tissue_that_keeps_the_memory_gets_it(measured_like):
    case, res, plain = measured_like["case"], measured_like["res"], measured_like["plain"]
    assert res.named == plain.named                  # naming does not see the memory
    assert "dwell_relaxation" in res.named
    assert float(res.fits[-1].nl["relax_memory"]) > 0.5
    assert res.fits[-1].sse < plain.fits[-1].sse
    tr = case.trials[0]
    v = np.gradient(tr.depth_mm, tr.t_s)
    after = _retraction_rmse(res.predictions[-1][0], case.truth[0], tr.t_s, v, case.noise_n)
    before = _retraction_rmse(plain.predictions[-1][0], case.truth[0], tr.t_s, v,
                              case.noise_n)
    # measured: 5.48 -> 2.45 the noise over the retraction
    assert after <= 0.6 * before, (before, after)


def test_a_tissue_that_drops_it_is_left_alone():
    """Phantom skin seed 202: its cutting force unloads within 0.3-0.8 mm; the memory is not
    worth its parameter there and the final model is the plain one."""
    trial, truth, noise, _ = phantom_trial("skin", 202)
    res = workflow.run([trial])
    assert "dwell_relaxation" in res.named
    assert float(res.fits[-1].nl["relax_memory"]) == 0.0
