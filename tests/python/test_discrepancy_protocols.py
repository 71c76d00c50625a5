"""The workflow on protocols other than insert-dwell-retract: a record that ends in its hold
(relaxation tests, hold-only protocols) is analysed with the phases it has -- it used to be
refused ("no retraction inside the tissue", and a condition of such records "no trial could be
split into phases", exit 2).  Phantom records (reference_py/tools/phantom.py) cut where the
retraction would start; seeds and holds not used anywhere else."""
from __future__ import annotations

import numpy as np
import pytest

from reference_py.discrepancy.io import Trial
from reference_py.discrepancy.prep import PHASES, prepare
from reference_py.discrepancy.workflow import run
from reference_py.tools.phantom import simulate_phantom


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
