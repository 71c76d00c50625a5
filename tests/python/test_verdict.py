"""The closing verdict of nte-ref estimate (reference_py/tools/verdict.py): the innovation RMS in
tissue against the sensor's noise, measured at rest or given, the share of gated updates, and
whether the model follows the file; the predict-only and no-tissue lines; the warning on a start
far off; the robust estimator's refinement appended; the header of the final estimates.

Every number of the line is recomputed here from the estimate file and the input with numpy,
and the whole line compared to the character (the format is nte-run's contract too)."""
from __future__ import annotations

import csv
import json
import math
import random
import re
from pathlib import Path

import numpy as np
import pytest

from reference_py.params import PARAM_NAMES, PRESETS
from reference_py.tools.cli import main
from reference_py.tools.verdict import rest_noise, verdict

from estimate_run import estimate

NOT_IN_TISSUE = (1 << 0) | (1 << 1) | (1 << 5) | (1 << 13)
GATED = 1 << 2


def judged(capsys, src: Path, out: Path, *flags: str) -> list[str]:
    """The stdout lines of an estimate that runs without a warning, its verdict checked
    against the numpy recomputation."""
    rc, so, se = estimate(capsys, src, out, *flags)
    assert rc == 0 and se == [], se
    assert so[-1] == expected_line(src, out)
    return so


def expected_line(src: Path, est: Path, noise_n: float | None = None) -> str:
    """The verdict recomputed with numpy from the input and the estimate file."""
    inp = np.genfromtxt(src, delimiter=",", names=True)
    e = np.genfromtxt(est, delimiter=",", names=True)
    st = e["status"].astype(np.int64)
    inside = (st & NOT_IN_TISSUE) == 0
    r = float(np.sqrt(np.mean(e["innovation_n"][inside] ** 2)))
    g = 100.0 * np.count_nonzero(st[inside] & GATED) / np.count_nonzero(inside)
    head = f"verdict: innovation RMS {1000 * r:.3g} mN"
    tail = f"; gated {g:.1f} % of updates; "
    if noise_n is None:
        d = inp["depth_mm"]
        n = int(np.argmax(np.abs(d - d[0]) > 0.01))
        if n < 20:
            return head + tail + "noise unknown (no rest before the stage moves): give --noise N"
        s, src_text = float(np.std(inp["force_n"][:n], ddof=1)), \
            f"measured in the first {n} samples at rest"
    else:
        s, src_text = noise_n, "given by --noise"
    k = r / s
    concl = ("the model follows this file" if k <= 5 else
             f"the model does not fit this file ({k:.1f}x the noise): see nte-discrepancy")
    return f"{head} = {k:.1f}x the noise ({1000 * s:.3g} mN, {src_text}){tail}{concl}"


def factor(line: str) -> float:
    m = re.search(r" = ([0-9.]+)x the noise \(", line)
    assert m, line
    return float(m.group(1))


# -- the phantom: Model III against Model II on the same record --------------------------------

