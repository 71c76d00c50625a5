"""A named effect that makes a phase the model explained worse (issue 22, item 4): measured for
every candidate judged, reported -- a warning in report.md, report.json effects[].worsens, an item
of "What next" -- and every refused candidate says why.  Not a refusal rule: accept.py gives the
figures of that rule on blind cases it was not designed on (more true effects lost than false
ones removed)."""
import numpy as np
import pytest

from reference_py.discrepancy.fit import Fit
from reference_py.discrepancy.prep import PHASES
from reference_py.discrepancy.accept import WORSEN_NOISE_X, worst_phase
from reference_py.discrepancy.report import build, render_md
from reference_py.discrepancy.unexplained import UNEXPLAINED_X
from reference_py.discrepancy.workflow import run

SIGMA = 0.01


def _fit(resid: np.ndarray) -> Fit:
    return Fit((), {}, {}, float(resid @ resid), len(resid), 3, resid)


def _phases(n: int = 200) -> np.ndarray:
    """Rows of the insertion, dwell and after-exit phases, n each."""
    return np.repeat([PHASES.index("insertion"), PHASES.index("dwell"),
                      PHASES.index("after_exit")], n)


def _resid(rms: dict[str, float], seed: int = 0) -> np.ndarray:
    """A residual with the given RMSE in each of _phases()'s phases (exactly)."""
    rng = np.random.default_rng(seed)
    out = []
    for name in ("insertion", "dwell", "after_exit"):
        r = rng.normal(size=200)
        out.append(r / np.sqrt(np.mean(r ** 2)) * rms[name])
    return np.concatenate(out)


# (case, RMSE before per phase, after, the phase flagged or "" and whether it is refused)
CASES = [
    ("an explained phase made 10x worse", {"insertion": 0.5, "dwell": 0.02, "after_exit": 0.012},
     {"insertion": 0.1, "dwell": 0.02, "after_exit": 0.12}, "after_exit", True),
    ("rise just inside the noise allowance",
     {"insertion": 0.5, "dwell": 0.02, "after_exit": 0.012},
     {"insertion": 0.1, "dwell": 0.02, "after_exit": 0.012 + 0.99 * WORSEN_NOISE_X * SIGMA},
     "after_exit", False),
    ("rise just beyond it", {"insertion": 0.5, "dwell": 0.02, "after_exit": 0.012},
     {"insertion": 0.1, "dwell": 0.02, "after_exit": 0.012 + 1.01 * WORSEN_NOISE_X * SIGMA},
     "after_exit", True),
    ("an unexplained phase is not protected",
     {"insertion": 0.5, "dwell": 0.02, "after_exit": 0.012},
     {"insertion": 1.5, "dwell": 0.01, "after_exit": 0.012}, "", False),
    ("explained at the threshold, 3x the noise more",
     {"insertion": UNEXPLAINED_X * SIGMA * 0.999, "dwell": 0.5, "after_exit": 0.01},
     {"insertion": UNEXPLAINED_X * SIGMA * 0.999 + 1.01 * WORSEN_NOISE_X * SIGMA, "dwell": 0.1,
      "after_exit": 0.01}, "insertion", True),
    ("just unexplained: not protected",
     {"insertion": UNEXPLAINED_X * SIGMA * 1.001, "dwell": 0.5, "after_exit": 0.01},
     {"insertion": 10 * UNEXPLAINED_X * SIGMA, "dwell": 0.1, "after_exit": 0.01}, "after_exit",
     False),
]


@pytest.mark.parametrize("case, before, after, phase, refused", CASES, ids=[c[0] for c in CASES])
def test_a_phase_made_worse(case, before, after, phase, refused):
    ph = _phases()
    name, b, a, ratio = worst_phase(_fit(_resid(before)), _fit(_resid(after, 1)), ph, SIGMA,
                                    UNEXPLAINED_X)
    if phase:
        assert name == phase, (case, name)
        assert b == pytest.approx(before[phase]) and a == pytest.approx(after[phase])
        assert ratio == pytest.approx((after[phase] - before[phase]) / (WORSEN_NOISE_X * SIGMA))
    assert (ratio > 1.0) == refused, (case, name, ratio)


@pytest.fixture(scope="module")
def presliding_case() -> tuple:
    from discrepancy_measured_like import make_case
    case = make_case(43, trials=3)
    return case, run(case.trials)


def test_every_judged_candidate_carries_its_worst_explained_phase(presliding_case):
    """Measured-like seed 43, three trials (layers, relaxation, Dahl pre-sliding): every
    candidate the workflow judged carries the phase the model explained that its refit made
    worse most (accept.worst_phase), so the report can warn; every candidate of the last round
    says why it was not named."""
    case, res = presliding_case
    assert res.named[:3] == ["layer_puncture", "dwell_relaxation", "reversal_presliding"]
    for step in res.steps:
        if step.effect == "layer_puncture":        # found by the ruptures, not judged
            continue
        row = next(c for c in step.candidates if c["name"] == step.effect)
        assert {"worst_phase", "worst_phase_rmse_before_n", "worst_phase_rmse_after_n",
                "worst_phase_ratio"} <= set(row), row
    assert res.last_round and all(c.get("rejected") for c in res.last_round), res.last_round


def test_an_effect_whose_refit_spoils_an_explained_phase_is_reported(presliding_case):
    """A named effect whose refit raises a phase the model explained by more than the allowance
    stays named (a refusal rule cost more true effects than it saved on blind cases: accept.py),
    with a warning in report.md and the advice to try it otherwise; an effect within the
    allowance carries none.  The case: seed 43's pre-sliding row set to a refit that raises the
    insertion from 0.037 to 0.15 N -- what a false tissue motion did to the dwell of seed 24
    (0.026 -> 0.16 N) until the tears were placed between their samples.  Since then no
    measured-like condition of seeds 11-90 names one, and the only real case left (seed 43
    itself, 0.037 -> 0.087 N) sits at 1.02 times the allowance: too close to the line for a test
    that must hold on every machine."""
    import copy
    case, res = presliding_case
    res = copy.deepcopy(res)
    step = next(st for st in res.steps if st.effect == "reversal_presliding")
    row = next(c for c in step.candidates if c["name"] == "reversal_presliding")
    before, after = 0.037, 0.15
    row.update(worst_phase="insertion", worst_phase_rmse_before_n=before,
               worst_phase_rmse_after_n=after,
               worst_phase_ratio=(after - before) / (WORSEN_NOISE_X * case.noise_n))
    rep = build(res, [t.name for t in case.trials])
    k = rep["named"].index("reversal_presliding")
    w = rep["effects"][k]["worsens"]
    assert w == {"phase": "insertion", "rmse_before_n": before, "rmse_after_n": after,
                 "allowance_x_noise": WORSEN_NOISE_X}
    md = render_md(rep, [])
    assert (f"- WARNING: its refit makes the insertion phase, which the model explained, worse: "
            f"RMSE {before:.4g} -> {after:.4g} N") in md
    items = [d for d in rep["what_next"]["effects"] if d["source"] == f"effects[{k}].worsens"]
    assert len(items) == 1 and items[0]["candidates"] == ["reversal_presliding"]
    # within the allowance (ratio <= 1): no warning, no advice
    row["worst_phase_ratio"] = 0.99
    rep = build(res, [t.name for t in case.trials])
    assert rep["effects"][k]["worsens"] is None
    assert not [d for d in rep["what_next"]["effects"] if d["source"].endswith(".worsens")]
    assert "WARNING: its refit makes" not in render_md(rep, [])
