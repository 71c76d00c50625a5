"""Held parameters at run time (nte.h HELD PARAMETERS; nte_set_frozen and reference_py
FilterBank.set_frozen, the Command frame's AdaptCmd freeze / resume on the node): C = reference
bit for bit with the freeze switched on and off between samples, the parameters stand still
while z keeps following the force, and they adapt again after the resume.

The C side is tests/c/nte_switch_replay.c (mode bit 2: held), shared with test_predict_only.py.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from reference_py.bank import STATUS_FROZEN, STATUS_PREDICT_ONLY
from reference_py.robust import STATUS_REFINED, RobustConfig
from test_node_port import paper_frames  # noqa: F401  (the fixture: a 3.5 s paper insertion)
from test_predict_only import PARAMS_AT, c_equals_reference, run_reference, scenario, switch_mode

HELD = 2          # nte_switch_replay's mode bit for nte_set_frozen
PREDICT_ONLY = 1

CASES = [  # (model, schedule, robust, spans) on p10_d50; Model III on the phantom below
    (2, "all", False, [(0.30, 0.55)]),
    (1, "rotate", False, [(0.20, 0.35), (0.60, 0.80)]),
    (2, "rotate", False, [(0.0, 0.1), (0.5, 1.0)]),
    (3, "all", False, [(0.25, 0.60)]),
    (2, "all", True, [(0.40, 0.50)]),
]


def _params(rows: list[tuple]) -> np.ndarray:
    return np.array([r[PARAMS_AT::2] for r in rows])


def _runs(mask: np.ndarray) -> list[np.ndarray]:
    on = np.flatnonzero(mask)
    return [r for r in np.split(on, np.flatnonzero(np.diff(on) > 1) + 1) if len(r)]


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("model,schedule,robust,spans", CASES)
def test_freeze_mid_run_c_equals_reference(precision, model, schedule, robust, spans):
    """nte_set_frozen on and off mid-record: every output of every sample of C = reference
    at 0 ULP; the held samples carry STATUS_FROZEN and not PREDICT_ONLY, no parameter moves
    while held (bit for bit), z does, and the parameters move again after the resume."""
    t, d, v, f = scenario("p10_d50")
    mode = switch_mode(len(t), spans) * HELD
    ref = c_equals_reference(precision, model, schedule, False, robust, math.nan, t, d, v,
                             np.asarray(f, dtype=np.float64), mode)
    st = np.array([r[7] for r in ref])
    held = mode == HELD
    assert np.all(((st & STATUS_FROZEN) != 0) == held)
    assert not np.any(st & STATUS_PREDICT_ONLY)
    p, z = _params(ref), np.array([r[1] for r in ref])
    inside = np.asarray(d) > 0
    for r in _runs(held):
        if r[0] > 0:
            assert np.array_equal(p[r[0] - 1], p[r[-1]]), "a held parameter moved"
        if np.count_nonzero(inside[r]) > 10:
            assert np.ptp(z[r][inside[r]]) > 0.0, "z stood still while held"
    # after the resume the filters learn again (Model I/II/III on the paper record: their
    # parameters move within the next 50 samples in the tissue)
    after = np.flatnonzero(~held & inside & (np.arange(len(t)) > _runs(held)[0][-1]))
    if len(after) > 50:
        assert not np.array_equal(p[after[0] - 1], p[after[50]])


def test_held_parameters_still_track_the_force():
    """Held from 40 % of the paper record to its end: the published force still follows the
    measured one through z (one-step innovation RMS within 1.5x that of the adapting run's in
    the same samples in the tissue), and the identified values are those of the freeze's start
    -- unlike predict-only, which reads no force: its innovation is the whole force."""
    t, d, v, f = scenario("p10_d50")
    n = len(t)
    out = {}
    for name, bit in (("adapting", 0), ("held", HELD), ("predict-only", PREDICT_ONLY)):
        mode = np.zeros(n, dtype=np.int64)
        mode[int(0.4 * n):] = bit
        out[name] = run_reference("float64", 2, "all", False, False, math.nan, t, d, v,
                                  np.asarray(f, dtype=np.float64), mode)
    k0 = int(0.4 * n)
    sel = (np.arange(n) > k0 + 5) & (np.asarray(d) > 0)

    def rms_innovation(rows: list[tuple]) -> float:
        return float(np.sqrt(np.mean(np.array([r[2] for r in rows])[sel] ** 2)))

    forces = np.abs(np.asarray(f))[sel]
    a, h = rms_innovation(out["adapting"]), rms_innovation(out["held"])
    print(f"\ninnovation RMS after 40 %: adapting {1e3 * a:.2f} mN, held {1e3 * h:.2f} mN "
          f"(force up to {float(forces.max()):.3f} N)")
    assert h <= 1.5 * a, (h, a)
    held = _params(out["held"])
    assert np.all(held[k0:] == held[k0 - 1])
    assert not np.array_equal(_params(out["adapting"])[k0 - 1], _params(out["adapting"])[-1])


def _rest_after(t_us, depth, vel, force, samples: int):
    """The record, then `samples` more at its last row (the needle resting at the surface),
    the time going on by its last interval: long enough for the default refinement (one
    buffer entry a sample) to be adopted."""
    step = int(t_us[-1] - t_us[-2])
    tail = np.int64(t_us[-1]) + step * np.arange(1, samples + 1, dtype=np.int64)

    def held(a):
        return np.concatenate([np.asarray(a), np.repeat(np.asarray(a)[-1:], samples)])
    return (np.concatenate([np.asarray(t_us, dtype=np.int64), tail]), held(depth), held(vel),
            held(force))


def test_a_held_insertion_is_not_refined():
    """The robust estimator: an insertion during which the parameters were held is neither
    recorded nor refined (its refinement would move them); the same record without the freeze
    is refined at its end."""
    t, d, v, f = _rest_after(*scenario("p10_d50"), RobustConfig().slices() + 10)
    n = len(t)
    status = {}
    for name, spans in (("free", []), ("held", [(0.30, 0.35)])):
        mode = switch_mode(n, spans) * HELD
        rows = run_reference("float64", 2, "all", False, True, math.nan, t, d, v,
                             np.asarray(f, dtype=np.float64), mode)
        status[name] = np.array([r[7] for r in rows])
    assert np.any(status["free"] & STATUS_REFINED)
    assert not np.any(status["held"] & STATUS_REFINED)


def test_node_freezes_and_resumes_mid_insertion(tmp_path, paper_frames) -> None:
    """On the node (nte-node --replay, Model II, a paper insertion): AdaptCmd freeze at 1.5 s
    and resume at 2.5 s, both in the tissue: both applied, every Estimate and Params frame the
    mirror's (reference_py's FilterBank with set_frozen), the published parameters constant
    while held and moving again after the resume, Adapting 0 exactly while held."""
    import can

    from host_bench.node_mirror import NodeMirror
    from test_node_port import DB, assert_node_equals_mirror, replay_node_args

    tx = DB.sender()

    def cmd(adapt: int):
        return tx.message("Command", {"Reset": 0, "ModelSel": 0, "EstimatorSel": 0,
                                      "AdaptCmd": adapt})

    merged = sorted(paper_frames + [(1.5, cmd(1)), (2.5, cmd(2))], key=lambda e: e[0])
    sent, st = replay_node_args(tmp_path, merged, "freeze",
                                ["--model", "2", "--preset", "paper-10mms"])
    assert st["commands_applied"] == 2 and st["events"]["command_refused"] == 0
    # the mirror reads what the node read, with the port clock (the log's times)
    mirror = NodeMirror().feed_all(can.CanutilsLogReader(str(tmp_path / "freeze.in.log")))
    assert_node_equals_mirror(sent, mirror)
    rx = DB.receiver()
    adapting, in_tissue, params = [], [], []      # params: (estimates before it, index, value)
    for m in sent:
        name, sig = rx.decode_strict(m.arbitration_id, bytes(m.data))
        if name == "Estimate":
            adapting.append(sig["Adapting"])
            in_tissue.append(sig["InTissue"])
        elif name == "Params":
            value = [v for k, v in sig.items()
                     if k not in ("Crc", "Counter", "ParamIndex") and "Std" not in k]
            params.append((len(adapting), int(sig["ParamIndex"]), value[0]))
    held = np.flatnonzero(np.array(adapting) == 0)
    assert len(held) > 100 and np.all(np.diff(held) == 1), "held in one stretch"
    assert all(in_tissue[held[0]:held[-1] + 1])

    def distinct(lo: int, hi: int) -> dict[int, set]:
        out: dict[int, set] = {}
        for k, idx, v in params:
            if lo < k <= hi:
                out.setdefault(idx, set()).add(v)
        return out

    while_held = distinct(held[0] + 1, held[-1] + 1)
    assert while_held and all(len(v) == 1 for v in while_held.values()), while_held
    after = distinct(held[-1] + 1, held[-1] + 200)
    assert any(len(v) > 1 for v in after.values()), "no parameter moved after the resume"
