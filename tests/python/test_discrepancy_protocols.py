"""The workflow on protocols other than one insert-dwell-retract cycle: a record that ends in its
hold (relaxation tests, hold-only protocols) is analysed with the phases it has -- it used to be
refused ("no retraction inside the tissue", and a condition of such records "no trial could be
split into phases", exit 2); two cycles in one record; the same tissue at 50 mN and at 10 N.
Phantom records (reference_py/sim/phantom.py), the hold-only ones cut where the retraction would
start; seeds and holds not used anywhere else."""
from __future__ import annotations

import numpy as np
import pytest

from reference_py.discrepancy.io import Trial
from reference_py.discrepancy.prep import PHASES, prepare
from reference_py.discrepancy.workflow import run
from reference_py.sim.phantom import simulate_phantom


def _ending_in_the_hold(name: str, seed: int, hold_s: float) -> Trial:
    ph = simulate_phantom(name, seed=seed, dwell_s=hold_s)
    keep = ph.t_s < ph.truth["cycles"][0]["retraction_start_s"]
    return Trial(f"{name}-{seed}-hold", ph.t_s[keep], ph.depth_mm[keep], ph.force_n[keep],
                 ph.velocity_mm_s[keep])


@pytest.mark.parametrize("name, seed, hold_s", [("skin", 5, 30.0), ("muscle", 6, 60.0)])
def test_a_record_that_ends_in_its_hold_is_analysed(name: str, seed: int, hold_s: float) -> None:
    tr = _ending_in_the_hold(name, seed, hold_s)
    p = prepare(tr)
    phases = {PHASES[i] for i in np.unique(p.phase)}
    assert "dwell" in phases and "insertion" in phases
    assert not phases & {"reversal", "retraction", "after_exit"}
    res = run([tr])
    # the hold decays in every preset of the phantom: relaxation is named; nothing that lives
    # in a reversal or after the exit is
    assert "dwell_relaxation" in res.named
    assert not set(res.named) & {"reversal_presliding", "sensor_drift", "direction_asymmetry"}
    assert np.all(np.isfinite(res.predictions[-1][0]))


def test_two_cycles_in_one_record_are_analysed() -> None:
    # two insertion-dwell-retraction cycles at 2 and 4 mm/s, each into a fresh site
    ph = simulate_phantom("muscle", seed=8, speeds_mm_s=(2.0, 4.0))
    res = run([Trial("muscle-8-two-cycles", ph.t_s, ph.depth_mm, ph.force_n, ph.velocity_mm_s)])
    assert "dwell_relaxation" in res.named and res.layers == [1]


@pytest.mark.parametrize("peak_n", [0.05, 10.0])
def test_the_same_tissue_at_50_mN_and_at_10_N(peak_n: float) -> None:
    # the skin phantom's records scaled (noise with them, as another sensor range would see the
    # same tissue): what is named does not depend on the force's scale
    trials = []
    for seed in (8, 9):
        ph = simulate_phantom("skin", seed=seed)
        k = peak_n / float(np.max(ph.force_n))
        trials.append(Trial(f"skin-{seed}", ph.t_s, ph.depth_mm, ph.force_n * k, ph.velocity_mm_s))
    res = run(trials)
    assert res.named == ["layer_puncture", "dwell_relaxation", "reversal_presliding"]
    assert res.layers == [1, 1]
