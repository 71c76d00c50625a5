"""Per-filter fault words (nte.h nte_output_t.filter_status, StepOutput.filter_status in
reference_py): what each filter of the bank raised at a sample, published on the bus as
Health.Filter<i>Flags.

C = reference bit for bit on records with force spikes (gates) and bad samples; the words OR to
the sample's filter bits; each bit lands on the filter that raised it (with the rotate schedule
only the updating filter can be gated; a clip only on the filter whose parameter is at u_max).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from reference_py.bank import (FILTER_BITS, STATUS_CLIPPED, STATUS_GATED, STATUS_INIT,
                               STATUS_REJECTED, FilterBank)
from reference_py.fmath import real_for
from reference_py.params import IDX, PRESETS
from reference_py.tools.estimate import make_config
from test_predict_only import (FILTER_STATUS_AT, PRESET, c_equals_reference, run_reference,
                               scenario)

SPIKE_N = 3.0        # far beyond the gate (12 sd of a 5 mN noise): the update is refused
SPIKE_EVERY = 97     # samples between spikes: never enough in a row to reopen the gate


def _spiked(f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The force with a spike every SPIKE_EVERY samples (from sample 50) and a NaN force at
    every fifth spike (a sample the estimator rejects); returns (force, spike mask)."""
    f = np.array(f, dtype=np.float64)
    spike = np.zeros(len(f), dtype=bool)
    spike[50::SPIKE_EVERY] = True
    f[spike] += SPIKE_N
    f[np.flatnonzero(spike)[::5]] = math.nan
    return f, spike


def _words(rows: list[tuple]) -> tuple[np.ndarray, np.ndarray]:
    st = np.array([r[7] for r in rows], dtype=np.uint32)
    fw = np.array([r[FILTER_STATUS_AT:FILTER_STATUS_AT + 3] for r in rows], dtype=np.uint32)
    return st, fw


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("model,schedule", [(1, "rotate"), (2, "all"), (2, "rotate"),
                                            (3, "all")])
def test_filter_words_c_equals_reference(precision, model, schedule):
    """C = reference at 0 ULP, the three words included; each word holds filter bits only,
    their OR is the status's filter bits; a rejected and the first sample carry none; every
    spike is gated by the filter(s) that updated at it."""
    t, d, v, f = scenario("p10_d50")
    f, spike = _spiked(f)
    rows = c_equals_reference(precision, model, schedule, False, False, math.nan, t, d, v, f,
                              np.zeros(len(t), dtype=np.int64))
    st, fw = _words(rows)
    assert not np.any(fw & ~np.uint32(FILTER_BITS))
    assert np.array_equal(st & np.uint32(FILTER_BITS), fw[:, 0] | fw[:, 1] | fw[:, 2])
    rejected = (st & STATUS_REJECTED) != 0
    assert rejected.sum() == np.isnan(f).sum() > 0
    assert not np.any(fw[rejected | ((st & STATUS_INIT) != 0)])
    gated = (fw & STATUS_GATED) != 0
    hit = spike & ~rejected
    if schedule == "all":
        # every filter updates at every sample: each one refuses the spike
        assert np.all(gated[hit]), np.flatnonzero(hit & ~gated.all(axis=1))[:5]
    else:
        # one filter updates per running sample (k mod 3, k counting them): it alone is gated
        k = np.cumsum(~rejected) - 2          # the first accepted sample is not a running one
        active = np.where(k >= 0, k % 3, -1)
        assert np.all(gated[hit, active[hit]])
        others = gated.copy()
        others[np.arange(len(k)), np.clip(active, 0, 2)] = False
        assert not np.any(others), "a filter that did not update was flagged gated"
    # outside the spikes the gate is as quiet as on the clean record (Model III gates a few
    # samples of its own after the reversals of this Model II record)
    clean = run_reference(precision, model, schedule, False, False, math.nan, t, d, v,
                          np.where(spike, f - SPIKE_N, f), np.zeros(len(t), dtype=np.int64))
    base = ((_words(clean)[1] & STATUS_GATED) != 0)[~spike].sum()
    assert gated[~spike].sum() <= base + 2    # measured: equal in every case


