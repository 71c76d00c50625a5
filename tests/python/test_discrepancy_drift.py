"""A sensor drift told by the air (issue 22, items 4 and 6): the level after the exit against the
tare before contact decides whether `sensor_drift` is seen, absent or not told, and the drift's
slope is one per trial, so drifts that part differently in each trial (a random walk, a warm-up)
are named and followed."""
import numpy as np
import pytest

from discrepancy_generator import case_seed, make_case
from reference_py.discrepancy import evidence
from reference_py.discrepancy.evidence import (AIR_DRIFT_MIN_NOISE, AIR_DRIFT_MIN_Z,
                                               AIR_DRIFT_NONE_Z, drift_verdict)
from reference_py.discrepancy.prep import prepare
from reference_py.discrepancy.report import build
from reference_py.discrepancy.workflow import run

NOISE = 0.01


def _ev(*air: tuple[float, float] | None) -> dict:
    """Evidence of trials whose air levels are (level in noise units, z), None: no air after."""
    per = []
    for a in air:
        d = {"available": 0.0, "level_n": 0.0, "slope_n_per_s": 0.0, "z": 0.0} if a is None \
            else {"available": 1.0, "level_n": a[0] * NOISE, "slope_n_per_s": 0.0, "z": a[1]}
        per.append({"air_drift": d, "noise_n": NOISE})
    return {"per_trial": per}


# (case, trials' air as (level / noise, z) or None, the verdict)
VERDICTS = [
    ("every trial moved", [(4.0, 40.0), (-3.0, 30.0)], True),
    ("half the trials moved, one not", [(4.0, 40.0), (0.1, 1.0)], True),
    ("one of three moved", [(4.0, 40.0), (0.1, 1.0), (0.2, 3.5)], None),
    ("z just below the seen threshold", [(4.0, AIR_DRIFT_MIN_Z * 0.99)], None),
    ("z at it", [(4.0, AIR_DRIFT_MIN_Z)], True),
    ("a level below the noise, however sure", [(AIR_DRIFT_MIN_NOISE * 0.9, 50.0)], None),
    ("every trial within the absent threshold", [(0.1, AIR_DRIFT_NONE_Z * 0.99), (0.0, 0.1)],
     False),
    ("one trial at the absent threshold", [(0.1, AIR_DRIFT_NONE_Z), (0.0, 0.1)], None),
    ("no trial with air after the exit", [None, None], None),
    ("trials without air do not count", [None, (4.0, 40.0), None], True),
]


@pytest.mark.parametrize("case, air, verdict", VERDICTS, ids=[c[0] for c in VERDICTS])
def test_the_air_tells_a_drift(case, air, verdict):
    got, why = drift_verdict(_ev(*air))
    assert got is verdict, (case, why)
    assert why


def _round(rep: dict, name: str) -> list[dict]:
    rounds = [e.get("candidates") or [] for e in rep.get("effects") or []] + \
        [rep.get("final_round") or []]
    return [c for cands in rounds for c in cands if c.get("name") == name]


@pytest.fixture(scope="module")
def random_walk():
    """A blind random-walk drift whose air levels part in sign: +4.8, -4.3 and -4.0 noise."""
    case = make_case("sensor_drift/random_walk", case_seed("sensor_drift/random_walk", 3))
    res = run(case.trials)
    return case, res, build(res, [t.name for t in case.trials])


def test_a_drift_that_parts_per_trial_is_named_first(random_walk):
    case, res, rep = random_walk
    assert rep["named"][0] == "sensor_drift", rep["named"]
    levels = [evidence.air_drift(prepare(t))["level_n"] for t in case.trials]
    assert np.sign(levels).tolist() == [1.0, -1.0, -1.0]
    final = res.fits[-1]
    slopes = [final.coef[f"drift[{i}]"] for i in range(len(case.trials))]
    # each trial's slope follows its own air level: one shared slope cannot
    assert np.sign(slopes).tolist() == np.sign(levels).tolist(), slopes
    # and the model comes closer to the noise-free truth (measured: 4.0 -> 3.4 noise)
    truth = {t.name: f for t, f in zip(case.trials, case.truth)}

    def rmse(preds: list[np.ndarray]) -> float:
        d = np.concatenate([p - truth[q.name] for p, q in zip(preds, res.preps)])
        return float(np.sqrt(np.mean(d ** 2)))

    assert rmse(res.predictions[-1]) < 0.9 * rmse(res.predictions[0])


def test_the_air_without_a_drift_refuses_it():
    case = make_case("none", case_seed("none", 0))
    res = run(case.trials)
    rep = build(res, [t.name for t in case.trials])
    assert "sensor_drift" not in rep["named"]
    refused = _round(rep, "sensor_drift")
    assert refused and refused[0]["rejected"] == "no local evidence", refused
    assert "the tare's in every trial" in refused[0]["local"]
