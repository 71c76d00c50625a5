"""The workflow on measured-like insertions (reference_py/MODEL.md §9 statistics, forms that are not the
library's: power-law tenting, Dahl pre-sliding over travel, a Maxwell element on the whole tissue
force; see discrepancy_measured_like.py): layers, relaxation, bounds, the base zero in the air,
the "unexplained" verdict, held-out validation and the measured-data path."""
from __future__ import annotations

import numpy as np
import pytest

from discrepancy_measured_like import make_case, make_trial, surface_of
from reference_py.discrepancy.evidence import collect, rupture_count
from reference_py.discrepancy.prep import prepare
from reference_py.discrepancy.report import bound_violations
from reference_py.discrepancy.workflow import run


@pytest.mark.parametrize("seed", range(2000, 2006))
def test_another_trial_keeps_the_condition(seed: int) -> None:
    """make_trial's ``trial`` (config_loop_figures part 6): the same tissue and noise level, the
    stage starting within 1.5 mm of the first trial's, the force leaving its tare where that
    surface says, the tears within 1.2 mm (4 sd) of the first trial's depth below the surface,
    and a noise draw of its own."""
    first, truth0, sigma0, n0 = make_trial(seed)
    other, truth1, sigma1, n1 = make_trial(seed, trial=1)
    assert (sigma1, n1) == (sigma0, n0)
    s0, s1 = surface_of(seed), surface_of(seed, 1)
    assert 0.0 < abs(s1 - s0) <= 1.5

    def tears(tr, truth, surface):
        rise = truth - truth[0]
        inside = tr.depth_mm > surface
        # nothing before the surface, a force once past it (membrane tenting or cutting)
        assert np.all(np.abs(rise[~inside & (tr.t_s < tr.t_s[np.argmax(inside)])]) == 0.0)
        assert np.max(rise[inside]) > 0.0
        drop = np.flatnonzero(np.diff(rise) < -0.15)
        drop = drop[np.diff(tr.depth_mm)[drop] > 0]
        return tr.depth_mm[drop] - surface
    d0, d1 = tears(first, truth0, s0), tears(other, truth1, s1)
    assert len(d0) == len(d1) == n0
    assert np.all(np.abs(d1 - d0) <= 1.2), (d0, d1)
    noise0 = first.force_n - truth0
    noise1 = other.force_n[:len(noise0)] - truth1[:len(noise0)]
    assert abs(np.corrcoef(noise0[:len(noise1)], noise1)[0, 1]) < 0.1


@pytest.mark.parametrize("seed", range(8))
def test_ruptures_counted_per_trial(seed: int) -> None:
    tr, _, _, n_layers = make_trial(1000 + seed)
    ev = collect([prepare(tr)])
    assert rupture_count(ev) == [n_layers]


@pytest.mark.parametrize("kind, form, at_least", [
    # the deepest membrane tears 0.6 mm before the stop, at speed (the old rule skipped the last
    # millimetre: 0 of 16)
    ("at the stop", {"stop_rupture_mm": 0.6}, 16),
    # a 500 Hz logger: the force is averaged over 30 ms, not 3 samples (3 samples: 14 of 16,
    # noise taken for drops)
    ("500 Hz", {"rate_hz": 500.0}, 16),
    # no rupture at 1 mm/s, where a decline of the force has longest to pass for a drop
    ("no layer, slow", {"n_layers": 0, "speed": 1.0}, 16),
    # a tear that runs on over half a millimetre at 1 mm/s: 0.5 s per drop, of which a 0.1 s
    # window sees a part (0.1 s alone: 8 of 16; a window in travel without the climb before it
    # took the slow decline of a blind-generator tissue for a tear)
    ("slow tear", {"speed": 1.0, "release_mm": 0.5, "rupture_scale": 0.5}, 15),
])
def test_ruptures_on_the_trials_own_scale(kind: str, form: dict, at_least: int) -> None:
    exact = 0
    for seed in range(1100, 1116):
        tr, _, _, n_layers = make_trial(seed, **form)
        exact += rupture_count(collect([prepare(tr)])) == [n_layers]
    assert exact >= at_least, f"{kind}: {exact}/16 trials with every rupture counted"


def test_a_sharp_tear_is_placed_between_its_two_samples() -> None:
    """The multi-layer base drops at once where the tip reaches the rupture depth, so the depth
    must lie between the last intact sample and the first torn one.  The averaged force peaks a
    sample early, and a depth taken there made the model drop two samples early: measured-like
    361 missed 5 N on two samples per tear, an insertion residual 58x the noise (8.9x placed
    between the samples).  Every tear of measured-like trials 1100-1115 (39): 0 placed right
    at the averaged peak, all 39 now."""
    placed = total = 0
    for seed in range(1100, 1116):
        tr, truth, _, _ = make_trial(seed)
        prep = prepare(tr)
        found = [r["depth_mm"] + prep.surface_mm
                 for r in collect([prep])["per_trial"][0]["ruptures"]]
        tears = np.flatnonzero((np.diff(truth) < -0.15) & (np.diff(tr.depth_mm) > 0))
        for i in tears:
            total += 1
            placed += any(tr.depth_mm[i] < d <= tr.depth_mm[i + 1] + 1e-9 for d in found)
    assert total == 39 and placed == total, (placed, total)