@pytest.fixture(scope="module")
def lab(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("verdict_lab")
    assert main(["phantom", "lab", "--seed", "3", "--out", str(d / "lab3.csv")]) == 0
    return d / "lab3.csv"


def test_the_phantom_model3_near_the_bound_model2_far_off(lab, tmp_path, capsys):
    """Measured on nte-ref phantom lab --seed 3 (noise 9.46 mN measured in the first 104
    samples at rest; the phantom's own 9.10 mN): Model III 40.4 mN = 4.3x the noise, the
    ruptures of the layers making most of it (50.4 mN = 5.3x before a tear's sample restarted
    the filters' covariances and moved z alone); Model II, which has neither relaxation nor
    layers nor the front end (the air gap counts as tissue), 583 mN = 61.7x.  Model III is
    within the bound of 5, so its line says the model follows the file; Model II's does not."""
    lines = {}
    for model in (3, 2):
        lines[model] = judged(capsys, lab, tmp_path / f"m{model}.csv", "--model",
                              str(model))[-1]
    assert "(9.46 mN, measured in the first 104 samples at rest)" in lines[3]
    k3, k2 = factor(lines[3]), factor(lines[2])
    assert k3 == pytest.approx(4.3, abs=0.3)
    assert lines[3].endswith("the model follows this file")
    assert k2 == pytest.approx(61.7, rel=0.05)
    assert k2 > 10 * k3
    assert lines[2].endswith(f"the model does not fit this file ({k2:.1f}x the noise): see "
                             f"nte-discrepancy")


# -- a record the model follows ----------------------------------------------------------------

@pytest.fixture(scope="module")
def fits(tmp_path_factory) -> Path:
    """A Model II record of needleB-tissueB-10mms (2 mN noise) led by 40 samples at rest."""
    d = tmp_path_factory.mktemp("verdict_fits")
    sim = d / "sim.csv"
    assert main(["simulate", "--preset", "needleB-tissueB-10mms", "--depth", "20", "--dwell",
                 "0.5", "--rate", "100", "--out", str(sim)]) == 0
    rng = random.Random(2)
    src = d / "rest.csv"
    with open(src, "w") as fh:
        fh.write("t_s,depth_mm,force_n\n")
        for k in range(40):
            fh.write("%r,0,%r\n" % (k * 0.01, rng.gauss(0.0, 0.002)))
        for r in csv.DictReader(open(sim)):
            fh.write("%r,%s,%s\n" % (float(r["t_s"]) + 0.4, r["depth_mm"], r["force_n"]))
    return src


def test_a_record_the_model_follows(fits, tmp_path, capsys):
    so = judged(capsys, fits, tmp_path / "e.csv", "--model", "2", "--preset",
                "needleB-tissueB-10mms")
    assert so[-1].endswith("; the model follows this file")
    assert factor(so[-1]) == pytest.approx(1.3, abs=0.3)          # measured: 1.3
    # the header says whose estimates they are, each parameter with its filter (Table I)
    assert so[0] == (f"{40 + 491} samples, Model II, float64; final estimates (± 1 sd): the "
                     f"bank's shared model at the last sample, each parameter as the filter that "
                     f"owns it (Table I) left it:")
    owners = {"sigma0": 1, "f1": 2, "sigma1": 2, "beta": 3, "sigma2": 3}
    for line in so[1:6]:
        name = line.split()[0]
        assert line.endswith(f"(filter {owners[name]})"), line


def test_the_robust_estimator_appends_its_refinement(fits, tmp_path, capsys):
    out = tmp_path / "e.csv"
    rc, so, _ = estimate(capsys, fits, out, "--model", "2", "--preset",
                         "needleB-tissueB-10mms", "--estimator", "robust")
    assert rc == 0
    e = np.genfromtxt(out, delimiter=",", names=True)
    conv = "converged" if int(e["status"][-1]) & (1 << 10) else "not converged"
    assert so[-1] == (expected_line(fits, out) + f"; robust refinement: confidence "
                                                  f"{e['confidence'][-1]:.3g}, {conv}")


def test_a_start_far_off_is_warned(fits, tmp_path, capsys):
    """Measured: start factors drawn with seed 1 within 100x are 193x the noise off in the
    first 2 s in tissue."""
    out = tmp_path / "e.csv"
    rc, so, se = estimate(capsys, fits, out, "--model", "2", "--init-seed", "1",
                          "--init-factor", "100")
    assert rc == 0 and so[-1] == expected_line(fits, out)
    e = np.genfromtxt(out, delimiter=",", names=True)
    inside = (e["status"].astype(np.int64) & NOT_IN_TISSUE) == 0
    t, inn = e["t_s"][inside], e["innovation_n"][inside]
    first = t <= t[0] + 2.0
    s = rest_noise(np.genfromtxt(fits, delimiter=",", names=True)["depth_mm"],
                   np.genfromtxt(fits, delimiter=",", names=True)["force_n"])
    assert s is not None
    k2 = float(np.sqrt(np.mean(inn[first] ** 2))) / s.sd_n
    assert k2 > 20
    assert se == [f"warning: the first 2 s in tissue are {k2:.0f}x the noise off the start: "
                  f"set it with --preset, --start or --config"]


# -- the other forms ------------------------------------------------------------------------

def test_no_rest_no_noise(tmp_path, capsys):
    sim = tmp_path / "sim.csv"
    assert main(["simulate", "--preset", "needleB-tissueB-10mms", "--depth", "10", "--dwell",
                 "0.2", "--rate", "100", "--out", str(sim)]) == 0
    so = judged(capsys, sim, tmp_path / "e.csv", "--model", "2", "--preset",
                "needleB-tissueB-10mms")
    assert so[-1].endswith("; noise unknown (no rest before the stage moves): give --noise N")


def test_no_sample_in_tissue(tmp_path, capsys):
    src = tmp_path / "air.csv"
    src.write_text("t_s,depth_mm,force_n\n" + "".join(f"{k * 0.01!r},0,0.001\n"
                                                       for k in range(50)))
    rc, so, _ = estimate(capsys, src, tmp_path / "e.csv", "--model", "2")
    assert rc == 0
    assert so[-1] == "verdict: no sample in tissue: no verdict"


def test_predict_only(fits, tmp_path, capsys):
    cfg = tmp_path / "c.json"
    p = PRESETS["needleB-tissueB-10mms"].params
    cfg.write_text(json.dumps({"schema": "nte-estimator-config/1", "model": 2,
                               "params": dict(zip(PARAM_NAMES, p.as_list()))}))
    rc, so, _ = estimate(capsys, fits, tmp_path / "e.csv", "--config", str(cfg),
                         "--predict-only")
    assert rc == 0
    assert so[-1] == "verdict: predict-only, the force was not read: no verdict"


# -- the arithmetic, on hand-made runs -------------------------------------------------------

def hand_run(n_rest: int, rest_sd: float = 0.002, inn_n: float = 0.004, seed: int = 0):
    rng = np.random.default_rng(seed)
    n = n_rest + 300
    t = np.arange(n) * 0.01
    depth = np.concatenate([np.zeros(n_rest), 0.02 + 0.1 * np.arange(300)])
    force = np.concatenate([rng.normal(0.0, rest_sd, n_rest), np.ones(300)])
    inn = np.where(np.arange(n) % 2 == 0, inn_n, -inn_n)
    status = np.zeros(n, dtype=np.uint32)
    status[:n_rest] = 1 << 5
    status[0] |= 1
    return t, depth, force, inn, status


def test_noise_measured_and_given():
    t, d, f, inn, st = hand_run(30)
    v = verdict(t, d, f, inn, st)
    sd = float(np.std(f[:30], ddof=1))
    k = 0.004 / sd
    assert k <= 5
    assert v.line == (f"verdict: innovation RMS 4 mN = {k:.1f}x the noise ({1000 * sd:.3g} mN, "
                      f"measured in the first 30 samples at rest); gated 0.0 % of updates; "
                      f"the model follows this file")
    given = verdict(t, d, f, inn, st, noise_n=0.0005)
    assert given.line == ("verdict: innovation RMS 4 mN = 8.0x the noise (0.5 mN, given by "
                          "--noise); gated 0.0 % of updates; the model does not fit this file "
                          "(8.0x the noise): see nte-discrepancy")
    # given, the noise needs no rest
    t, d, f, inn, st = hand_run(5)
    assert verdict(t, d, f, inn, st).line.endswith("noise unknown (no rest before the stage "
                                                   "moves): give --noise N")
    assert "(2 mN, given by --noise)" in verdict(t, d, f, inn, st, noise_n=0.002).line


def test_rest_ends_where_the_depth_leaves_it_by_more_than_10_um():
    d = np.array([0.0] * 25 + [0.0105] + [1.0] * 10)
    f = np.arange(36.0)
    got = rest_noise(d, f)
    assert got is not None and got.source == "measured in the first 25 samples at rest"
    assert got.sd_n == pytest.approx(float(np.std(f[:25], ddof=1)), rel=1e-15)
    d[19] = 0.011                                             # only 19 before it: unknown
    assert rest_noise(d, f) is None
    d[19] = 0.01                                              # 0.01 mm is still at rest
    assert rest_noise(d, f) is not None


def test_the_bound_gated_share_and_the_start():
    # 2^-7 N against 2^-7 / 5 N: K is 5.0 to the bit, on the bound (binary fractions: exact)
    t, d, f, inn, st = hand_run(30, inn_n=0.0078125)
    st[30:60] |= 1 << 2                                        # 30 of 300 in tissue gated
    st[30:40] |= 1 << 6                                        # other bits do not matter
    v = verdict(t, d, f, inn, st, noise_n=0.0015625)
    assert v.line == ("verdict: innovation RMS 7.81 mN = 5.0x the noise (1.56 mN, given by "
                      "--noise); gated 10.0 % of updates; the model follows this file")
    assert v.warning is None
    inn2 = inn.copy()
    inn2[30:240] *= 5.0                                         # 25x over the first 2 s
    v = verdict(t, d, f, inn2, st, noise_n=0.0015625)
    assert v.warning == ("warning: the first 2 s in tissue are 25x the noise off the start: "
                         "set it with --preset, --start or --config")
    assert math.isclose(factor(v.line), float(np.sqrt(np.mean(inn2[30:] ** 2))) / 0.0015625,
                        abs_tol=0.05)


def test_robust_suffix_and_predict_only_and_no_tissue_forms():
    t, d, f, inn, st = hand_run(30)
    st[-1] |= 1 << 10
    assert verdict(t, d, f, inn, st, noise_n=0.002, confidence=0.81234).line.endswith(
        "; the model follows this file; robust refinement: confidence 0.812, converged")
    st[-1] &= ~np.uint32(1 << 10)
    assert verdict(t, d, f, inn, st, noise_n=0.002, confidence=0.5).line.endswith(
        "; robust refinement: confidence 0.5, not converged")
    assert verdict(t, d, f, inn, st, predict_only=True).line == \
        "verdict: predict-only, the force was not read: no verdict"
    st[:] = 1 << 5
    assert verdict(t, d, f, inn, st).line == "verdict: no sample in tissue: no verdict"


def test_a_noise_free_rest_measures_no_noise():
    """A simulated record without noise rests at exactly one force: no noise to judge by
    (not a division by zero), so the verdict asks for --noise."""
    from reference_py.tools.verdict import rest_noise, verdict
    depth = np.concatenate([np.zeros(30), np.linspace(0.1, 5.0, 50)])
    force = np.concatenate([np.full(30, 0.25), np.linspace(0.3, 2.0, 50)])
    assert rest_noise(depth, force) is None
    line = verdict(np.arange(80) * 0.01, depth, force, np.full(80, 0.01),
                   np.zeros(80, dtype=np.uint32)).line
    assert line.endswith("noise unknown (no rest before the stage moves): give --noise N"), line