def test_clip_lands_on_the_filter_whose_parameter_is_at_the_clip():
    """A tight clip (u_max 0.05) and starts 3x off (sigma0 above, sigma2 below): CLIPPED
    appears, and only on a filter one of whose own parameters sits at |u| = u_max after the
    sample."""
    R = real_for("float64")
    p = PRESETS[PRESET]
    cfg = replace(make_config(p, 2, "default", "all"), u_max=0.05)
    start = list(p.params.as_list())
    start[IDX["sigma0"]] *= 3.0
    start[IDX["sigma2"]] /= 3.0
    bank = FilterBank(R, cfg, [start])
    t, d, v, f = scenario("p10_d50")
    flagged = np.zeros(3, dtype=int)
    for k in range(len(t)):
        o = bank.step(np.array([t[k]], dtype=np.int64), R.arr([d[k]]), R.arr([v[k]]),
                      R.arr([f[k]]))
        for i, names in enumerate(bank.subsets):
            if o.filter_status[i, 0] & STATUS_CLIPPED:
                flagged[i] += 1
                at_clip = [abs(float(bank.u[IDX[n]][0])) == 0.05 for n in names]
                assert any(at_clip), (k, i, names)
    assert flagged.sum() > 0, "the tight clip was never reached: the test shows nothing"


def test_node_health_frames_equal_the_mirror(tmp_path):
    """On the bus (nte-node --replay): two paper insertions, the robust estimator selected
    between them.  Every Health frame equals the mirror's (raw values, bit for bit); the bank's
    filter words reach the bus (some frame carries a flag); the refinement at the end of the
    second insertion is published as Refined with its confidence (Converged needs a second
    refinement that agrees with it)."""
    import json
    import subprocess

    import can

    from host_bench.node_mirror import NodeMirror
    from host_bench.node_outputs import health_outputs
    from reference_py.bus.candump import write_candump
    from test_node_port import DB, assert_node_equals_mirror, node_binary, two_insertions

    # 8.6 s at the surface after each insertion: the default refinement (one buffer entry a
    # sample, 1 710 samples) is adopted before the record ends
    frames, t_out = two_insertions(tmp_path, seed=3, rest_s=8.6)
    robust = DB.sender().message("Command", {"Reset": 0, "ModelSel": 0, "EstimatorSel": 2,
                                             "AdaptCmd": 0})
    log, rec, stats = tmp_path / "in.log", tmp_path / "out.log", tmp_path / "stats.json"
    write_candump(log, sorted(frames + [(t_out + 0.1, robust)], key=lambda e: e[0]), "vcan0",
                  1.0)
    r = subprocess.run([str(node_binary()), "--replay", str(log), "--record", str(rec),
                        "--stats", str(stats), "--model", "2", "--preset", "paper-10mms"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    sent = list(can.CanutilsLogReader(str(rec)))
    mirror = NodeMirror().feed_all(can.CanutilsLogReader(str(log)))
    assert mirror.estimator == "robust"
    assert_node_equals_mirror(sent, mirror)      # Health frames included
    healths, bad = health_outputs(DB, sent)
    st = json.loads(stats.read_text())
    assert bad == 0 and st["tx"]["health"] == len(healths)
    print(f"\n{st['tx']['estimate']} Estimate frames, {len(healths)} Health frames "
          f"({sum(any(h.filter_flags) for h in healths)} with a filter flag), refined at "
          f"confidence {[h.confidence_raw * 1e-4 for h in healths if h.refined]}")
    assert any(any(h.filter_flags) for h in healths), "no filter flag reached the bus"
    refined = [h for h in healths if h.refined]
    assert len(refined) == 1, [h.key() for h in refined]
    assert 0 < refined[0].confidence_raw <= 10000
    # a first refinement has no previous one to agree with: not yet CONVERGED (robust.py)
    assert refined[0].converged == 0
    # before the refinement nothing is refined or converged, and the confidence is 0
    first = healths.index(refined[0])
    assert not any(h.refined or h.converged or h.confidence_raw for h in healths[:first])
    # the fit ran in slices (Refining) from the end of the insertion to its adoption
    assert refined[0].refining == 1 and healths[first + 1].refining == 0
    assert any(h.refining and not h.refined for h in healths[:first])
