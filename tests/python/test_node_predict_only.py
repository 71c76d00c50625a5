"""The node's predict-only mode (nte_node.h PREDICT-ONLY) through nte-node --replay, against
the mirror (host_bench/node_mirror.py) bit for bit: a Command ForceSource switching to the model
mid-insertion and back, a SensorFault stretch, a lost sensor; and on a Model III phantom record
the prediction after a sensor fault from mid-insertion to the end, measured against the
fault-free estimate."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import can
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from host_bench.cli import sensor_failures  # noqa: E402
from host_bench.replay import scenario_frames  # noqa: E402
from reference_py.bus.candump import write_candump  # noqa: E402
from reference_py.bus.dbc import NteDatabase  # noqa: E402
from host_bench.node_mirror import NodeMirror  # noqa: E402
from host_bench.node_outputs import compare, contact_outputs, node_outputs  # noqa: E402

DB = NteDatabase()

#: the Model III phantom (lab, seed 101), sensor flagged faulty from mid-insertion (7.30 s, 6 mm
#: below the surface) to the end: the model's prediction against the fault-free estimate over
#: the fault while in the tissue (1631 estimates).  Measured 2026-11-24: RMS 1.92 N, largest
#: 4.21 N, peak force 4.70 N (against the true force: fault-free 0.14 N RMS, predicted 1.93 N).
#: The parameters identified after 6 mm of tissue make a poor predictor of this phantom (its
#: ruptures and layers are not the model's): within 0.7 s the prediction falls to a third of
#: the estimate while z goes to its steady state (sigma0 0.006, sigma1 8.2: the force was mostly
#: the transient term).  The bounds are the measurement with 10 % margin: they catch a
#: prediction that diverges or vanishes, not a good one.  On a record of the model's own
#: (tests/python/test_predict_only.py) the prediction is within 7 mN RMS.
PHANTOM_RMS_MAX_N = 2.1
PHANTOM_ABS_MAX_N = 4.65
#: the switch keeps the state: over the first 50 ms of the fault the prediction stays this close
#: (measured 0.38 N: the fault starts while the membrane tents at about 6 N/s, 60 ms before it
#: tears, so the fault-free estimate rises 0.3 N in those 50 ms and the model's prediction
#: rises more slowly; a switch that lost z or the memories would jump by the force, 3 N)
PHANTOM_FIRST_50MS_MAX_N = 0.45


def node_binary() -> Path:
    for c in (ROOT / "build/host/bin/nte-node", ROOT / "build/node/bin/nte-node"):
        if c.exists():
            return c
    pytest.skip("nte-node not built (cmake --build build/host)")


def replay(tmp_path: Path, frames: list, tag: str, args: list[str]):
    """nte-node --replay on `frames`: (frames it sent, its counters, the input log)."""
    log, rec, stats = (tmp_path / f"{tag}.in.log", tmp_path / f"{tag}.out.log",
                       tmp_path / f"{tag}.stats.json")
    write_candump(log, frames, "vcan0", 1.0)
    r = subprocess.run([str(node_binary()), "--replay", str(log), "--record", str(rec),
                        "--stats", str(stats), *args], capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr
    return list(can.CanutilsLogReader(str(rec))), json.loads(stats.read_text()), log


def assert_equal_to_mirror(sent: list, mirror: NodeMirror, with_contact: bool = False) -> dict:
    est, par, bad = node_outputs(DB, sent)
    contacts = contact_outputs(DB, sent)[0] if with_contact else None
    res = compare(mirror, est, par, contacts)
    assert bad == 0
    assert res["estimates_node"] == res["estimates_reference"] > 0
    assert res["estimate_mismatches"] == 0, res["first_mismatch"]
    assert res["params_node"] == res["params_reference"]
    assert res["param_value_mismatches"] == 0
    assert res["param_std_beyond_1lsb"] == 0
    if with_contact:
        assert res["contact_node"] == res["contact_reference"] > 0
        assert res["contact_mismatches"] == 0
    return res


def test_replay_model2_switches_equal_mirror(tmp_path: Path) -> None:
    """Model II, one insertion (50 mm at 10 mm/s, 1 s dwell): ForceSource model at 2.0 s and
    sensor at 3.0 s (in tissue: accepted), SensorFault on 4.0-4.5 s, the sensor lost 5.5-6.0 s:
    every Estimate and Params frame of the node equals the mirror's, and so do the counters."""
    csv = tmp_path / "paper.csv"
    subprocess.run([sys.executable, "-m", "reference_py", "simulate", "--preset", "paper-10mms",
                    "--depth", "50", "--dwell", "1", "--seed", "1", "--out", str(csv)],
                   check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    frames = scenario_frames(str(csv), DB, 1000.0)
    frames = sensor_failures(frames, DB, [(2.0, "model"), (3.0, "sensor")], [(4.0, 4.5)],
                             [(5.5, 6.0)])
    sent, st, log = replay(tmp_path, frames, "m2", ["--model", "2", "--preset", "paper-10mms"])
    mirror = NodeMirror().feed_all(can.CanutilsLogReader(str(log)))   # with the port clock
    assert_equal_to_mirror(sent, mirror)
    assert st["commands_applied"] == 2 and st["events"]["command_refused"] == 0
    assert {k: st[k] for k in mirror.predict_counts} == mirror.predict_counts
    assert st["predict_on"] == st["predict_off"] == 3
    assert st["predict_depth_steps"] > 50            # 0.5 s lost, less the 50 ms timeout
    est = node_outputs(DB, sent)[0]
    assert sum(1 - e.adapting for e in est) > 200 + 100 + 50
    assert all(e.innovation_raw == 0 for e in est if not e.adapting and not e.stale)
    print(f"\nModel II switches: {len(est)} Estimates, {sum(1 - e.adapting for e in est)} "
          f"predicted, counters {mirror.predict_counts}")


@pytest.fixture(scope="module")
def phantom(tmp_path_factory: pytest.TempPathFactory):
    work = tmp_path_factory.mktemp("po_phantom")
    csv = work / "lab101.csv"
    subprocess.run([str(ROOT / ".venv/bin/nte-ref"), "phantom", "lab", "--seed", "101",
                    "--out", str(csv)], check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    return csv, json.loads((work / "lab101.truth.json").read_text())


def test_model3_phantom_sensor_fault_prediction(tmp_path: Path, phantom) -> None:
    """Model III (contact front end) on the phantom, every Force frame flagged SensorFault from
    mid-insertion to the end of the record: node = mirror bit for bit (Contact frames too),
    and the prediction stays within PHANTOM_RMS_MAX_N (RMS) and PHANTOM_ABS_MAX_N (largest) of
    the fault-free estimate over the fault while in the tissue."""
    csv, truth = phantom
    cyc = truth["cycles"][0]
    t_fault = 0.5 * (cyc["start_s"] + cyc["insertion_end_s"])
    args = ["--model", "3", "--preset", "paper-10mms"]
    clean = scenario_frames(str(csv), DB, 1000.0)
    faulty = sensor_failures(clean, DB, faults=[(t_fault, clean[-1][0] + 1.0)])
    sent, st, log = replay(tmp_path, faulty, "m3f", args)
    mirror = NodeMirror(model=3).feed_all(can.CanutilsLogReader(str(log)))
    assert_equal_to_mirror(sent, mirror, with_contact=True)
    assert st["predict_on"] == 1 and st["predict_off"] == 0
    sent0, _, _ = replay(tmp_path, clean, "m3c", args)
    e1, e0 = node_outputs(DB, sent)[0], node_outputs(DB, sent0)[0]
    assert len(e1) == len(e0)
    f1 = np.array([e.force_raw for e in e1]) * 1e-4
    f0 = np.array([e.force_raw for e in e0]) * 1e-4
    pred = np.array([not e.adapting for e in e1])
    inside = pred & np.array([bool(e.in_tissue) for e in e0])
    assert inside.sum() > 100
    d = f1[inside] - f0[inside]
    rms, worst, peak = float(np.sqrt(np.mean(d * d))), float(np.max(np.abs(d))), \
        float(np.max(np.abs(f0)))
    # against the truth (force_true_n, the phantom's force less nothing: the estimates are
    # tare-free) over the same samples, for scale
    import csv as _csv
    with open(csv) as fh:
        rows = list(_csv.DictReader(fh))
    t_true = np.array([float(r["t_s"]) for r in rows])
    f_true = np.array([float(r["force_true_n"]) for r in rows])
    force_id = DB.frame_id("Force")
    t_force = np.array([t for t, m in clean if m.arbitration_id == force_id])
    # the last force sample has no depth after it: never decided, no Estimate
    assert len(t_force) - 1 <= len(e0) <= len(t_force)
    t_force = t_force[:len(e0)]
    ft = np.interp(t_force[inside], t_true, f_true)
    rms_true_clean = float(np.sqrt(np.mean((f0[inside] - ft) ** 2)))
    rms_true_pred = float(np.sqrt(np.mean((f1[inside] - ft) ** 2)))
    print(f"\nModel III phantom lab-101, SensorFault from {t_fault:.2f} s to the end "
          f"({int(inside.sum())} predicted estimates in the tissue): prediction - fault-free "
          f"estimate RMS {rms:.3f} N, largest {worst:.3f} N (peak force {peak:.2f} N); "
          f"RMS against the true force: fault-free {rms_true_clean:.3f} N, "
          f"predicted {rms_true_pred:.3f} N")
    assert rms <= PHANTOM_RMS_MAX_N and worst <= PHANTOM_ABS_MAX_N, (rms, worst)
    first = pred & (t_force < t_fault + 0.05)
    early = float(np.max(np.abs(f1[first] - f0[first])))
    print(f"first 50 ms of the fault: largest difference {early:.3f} N")
    assert first.sum() >= 3 and early <= PHANTOM_FIRST_50MS_MAX_N
    # the prediction stays a force of the tissue: positive while going in, finite, bounded
    assert np.all(np.isfinite(f1)) and np.all(np.abs(f1) <= 50.0)


def test_bench_options_build_the_failures(tmp_path: Path) -> None:
    """nte-bench replay --force-source / --sensor-fault / --sensor-lost: parsed (bad values
    refused, exit 2), and sensor_failures builds the frames: Force frames in the fault span
    flagged (value kept, CRC valid), those of the lost span gone, one Command per time with
    counters 0, 1, ... and ForceSource 2 / 1; frames without a failure unchanged."""
    from host_bench.cli import build_parser
    p = build_parser()
    a = p.parse_args(["replay", "x.csv", "--out", str(tmp_path / "o"), "--force-source",
                      "2:model", "--force-source", "3.5:sensor", "--sensor-fault", "4:4.5",
                      "--sensor-lost", "5:5.5"])
    assert a.force_source == [(2.0, "model"), (3.5, "sensor")]
    assert a.sensor_fault == [(4.0, 4.5)] and a.sensor_lost == [(5.0, 5.5)]
    for bad in (["--force-source", "2:nope"], ["--force-source", "x:model"],
                ["--sensor-fault", "5:4"], ["--sensor-lost", "-1:2"]):
        with pytest.raises(SystemExit) as e:
            p.parse_args(["replay", "x.csv", "--out", "o", *bad])
        assert e.value.code == 2
    csv = tmp_path / "s.csv"
    csv.write_text("t_s,depth_mm,force_n\n" + "".join(
        f"{k * 0.005:.3f},{max(0.0, k * 0.05 - 1.0):.3f},{0.01 * k:.4f}\n" for k in range(1400)))
    clean = scenario_frames(str(csv), DB, 1000.0)
    frames = sensor_failures(clean, DB, a.force_source, a.sensor_fault, a.sensor_lost)
    fid, cid = DB.frame_id("Force"), DB.frame_id("Command")
    rx = DB.receiver()
    cmds, flagged, n_force = [], 0, 0
    for t, m in frames:
        name, sig, status = rx.decode(m.arbitration_id, bytes(m.data))
        assert sig is not None, (t, name, status)
        if m.arbitration_id == cid:
            cmds.append((t, m.data[1] & 0x0F, int(sig["ForceSource"])))
        elif m.arbitration_id == fid:
            n_force += 1
            assert not 5.0 <= t < 5.5
            flagged += int(sig["SensorFault"])
            assert bool(sig["SensorFault"]) == (4.0 <= t < 4.5)
    assert cmds == [(2.0, 0, 2), (3.5, 1, 1)]
    assert flagged == 100 and n_force == 1400 - 100
    keep = {(t, bytes(m.data)) for t, m in clean
            if m.arbitration_id != fid or not (4.0 <= t < 5.5)}
    assert keep <= {(t, bytes(m.data)) for t, m in frames}
