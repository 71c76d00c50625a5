"""The fault table's node runs: a fresh nte-node fed one stream of frames, either through
``nte-node --replay`` (the same node code over a candump log, no CAN needed) or live on vcan0.

On vcan0 (``play_on_vcan``) every run of a table goes to the bus in one command:
``host_bench/with-vcan bash host_bench/fault_bus.sh NODE DIR`` (the kernel with-vcan finds or
boots, or the one of the session named by WITH_VCAN_CHANNEL).  Inside it only the node and
can-utils' canplayer run; the logs are written here before and read here after.  Each run's
node is started on vcan0 with its kernel filters (its four input ids), sent the run's frames by
canplayer at the log's pace, then stopped by its process group (or killed, a crash, when the
run says so).  The node's own logs of what it received and sent are the record (a candump in a
slow kernel may drop frames; the node's logs do not).

What is checked, per run (``BusRun``): the node received exactly the frames played on its input
ids, in order (nothing lost, nothing added: vcan is lossless when its readers keep up); and what
it sent -- every Estimate and Params frame, byte for byte -- equals what ``nte-node --replay``
sends for those frames at their own timestamps.  The node's results depend only on the frames'
SensorTime, so that replay also gives each Estimate its scenario time: the time of the last
frame read before it was published, as ``nte-node --replay`` stamps it.  Nothing is judged by
arrival times, so a kernel under QEMU's TCG, several times slower, gives the same table.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import can
import numpy as np

from reference_py.bus.candump import write_candump
from reference_py.bus.dbc import NteDatabase

ROOT = Path(__file__).resolve().parents[1]
WITH_VCAN = ROOT / "host_bench" / "with-vcan"
BUS_SCRIPT = ROOT / "host_bench" / "fault_bus.sh"
#: the replay log's clock starts here (s); an Estimate's scenario time is its stamp minus it
REPLAY_START_S = 1000.0
#: with-vcan's limit for the whole bus half (s): a limit, not a measure (TCG on a loaded host)
BUS_TIMEOUT_S = 3600


def input_ids(db: NteDatabase) -> set[int]:
    """The ids the node's kernel filters pass: Depth, Force, Command, Setting."""
    return {db.frame_id(n) for n in ("Depth", "Force", "Command", "Setting")}


def drain_marker(db: NteDatabase) -> can.Message:
    """The Command that ends every run on the bus: AdaptCmd resume (applied, changes nothing:
    nte_node.h COMMANDS (4)); the node has read the whole log once it counts it applied."""
    return db.sender().message("Command", {"Reset": 0, "ModelSel": 0, "EstimatorSel": 0,
                                           "AdaptCmd": 2, "ForceSource": 0})


def replay(node: str, frames: list[tuple[float, can.Message]], work: Path, tag: str,
           preset: str = "paper-10mms", model: int = 2) -> tuple[list[can.Message], dict]:
    """nte-node --replay on frames (scenario times): (the frames it sent, its counters)."""
    log, rec, st = work / f"{tag}.in.log", work / f"{tag}.out.log", work / f"{tag}.stats.json"
    write_candump(log, frames, "vcan0", 1.0, start=REPLAY_START_S)
    subprocess.run([node, "--replay", str(log), "--record", str(rec), "--stats", str(st),
                    "--model", str(model), "--preset", preset], check=True,
                   capture_output=True, timeout=600)
    return list(can.CanutilsLogReader(str(rec))), json.loads(st.read_text())


def estimates(db: NteDatabase, sent: list[can.Message],
              times: list[float] | None = None) -> np.ndarray:
    """(t_s, force_est_n, stale or fault) per Estimate frame of `sent`, at `times` if given
    (one per Estimate), else at the frames' own stamps less REPLAY_START_S."""
    rx = db.receiver()
    out = []
    for m in sent:
        name, sig, _ = rx.decode(m.arbitration_id, bytes(m.data))
        if name == "Estimate" and sig is not None:
            out.append([m.timestamp - REPLAY_START_S, float(sig["ForceEst"]),
                        bool(sig["Stale"]) or bool(sig["Fault"])])
    est = np.array(out, dtype=float).reshape(-1, 3)
    if times is not None:
        est[:, 0] = times
    return est