def test_four_evenly_spaced_layers_are_layers_and_a_sawtooth_is_not() -> None:
    """Four ruptures whose three intervals happen to come out even (measured-like 166, 272, 361:
    interval spread 0.091, 0.098, 0.075 of the mean) are layers: the rule that takes evenly
    spaced drops for an oscillation threw all four away (361's final residual 72x the noise,
    29x with them).  A stick-slip sawtooth with four drops (blind generator, stick_slip seed
    10, its second trial: spread 0.043) is still no layer, nor one with many drops."""
    from discrepancy_generator import make_case as blind_case
    for seed in (166, 272, 361):
        tr, _, _, n_layers = make_trial(seed)
        assert n_layers == 4
        assert rupture_count(collect([prepare(tr)])) == [4], seed
    stick = blind_case("stick_slip", 10).trials[1]
    assert rupture_count(collect([prepare(stick)])) == [0]
    many = blind_case("stick_slip", 1).trials[0]          # 17 drops, spread 0.033
    assert rupture_count(collect([prepare(many)])) == [0]


@pytest.fixture(scope="module")
def relaxing() -> tuple:
    case = make_case(4, trials=3)
    return case, run(case.trials)


def test_measured_like_relaxation_and_layers_named(relaxing: tuple) -> None:
    case, res = relaxing
    assert res.layers == case.layers
    assert "dwell_relaxation" in res.named and res.named[0] == "layer_puncture"
    assert bound_violations(res) == []


def test_base_is_zero_in_air_and_gap_shrinks(relaxing: tuple) -> None:
    case, res = relaxing
    for i, (p, pred) in enumerate(zip(res.preps, res.predictions[0])):
        surface = p.surface_mm + float(res.fits[0].nl["surface"][i])
        air = p.stage_mm <= surface
        assert air.sum() > 20 and np.max(np.abs(pred[air] - p.tare_n)) <= 1e-12
    base = np.sqrt(np.mean(np.concatenate([(a - b) ** 2 for a, b in
                                           zip(res.predictions[0], case.truth)])))
    final = np.sqrt(np.mean(np.concatenate([(a - b) ** 2 for a, b in
                                            zip(res.predictions[-1], case.truth)])))
    assert final <= 0.5 * base
    assert res.validation["shrink"] > 0.2


def test_local_dwell_evidence_survives_a_poor_base_fit() -> None:
    tr, truth, sig, _ = make_trial(4000, n_layers=3)
    ev = collect([prepare(tr)])
    d = ev["per_trial"][0]["dwells"][0]
    assert d["relative_decay"] > 0.05 and d["amplitude_over_noise"] > 4.0
    assert 0.05 <= d["tau_fast_s"] <= 1.5 and d["tau_slow_s"] <= 30.0


def test_unexplained_fires_on_stick_slip() -> None:
    case = make_case(7, trials=2, stick_slip=True, noise=0.01)
    res = run(case.trials, max_effects=2)
    assert res.unexplained and res.unexplained[0]["over_noise"] > 3.0


def test_velocity_friction_never_from_one_speed() -> None:
    case = make_case(9, trials=2, speed=2.0)
    res = run(case.trials, max_effects=2)
    assert "velocity_friction" not in res.named
    assert any(r.get("name") == "velocity_friction" for r in res.last_round) is False or all(
        r.get("rejected") for r in res.last_round if r.get("name") == "velocity_friction")


def test_realistic_phantom_layers_relaxation_and_shrink() -> None:
    """A record of the realistic phantom (sim/tissue.py: exponential tenting, Maxwell element
    on the engaged tissue, Dahl pre-sliding over stage travel): its two ruptures found, relaxation
    named, no parameter outside its bounds, the RMSE to the noise-free force shrinks by >= 50 %."""
    from discrepancy_measured_like import phantom_trial
    tr, truth, sig, n_layers = phantom_trial("skin-on-muscle", 1)
    res = run([tr])
    assert res.layers == [n_layers] and n_layers >= 1
    assert "dwell_relaxation" in res.named
    assert bound_violations(res) == []
    before = np.sqrt(np.mean((res.predictions[0][0] - truth) ** 2))
    after = np.sqrt(np.mean((res.predictions[-1][0] - truth) ** 2))
    assert after <= 0.5 * before and after <= 6.0 * sig


@pytest.mark.parametrize("relaxation", [True, False])
def test_a_memory_that_recovers_after_an_unloading_is_relaxation(relaxation: bool) -> None:
    # the stage backs off 0.4 mm as the dwell starts: a relaxing tissue's force then recovers
    # (rises), or rises and decays again (issue 22 item 6).  Without relaxation the same motion
    # must not name it.  The dwell gate reads only a fall (named 0/4); workflow._memory_gate
    # takes a transient either way, but only one the current model leaves in the dwell's
    # residual: the force alone also rises in the blind generator's pre-sliding dwells (dahl#2,
    # elastoplastic#1), where the base model explains it.
    named = []
    for seed in (70, 71, 72, 73):
        case = make_case(seed, trials=2, unload_mm=0.4, relaxation=relaxation)
        named.append("dwell_relaxation" in run(case.trials).named)
    assert named == [relaxation] * 4


def test_a_rank_deficient_fit_stays_bounded() -> None:
    """Measured-like seed 38 (three trials): a held-out fit whose columns are nearly collinear
    on the fitted rows.  The bounded solve must cut the near-null directions as a least-squares
    solve over the samples does; a reduced k x k system keeps them (numpy's cut-off scales with
    the row count) and its predictions went 10^3..10^8 N astray off the fitted rows -- two
    faster solves tried this stop did, so this guards the next one.  The reduced solve that
    carries the tall cut-off over (fit.solve_bounded) found a second way astray here: a surface
    correction that leaves trial 2's first layer one fitting row thick (u = 8e-4), fitted there
    by k2 = 1.5e6 N (RMSE to truth 1.9e4 N); a layer's k1, k2 are now at most the trial's
    largest force (measured: 0.30 -> 0.15 N)."""
    from discrepancy_measured_like import grade
    r = grade(38, trials=3)
    assert r["truth_before"] < 1.0 and r["truth_after"] < 0.5 * r["truth_before"] + 0.05, r
