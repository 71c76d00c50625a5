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
from reference_py.discrepancy.workflow import UNEXPLAINED_X, run

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


def test_tissue_motion_that_spoils_the_dwell_is_reported():
    """Measured-like seed 24, three trials (layers, relaxation, Dahl pre-sliding; no motion):
    tissue motion's refit lowers the error where it acts and held out, but raises the dwell the
    model explained from 0.026 to 0.16 N RMS.  It is named (a refusal rule cost more true effects
    than it saved on blind cases), with the warning, and the advice to try it otherwise.  (The
    case moves between seeds when the fits' numbers move: seed 11 until the first band carried
    its own friction, seed 26 until stiff samples stepped exactly; 4 of seeds 11-30 name this
    false motion before and after both changes.)"""
    from discrepancy_measured_like import make_case
    case = make_case(24, trials=3)
    res = run(case.trials)
    assert "tissue_motion" in res.named
    rep = build(res, [t.name for t in case.trials])
    k = rep["named"].index("tissue_motion")
    w = rep["effects"][k]["worsens"]
    assert w["phase"] == "dwell" and w["rmse_before_n"] <= UNEXPLAINED_X * case.noise_n * 1.5
    assert w["rmse_after_n"] - w["rmse_before_n"] > WORSEN_NOISE_X * 0.01
    assert w["rmse_after_n"] > 5 * w["rmse_before_n"]
    md = render_md(rep, [])
    assert (f"- WARNING: its refit makes the dwell phase, which the model explained, worse: "
            f"RMSE {w['rmse_before_n']:.4g} -> {w['rmse_after_n']:.4g} N") in md
    items = [d for d in rep["what_next"]["effects"] if d["source"] == f"effects[{k}].worsens"]
    assert len(items) == 1 and items[0]["candidates"] == ["tissue_motion"]
    # effects whose refit leaves every explained phase within the allowance carry no warning
    for e in rep["effects"]:
        if e["name"] not in ("tissue_motion", "layer_puncture"):
            row = next(c for c in e["candidates"] if c["name"] == e["name"])
            assert (e["worsens"] is None) == (row["worst_phase_ratio"] is None or
                                              row["worst_phase_ratio"] <= 1.0)
    # every candidate of the last round says why it was not named
    assert res.last_round and all(c.get("rejected") for c in res.last_round), res.last_round