@dataclass
class NodeRun:
    """One fresh node fed `frames`; ``end`` "stop" (SIGTERM) or "kill" (SIGKILL, a crash);
    the frames of the `realtime` span (s), if any, played in real time whatever the speed."""
    tag: str
    frames: list[tuple[float, can.Message]]
    end: str = "stop"
    realtime: tuple[float, float] | None = None


def paced(frames: list[tuple[float, can.Message]], speed: float,
          realtime: tuple[float, float] | None = None) -> list[tuple[float, can.Message]]:
    """The frames at the times canplayer is to send them: `speed` times real time, but real
    time within the `realtime` span (s)."""
    a, b = realtime if realtime is not None else (0.0, 0.0)

    def at(t: float) -> float:
        fast = min(t, a) + max(0.0, t - b)
        return fast / speed + min(max(t - a, 0.0), b - a)

    return [(at(t), m) for t, m in frames]


def received_digest(frames: list[tuple[float, can.Message]]) -> str:
    """"COUNT MD5" of the frames as the node logs what it received: "ID#DATA" a line (the
    third field of its candump lines), in order (fault_bus.sh writes the same of its log)."""
    text = "".join(f"{m.arbitration_id:03X}#{bytes(m.data).hex().upper()}\n" for _, m in frames)
    return f"{len(frames)} {hashlib.md5(text.encode()).hexdigest()}"


@dataclass
class BusRun:
    """What one run did on the bus, and how it compares with its replay."""
    tag: str
    played: int                         #: frames canplayer sent (the drain marker included)
    played_inputs: int                  #: of them on the node's input ids
    received: int | None                #: frames the node logged as received (None: killed)
    received_equal: bool | None         #: exactly the played input frames, in order
    exit_status: int
    stats: dict                         #: the node's counters (at its end, or before the kill)
    replay_stats: dict
    sent_equal: bool | None             #: Estimate and Params frames equal the replay's
    counters_equal: bool                #: the counters equal the replay's (see _same_counters)
    bus_s: list[float]                  #: wall s in the kernel: run, start, play, reading, stop, copy
    est: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))


def _outputs(db: NteDatabase, sent: list[can.Message]) -> list[tuple[int, bytes]]:
    ids = {db.frame_id("Estimate"), db.frame_id("Params")}
    return [(m.arbitration_id, bytes(m.data)) for m in sent if m.arbitration_id in ids]


#: counters that depend on the port (its clock, its socket) rather than on the frames
PORT_COUNTERS = {"send_failed", "receive_error", "encode_error"}


def _same_counters(bus: dict, rep: dict) -> bool:
    """The node's frame counters equal its replay's: events (but the port's), frames lost,
    frames accepted, steps, Estimate and Params frames sent."""
    ev = {k: v for k, v in bus["events"].items() if k not in PORT_COUNTERS}
    ev_r = {k: v for k, v in rep["events"].items() if k not in PORT_COUNTERS}
    keys = ("frames_lost", "rx_accepted", "steps", "commands_applied", "predict_on",
            "predict_off", "predict_depth_steps")
    return (ev == ev_r and all(bus[k] == rep[k] for k in keys)
            and bus["tx"]["estimate"] == rep["tx"]["estimate"]
            and bus["tx"]["params"] == rep["tx"]["params"])


class BusError(RuntimeError):
    """The bus half could not run (no vehicle, a node that did not start...): one line."""


