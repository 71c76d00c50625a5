"""The host half of tests/python/test_node_vcan.py: ``prepare`` writes every case's input
candump log (the paper scenario, the bad traffic, the seeded burst) before the bus runs;
``analyse`` reads what the bus half (node_vcan_bus.sh, inside the session's kernel) recorded --
candump captures and the node's own logs of what it received and sent -- and compares the node
with the reference (host_bench.node_mirror) fed the same frames.  Nothing here needs AF_CAN, so
it runs on the host at full speed whatever kernel carries the bus."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import can

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from host_bench.replay import scenario_frames  # noqa: E402
from reference_py.bus.candump import write_candump  # noqa: E402
from reference_py.bus.dbc import NteDatabase, TICK_S  # noqa: E402
from host_bench.faults import burst  # noqa: E402
from host_bench.node_mirror import NodeMirror  # noqa: E402
from host_bench.node_outputs import compare, contact_outputs, health_outputs, node_outputs  # noqa: E402

DB = NteDatabase()
INPUT_IDS = {DB.frame_id(n) for n in ("Depth", "Force", "Command")}
CASES = ("full_rate", "bad_traffic", "cangen", "burst", "enobufs", "no_iface", "model3",
         "predict_only", "settings")
#: the model3 case: the first seconds of phantom lab seed 101 (stage moves at 1.0 s, touches the
#: surface, 6.48 mm, at 4.3 s), a Command selecting Model III at 0.5 s (in the air)
MODEL3_WINDOW_S = 5.5
MODEL3_COMMAND_S = 0.5
#: the predict_only case: the paper scenario's first PO_WINDOW_S seconds, ForceSource model and
#: sensor commands (in tissue), a SensorFault stretch and a lost force sensor (s)
PO_WINDOW_S = 6.5
PO_COMMANDS = [(2.0, "model"), (3.0, "sensor")]
PO_FAULTS = [(4.0, 4.5)]
PO_LOST = [(5.0, 5.5)]


def capture(path: Path) -> list[can.Message]:
    return list(can.CanutilsLogReader(str(path)))


OUTPUT_IDS = {DB.frame_id(n) for n in ("Estimate", "Params", "Heartbeat", "Contact", "Health")}


def _result(out: Path, cap: list[can.Message], tag: str, inputs: list | None = None,
            **mirror_kw) -> dict:
    """Node outputs from `cap`; the mirror is fed `inputs` (the frames sent) if given, else the
    input frames of `cap` (a complete capture)."""
    mirror = NodeMirror(**mirror_kw)
    if inputs is None:
        inputs = [m for m in cap if m.arbitration_id not in OUTPUT_IDS]
    mirror.feed_all(inputs)
    est, par, bad = node_outputs(DB, cap)
    healths, bad_h = health_outputs(DB, cap)
    res = compare(mirror, est, par, healths=healths)
    res["output_e2e_errors"] = bad + bad_h
    res["mirror_events"] = mirror.events
    res["stats"] = json.loads((out / f"{tag}.stats.json").read_text())
    res["inputs_captured"] = sum(1 for m in cap if m.arbitration_id in INPUT_IDS)
    res["heartbeats"] = sum(1 for m in cap if m.arbitration_id == DB.frame_id("Heartbeat"))
    return res


def paper_frames(out: Path, cycles: int = 1) -> list:
    csv = out / f"paper{cycles}.csv"
    if not csv.exists():
        subprocess.run([sys.executable, "-m", "reference_py", "simulate", "--preset",
                        "paper-10mms", "--depth", "50", "--dwell", "1", "--seed", "1",
                        "--cycles", str(cycles), "--out", str(csv)], check=True,
                       stdout=subprocess.DEVNULL)
    return scenario_frames(str(csv), DB, 1000.0)


# ---------------------------------------------------------------------------------- prepare
def prepare(out: Path) -> None:
    """Every case's input log (candump -l, replayed by canplayer in real time) and the ids the
    bus half filters on."""
    (out / "ids").mkdir(exist_ok=True)
    (out / "ids" / "depth").write_text(f"{DB.frame_id('Depth'):03X}\n")
    paper = paper_frames(out)
    write_candump(out / "full_in.log", paper, "vcan0", 1.0)
    write_candump(out / "nobuf_in.log", paper, "vcan0", 1.0)
    frames, expect = _bad_traffic_frames()
    write_candump(out / "bad_in.log", frames, "vcan0", 0.5)   # half speed
    (out / "bad_expect.json").write_text(json.dumps(expect))
    write_candump(out / "gen_in.log", paper_frames(out, cycles=5), "vcan0", 1.0)
    frames, rep = burst(paper, DB, seed=2026)
    write_candump(out / "burst_in.log", frames, "vcan0", 1.0)
    write_candump(out / "model3_in.log", model3_frames(out), "vcan0", 1.0)
    write_candump(out / "po_in.log", predict_only_frames(out), "vcan0", 1.0)
    write_candump(out / "settings_in.log", settings_frames(out), "vcan0", 1.0)
    (out / "burst_report.json").write_text(json.dumps({
        "random": rep.random_frames, "crafted": rep.crafted_forward + rep.crafted_backward,
        "total": rep.total, "sent": len(frames)}))


def model3_frames(out: Path) -> list:
    """The phantom's first MODEL3_WINDOW_S seconds (stage position and raw force, as a rig
    sends them) with a Command ModelSel 3 at MODEL3_COMMAND_S, while the stage is still at 0
    (so the Model II node, InTissue = depth > 0, is out of tissue and applies it)."""
    csv = out / "lab101.csv"
    if not csv.exists():
        subprocess.run([sys.executable, "-m", "reference_py", "phantom", "lab", "--seed", "101",
                        "--out", str(csv)], check=True, stdout=subprocess.DEVNULL)
    frames = [(t, m) for t, m in scenario_frames(str(csv), DB, 1000.0)
              if t <= MODEL3_WINDOW_S]
    cmd = DB.sender().message("Command", {"Reset": 0, "ModelSel": 3, "EstimatorSel": 0,
                                          "AdaptCmd": 0})
    return sorted(frames + [(MODEL3_COMMAND_S, cmd)], key=lambda e: e[0])


def settings_frames(out: Path) -> list:
    """The settings case: nte-run's Model III export of phantom lab seed 101 as
    OUT/settings_m3.json (layer sets, known surface, Model III's constants), and the phantom's
    first MODEL3_WINDOW_S seconds, played after nte-bench settings sent the export."""
    model3_frames(out)                                   # writes lab101.csv
    nte_run = next(p for p in (ROOT / "build/host/bin/nte-run", ROOT / "build/node/bin/nte-run")
                   if p.exists())
    subprocess.run([str(nte_run), str(out / "lab101.csv"), "--model", "3", "--out",
                    str(out / "settings_e.csv"), "--export-config", str(out / "settings_m3.json")],
                   check=True, stdout=subprocess.DEVNULL)
    return [(t, m) for t, m in scenario_frames(str(out / "lab101.csv"), DB, 1000.0)
            if t <= MODEL3_WINDOW_S]


def predict_only_frames(out: Path) -> list:
    """The paper scenario's first PO_WINDOW_S seconds with the force sensor's failures of
    nte-bench replay's options (host_bench.cli.sensor_failures)."""
    from host_bench.cli import sensor_failures
    frames = [(t, m) for t, m in paper_frames(out) if t <= PO_WINDOW_S]
    return sensor_failures(frames, DB, PO_COMMANDS, PO_FAULTS, PO_LOST)


def _bad_traffic_frames() -> tuple[list, dict]:
    """A 3 s scenario with every kind of bad frame, a 200 ms depth gap and commands."""
    tx = DB.sender()
    out: list[tuple[float, can.Message]] = []
    expect = {"wrong_dlc": 0, "unknown_id": 0, "bad_crc": 0, "counter_repeated": 0,
              "counter_skipped": 0, "out_of_range": 0, "time_backwards": 0}

    def add(t, m):
        out.append((t, m))

    for k in range(0, 30000, 10):                      # ticks of 100 us: 3 s, depth 1 kHz
        t = k * TICK_S
        # insertion, out of tissue 2.4 .. 2.55 s (the valid reset at 2.5 s needs it), again
        depth = (max(0.0, 10.0 * (t - 0.1)) if k < 24000 else
                 0.0 if k < 25500 else 10.0 * (t - 2.55))
        st = (k % 65536) * TICK_S
        if not (12000 <= k < 14000):                    # depth missing 1.2 .. 1.4 s
            add(t, tx.message("Depth", {"Depth": depth, "Velocity": 10.0, "SensorTime": st}))
        if k % 50 == 0:
            f = 0.02 * depth + 0.001 * ((k // 50) % 5)
            add(t, tx.message("Force", {"Force": f, "SensorTime": st}))
        if k % 1000 == 500:                             # once per 100 ms: one bad frame
            kind = (k // 1000) % 7
            base = out[-1][1]
            if kind == 0:
                add(t, can.Message(arbitration_id=base.arbitration_id, data=bytes(base.data[:5]),
                                   is_extended_id=False)); expect["wrong_dlc"] += 1
            elif kind == 1:
                add(t, can.Message(arbitration_id=0x205, data=bytes(8), is_extended_id=False))
                expect["unknown_id"] += 1
            elif kind == 2:
                d = bytearray(base.data); d[4] ^= 0x10
                add(t, can.Message(arbitration_id=base.arbitration_id, data=bytes(d),
                                   is_extended_id=False)); expect["bad_crc"] += 1
            elif kind == 3:
                add(t, base); expect["counter_repeated"] += 1
            elif kind == 4:                             # skip a depth counter (accepted)
                tx.counters["Depth"] = (tx.counters["Depth"] + 2) % 15
                expect["counter_skipped"] += 1
            elif kind == 5:                             # raw depth 510 mm, E2E-valid
                raw = bytearray(DB.db.get_message_by_name("Depth").encode(
                    {"Crc": 0, "Counter": 0, "Depth": 0, "Velocity": 0, "SensorTime": st}))
                v = 510000
                bits = int.from_bytes(raw, "little") | (v << 12)
                data = bytearray(bits.to_bytes(8, "little"))
                cnt = tx.counters.get("Depth", 0)
                data[1] = (data[1] & 0xF0) | cnt
                tx.counters["Depth"] = (cnt + 1) % 15
                from e2e.p11 import E2E_P11_DATAID_BOTH, e2e_p11_protect
                e2e_p11_protect(data, DB.data_ids["Depth"], data_id_mode=E2E_P11_DATAID_BOTH,
                                increment_counter=False)
                add(t, can.Message(arbitration_id=DB.frame_id("Depth"), data=bytes(data),
                                   is_extended_id=False)); expect["out_of_range"] += 1
            else:                                       # force 2 ms in the past
                add(t, tx.message("Force", {"Force": 0.1,
                                            "SensorTime": ((k - 20) % 65536) * TICK_S}))
                expect["time_backwards"] += 1
        if k == 20000:                                  # a command with a bad CRC, then a reset
            bad = bytearray(tx.encode("Command", {"Reset": 1, "ModelSel": 0, "EstimatorSel": 0,
                                                  "AdaptCmd": 0}))
            bad[0] ^= 0xFF
            add(t, can.Message(arbitration_id=DB.frame_id("Command"), data=bytes(bad),
                               is_extended_id=False))
            expect["bad_crc"] += 1
        if k == 25000:
            add(t, tx.message("Command", {"Reset": 1, "ModelSel": 0, "EstimatorSel": 0,
                                          "AdaptCmd": 0}))
    return out, expect


# ---------------------------------------------------------------------------------- analyse
def full_rate(out: Path) -> dict:
    """Paper scenario, 1 kHz depth + 200 Hz force, canplayer in real time (the mirror is fed
    the frames sent; the node's counters prove it received them all); then the session recorded
    with `candump -l` (input ids) replayed with canplayer to a fresh node."""
    frames = paper_frames(out)
    res = _result(out, capture(out / "full.sent.log"), "full", [m for _, m in frames])
    res["node_exit"] = int((out / "full.exit").read_text())
    res["sent"] = len(frames)
    res["forces_sent"] = sum(1 for _, m in frames if m.arbitration_id == DB.frame_id("Force"))
    res["depth_sent"] = len(frames) - res["forces_sent"]
    session = sorted((out / "session").glob("candump-*.log"))[0]
    sess = capture(session)
    res["session_frames"] = len(sess)
    again = _result(out, capture(out / "again.sent.log"), "again", sess)
    res["session_replay"] = {k: again[k] for k in ("estimates_node", "estimates_reference",
                                                   "estimate_mismatches", "param_value_mismatches")}
    a = [m for m in capture(out / "full.sent.log") if m.arbitration_id == DB.frame_id("Estimate")]
    b = [m for m in capture(out / "again.sent.log") if m.arbitration_id == DB.frame_id("Estimate")]
    res["replayed_identical"] = [bytes(m.data) for m in a] == [bytes(m.data) for m in b]
    return res


def bad_traffic(out: Path) -> dict:
    """Every kind of bad frame, a depth gap and commands, the node without its kernel filters:
    the mirror fed what the node received (its own log, every frame on the bus but its own)
    must give what it sent (its own log) and count the same events."""
    recv = capture(out / "bad.recv.log")
    sent = capture(out / "bad.sent.log")
    res = _result(out, sent, "bad", inputs=recv)
    res["expect"] = json.loads((out / "bad_expect.json").read_text())
    # reference for "a valid reset resets": a fresh mirror fed only what follows the reset
    cmd = [i for i, m in enumerate(recv) if m.arbitration_id == DB.frame_id("Command")]
    if not cmd:
        raise AssertionError(f"no Command frame among the {len(recv)} the node received")
    fresh = NodeMirror()
    after = recv[cmd[-1] + 1:]
    # the fresh mirror needs E2E sync and clock history as the node had: feed the depth
    # history before the reset silently, then compare the estimates after the reset
    fresh.feed_all(m for m in recv[:cmd[-1]] if m.arbitration_id == DB.frame_id("Depth"))
    fresh.estimates.clear()
    fresh.params.clear()
    fresh.feed_all(m for m in after if m.arbitration_id == DB.frame_id("Depth") or
                   m.arbitration_id == DB.frame_id("Force"))
    est, _, _ = node_outputs(DB, sent)
    # the node's last estimates are those of the forces after the reset
    res["after_reset_node"] = [e.key() for e in est[len(est) - len(fresh.estimates):]]
    res["after_reset_fresh"] = [e.key() for e in fresh.estimates]
    return res


def _exact_bookkeeping(out: Path, tag: str, genuine: list) -> dict:
    """The node's own logs of what it received and sent (--received/--record): the mirror fed
    what it received must give what it sent, bit for bit, whatever else was on the bus; and
    every genuine frame must be among what it received, in order."""
    recv = capture(out / f"{tag}.recv.log")
    sent = capture(out / f"{tag}.sent.log")
    mirror = NodeMirror().feed_all(recv)
    est, par, bad = node_outputs(DB, sent)
    healths, bad_h = health_outputs(DB, sent)
    res = compare(mirror, est, par, healths=healths)
    res["output_e2e_errors"] = bad + bad_h
    res["mirror_events"] = mirror.events
    res["stats"] = json.loads((out / f"{tag}.stats.json").read_text())
    res["received"] = len(recv)
    key = [(m.arbitration_id, bytes(m.data)) for m in genuine]
    i = 0
    for m in recv:
        if i < len(key) and (m.arbitration_id, bytes(m.data)) == key[i]:
            i += 1
    res["genuine_sent"] = len(key)
    res["genuine_received_in_order"] = i
    clean = NodeMirror().feed_all(genuine)
    res["estimates_equal_clean"] = [e.key() for e in est] == [e.key() for e in clean.estimates]
    res["foreign_received"] = len(recv) - i
    return res


def cangen(out: Path) -> dict:
    """60 s of cangen random traffic (random ids, lengths, data; 2 ms gap) while a 57 s
    scenario (five paper insertions) is replayed at full rate with canplayer.  cangen also hits
    the node's output ids and, rarely, passes the CRC on an input id: the node's own logs of
    what it received and sent make the comparison exact in every run."""
    frames = paper_frames(out, cycles=5)
    res = _exact_bookkeeping(out, "gen", [m for _, m in frames])
    res["cangen_s"] = float((out / "gen.cangen_s").read_text())
    res["forces_sent"] = sum(1 for _, m in frames if m.arbitration_id == DB.frame_id("Force"))
    res["sent"] = len(frames)
    return res


def burst_case(out: Path) -> dict:
    """A seeded burst (host_bench.faults.burst, seed 2026) on the input ids merged into the
    replay of the paper scenario, played by canplayer at full rate."""
    genuine = paper_frames(out)
    rep = json.loads((out / "burst_report.json").read_text())
    res = _exact_bookkeeping(out, "burst", [m for _, m in genuine])
    res["burst"] = {k: rep[k] for k in ("random", "crafted", "total")}
    res["sent"] = rep["sent"]
    res["forces_sent"] = sum(1 for _, m in genuine if m.arbitration_id == DB.frame_id("Force"))
    res["depth_sent"] = len(genuine) - res["forces_sent"]
    return res


def enobufs(out: Path) -> dict:
    """send() failed with ENOBUFS (LD_PRELOAD shim) for a fixed count of sends mid-replay."""
    frames = paper_frames(out)
    cap = capture(out / "nobuf.sent.log")
    res = _result(out, cap, "nobuf", [m for _, m in frames])
    res["alive_after"] = (out / "nobuf.alive").read_text().strip() == "1"
    res["enobufs_sends"] = int((out / "nobuf.sends").read_text())
    # every Estimate frame the node recorded, whether or not it passes the receiver's E2E check:
    # the counter counts modulo 15, so when the outage took a multiple of 15 frames the first
    # one after it carries the counter of the last one before and the receiver refuses it as a
    # repeat (decoded = recorded - 1 then, about one run in 15)
    res["estimate_frames_recorded"] = sum(1 for m in cap
                                          if m.arbitration_id == DB.frame_id("Estimate"))
    # the frames that did go out still follow the reference; counters cannot align the node's
    # estimates to the mirror's across 15+ losses, so compare the tail after the outage (the
    # last 500) one to one
    est, _, _ = node_outputs(DB, cap)
    mirror = NodeMirror().feed_all(m for _, m in frames)
    res["tail_equal"] = [e.key() for e in est[-500:]] == [e.key() for e in mirror.estimates[-500:]]
    return res


def model3(out: Path) -> dict:
    """Model III selected by a Command during a replay: the mirror (started in Model II, as
    the node) fed what the node received (its own log, port clock times) must give what it
    sent -- Estimate, Params and Contact frames -- bit for bit."""
    recv = capture(out / "model3.recv.log")
    sent = capture(out / "model3.sent.log")
    mirror = NodeMirror(model=2).feed_all(recv)
    est, par, bad = node_outputs(DB, sent)
    contacts, bad_c = contact_outputs(DB, sent)
    healths, bad_h = health_outputs(DB, sent)
    res = compare(mirror, est, par, contacts, healths)
    res["output_e2e_errors"] = bad + bad_c + bad_h
    res["mirror_events"] = mirror.events
    res["mirror_model"] = mirror.model
    res["stats"] = json.loads((out / "model3.stats.json").read_text())
    frames = model3_frames(out)
    res["sent"] = len(frames)
    res["received"] = len(recv)
    res["genuine_received"] = sorted((m.arbitration_id, bytes(m.data)) for m in recv) == \
        sorted((m.arbitration_id, bytes(m.data)) for _, m in frames)
    res["heartbeat_models"] = [int(DB.decode_unchecked("Heartbeat", bytes(m.data))["ActiveModel"])
                               for m in sent if m.arbitration_id == DB.frame_id("Heartbeat")]
    res["param_indices"] = sorted({p.index for p in par})
    res["contact_states"] = [c.contact_state for c in contacts]
    res["surfaces_mm"] = sorted({c.surface_raw * 1e-3 for c in contacts if c.surface_valid})
    return res


def predict_only(out: Path) -> dict:
    """Predict-only on the bus: the mirror fed what the node received (its own log, port clock
    times: the commands' rate limit) must give what it sent, bit for bit, and its counters."""
    recv = capture(out / "po.recv.log")
    sent = capture(out / "po.sent.log")
    mirror = NodeMirror(model=2).feed_all(recv)
    est, par, bad = node_outputs(DB, sent)
    healths, bad_h = health_outputs(DB, sent)
    res = compare(mirror, est, par, healths=healths)
    res["output_e2e_errors"] = bad + bad_h
    res["mirror_events"] = mirror.events
    res["mirror_predict"] = mirror.predict_counts
    res["stats"] = json.loads((out / "po.stats.json").read_text())
    frames = predict_only_frames(out)
    res["sent"] = len(frames)
    res["received"] = len(recv)
    res["genuine_received"] = sorted((m.arbitration_id, bytes(m.data)) for m in recv) == \
        sorted((m.arbitration_id, bytes(m.data)) for _, m in frames)
    res["predicted"] = sum(1 - e.adapting for e in est)
    return res


def settings(out: Path) -> dict:
    """A configuration sent over the bus: the node's counters, the bench's answer, and the node's
    outputs against nte-node --replay of the same phantom frames with --config on the file
    (the node configured at start), Estimate, Params and Contact frames byte for byte."""
    recv = capture(out / "settings.recv.log")
    sent = capture(out / "settings.sent.log")
    res: dict = {"stats": json.loads((out / "settings.stats.json").read_text()),
                 "bench_exit": int((out / "settings.bench.exit").read_text()),
                 "bench_out": (out / "settings.bench.out").read_text()}
    setting_id = DB.frame_id("Setting")
    res["setting_frames_received"] = sum(1 for m in recv if m.arbitration_id == setting_id)
    node = next(p for p in (ROOT / "build/host/bin/nte-node", ROOT / "build/node/bin/nte-node")
                if p.exists())
    ref = out / "settings.config.sent.log"
    subprocess.run([str(node), "--replay", str(out / "settings_in.log"), "--record", str(ref),
                    "--config", str(out / "settings_m3.json")], check=True)
    ids = {DB.frame_id(n) for n in ("Estimate", "Params", "Contact")}
    got = [(m.arbitration_id, bytes(m.data)) for m in sent if m.arbitration_id in ids]
    want = [(m.arbitration_id, bytes(m.data)) for m in capture(ref) if m.arbitration_id in ids]
    res["outputs"] = len(got)
    res["outputs_config"] = len(want)
    res["equal"] = got == want
    res["contacts"] = sum(1 for m in sent if m.arbitration_id == DB.frame_id("Contact"))
    return res


def no_iface(out: Path) -> dict:
    return {"exit": int((out / "noif.exit").read_text()), "stderr": (out / "noif.err").read_text()}


ANALYSE = {"full_rate": full_rate, "bad_traffic": bad_traffic, "cangen": cangen,
           "burst": burst_case, "enobufs": enobufs, "no_iface": no_iface, "model3": model3,
           "predict_only": predict_only, "settings": settings}


def analyse(out: Path, case: str) -> dict:
    """The case's findings, or {"error": why} when its bus half failed."""
    failed = out / f"{case}.failed"
    if failed.exists():
        return {"error": failed.read_text()}
    done = out / f"{case}.done"
    if not done.exists():
        return {"error": f"the bus half did not run case {case}"}
    res = ANALYSE[case](out)
    res["bus_s"] = float(done.read_text())
    return res