def play_on_vcan(node: str, runs: list[NodeRun], work: Path, speed: float,
                 db: NteDatabase, keep: bool = False) -> tuple[dict[str, BusRun], str]:
    """Every run on vcan0, in order, in one with-vcan command: {tag: BusRun}, and the vehicle
    with-vcan used (its own words).  Logs are played at `speed` times real time (`paced`).
    `keep`: the nodes' received logs are copied here too (work/bus/TAG.recv.log).  Raises
    BusError when the bus half fails."""
    bus_dir = work / "bus"
    shutil.rmtree(bus_dir, ignore_errors=True)       # nothing of an earlier table (--keep DIR)
    bus_dir.mkdir()
    marker = drain_marker(db)
    played: dict[str, list[tuple[float, can.Message]]] = {}
    for r in runs:
        fr = list(r.frames) + [(r.frames[-1][0], marker)]
        played[r.tag] = fr
        write_candump(bus_dir / f"{r.tag}.in.log", paced(fr, speed, r.realtime), "vcan0", 1.0)
    (bus_dir / "plan").write_text("".join(f"{r.tag} {r.end}\n" for r in runs))
    env = dict(os.environ,
               WITH_VCAN_TIMEOUT=os.environ.get("WITH_VCAN_TIMEOUT", str(BUS_TIMEOUT_S)))
    p = subprocess.run([str(WITH_VCAN), "bash", str(BUS_SCRIPT), node, str(bus_dir)]
                       + (["keep"] if keep else []), cwd=ROOT, env=env, capture_output=True,
                       text=True)
    vehicle = next((ln.split("vehicle ", 1)[1] for ln in p.stderr.splitlines()
                    if ln.startswith("with-vcan: vehicle ")), None)
    if vehicle is None and os.environ.get("WITH_VCAN_CHANNEL"):
        vehicle = f"the kernel served at {os.environ['WITH_VCAN_CHANNEL']}"
    failed = sorted(bus_dir.glob("*.failed"))
    if p.returncode == 125:
        reasons = [ln.strip() for ln in p.stderr.splitlines() if ln.startswith("  ")]
        raise BusError("no vcan0: host_bench/with-vcan could not start a vehicle ("
                       + "; ".join(reasons or p.stderr.strip().splitlines()[-1:]) + ")")
    if p.returncode != 0 or failed:
        why = failed[0].read_text().strip() if failed else (p.stderr.strip() or "no output")
        raise BusError(f"the bus half failed (with-vcan exit {p.returncode}): "
                       + " / ".join(why.splitlines()[-3:]))
    ids = input_ids(db)
    out = {}
    for r in runs:
        fr = played[r.tag]
        inputs = [(t, m) for t, m in fr if m.arbitration_id in ids]
        stats = json.loads((bus_dir / f"{r.tag}.stats.json").read_text())
        sent_r, st_r = replay(node, inputs, work, f"{r.tag}.replay")
        res = BusRun(tag=r.tag, played=len(fr), played_inputs=len(inputs), received=None,
                     received_equal=None,
                     exit_status=int((bus_dir / f"{r.tag}.exit").read_text()),
                     stats=stats, replay_stats=st_r, sent_equal=None,
                     counters_equal=_same_counters(stats, st_r),
                     bus_s=[float(x) for x in (bus_dir / f"{r.tag}.done").read_text().split()])
        if r.end == "stop":
            got = (bus_dir / f"{r.tag}.recv").read_text().split()
            sent = list(can.CanutilsLogReader(str(bus_dir / f"{r.tag}.sent.log")))
            res.received = int(got[0])
            res.received_equal = " ".join(got) == received_digest(inputs)
            res.sent_equal = _outputs(db, sent) == _outputs(db, sent_r)
            # the bus node's Estimates at the times its replay published them (when equal)
            t_rep = estimates(db, sent_r)[:, 0]
            est = estimates(db, sent)
            if res.sent_equal and len(est) == len(t_rep):
                est[:, 0] = t_rep
                res.est = est
        out[r.tag] = res
    return out, vehicle or "unknown"


__all__ = ["BusError", "BusRun", "NodeRun", "drain_marker", "estimates", "input_ids",
           "play_on_vcan", "replay"]
