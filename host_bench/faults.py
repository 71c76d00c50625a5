"""The node's fault table: faults injected into a stream of bus frames (lists of (t_s,
can.Message) in send order), each faulted stream fed to a fresh node, scored against the
fault-free run (``python -m host_bench.faults``, through ``nte-node --replay`` or live on vcan0:
host_bench/fault_bus.py runs the node).

burst(): a seeded burst of foreign frames on the node's input ids -- random lengths and data
(almost all fail the CRC) and frames crafted to pass the CRC with a sensor time far ahead of or
behind their stream, carrying the alive counter the next genuine frame of that stream will have
(the worst case for the counter check).  The genuine frames are never altered or removed, so a
node that cannot be blinded publishes the same estimates with and without the burst.
flood(): foreign frames at the bus's capacity (CAPACITY_FPS) for a span, half of them on the
node's Depth and Force ids.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import can
import numpy as np

from reference_py.bus.dbc import TICK_S, NteDatabase
from reference_py.config import EstimatorConfig
from reference_py.tools.csvio import read_trial

from .fault_bus import ROOT, BusError, BusRun, NodeRun, estimates, play_on_vcan, replay
from .replay import scenario_frames
from .sensor_failures import reencode, sensor_fault, sensor_lost


@dataclass
class BurstReport:
    random_frames: int = 0
    crafted_forward: int = 0
    crafted_backward: int = 0

    @property
    def total(self) -> int:
        return self.random_frames + self.crafted_forward + self.crafted_backward


def _sensor_ticks(db: NteDatabase, name: str, m: can.Message) -> int:
    return int(db.decode_unchecked(name, bytes(m.data))["SensorTime"] / TICK_S + 0.5) % 65536


def burst(frames: list[tuple[float, can.Message]], db: NteDatabase, seed: int,
          every_s: float = 0.5, size: int = 12, min_jump_s: float = 0.05,
          max_jump_s: float = 3.0) -> tuple[list[tuple[float, can.Message]], BurstReport]:
    """`frames` with a burst of `size` foreign frames after the first genuine frame at or after
    every `every_s` seconds (from the second burst period on).  In each burst one depth and one
    force frame are crafted (valid CRC, sensor time moved by +-min_jump_s..max_jump_s, counter
    of the next genuine frame of the stream); the rest are random (id: Depth or Force; length
    0..8; random bytes).  Deterministic for a seed."""
    rng = np.random.default_rng(seed)
    ids = {db.frame_id("Depth"): "Depth", db.frame_id("Force"): "Force"}
    rep = BurstReport()
    # the counter of the next genuine frame of each stream, from every position
    next_counter: list[dict[str, int]] = [{} for _ in frames]
    upcoming: dict[str, int] = {}
    for i in range(len(frames) - 1, -1, -1):
        name = ids.get(frames[i][1].arbitration_id)
        if name is not None:
            upcoming = dict(upcoming, **{name: frames[i][1].data[1] & 0x0F})
        next_counter[i] = upcoming
    last_ticks: dict[str, int] = {}
    out: list[tuple[float, can.Message]] = []
    t_next = 2 * every_s
    for i, (t, m) in enumerate(frames):
        out.append((t, m))
        name = ids.get(m.arbitration_id)
        if name is not None:
            last_ticks[name] = _sensor_ticks(db, name, m)
        if t < t_next or len(last_ticks) < 2 or i + 1 >= len(frames):
            continue
        t_next += every_s
        nxt = next_counter[i + 1]
        crafted = [n for n in ("Depth", "Force") if n in nxt]
        slots = sorted(rng.choice(size, size=len(crafted), replace=False).tolist())
        for k in range(size):
            if slots and k == slots[0]:
                slots.pop(0)
                cname = crafted.pop(0)
                jump = int(rng.uniform(min_jump_s, max_jump_s) / TICK_S)
                forward = bool(rng.integers(2))
                ticks = (last_ticks[cname] + (jump if forward else -jump)) % 65536
                sig = {"SensorTime": ticks * TICK_S}
                if cname == "Depth":
                    sig.update(Depth=float(rng.uniform(0.0, 400.0)),
                               Velocity=float(rng.uniform(-400.0, 400.0)))
                else:
                    sig.update(Force=float(rng.uniform(-40.0, 40.0)))
                data = db.encode(cname, sig, nxt[cname])
                out.append((t, can.Message(arbitration_id=db.frame_id(cname), data=data,
                                           is_extended_id=False, timestamp=t)))
                if forward:
                    rep.crafted_forward += 1
                else:
                    rep.crafted_backward += 1
                continue
            cid = db.frame_id("Depth" if rng.integers(2) == 0 else "Force")
            n = int(rng.integers(0, 9))
            data = bytes(rng.integers(0, 256, size=n, dtype=np.uint8).tolist())
            out.append((t, can.Message(arbitration_id=cid, data=data, dlc=n,
                                       is_extended_id=False, timestamp=t)))
            rep.random_frames += 1
    return out, rep


def clock_jump(frames: list[tuple[float, can.Message]], db: NteDatabase, at_s: float,
               jump_s: float) -> list[tuple[float, can.Message]]:
    """`frames` with the sensor clock moved by jump_s (either sign) from at_s on: every Depth
    and Force frame from then carries SensorTime + jump_s (same counter, CRC recomputed)."""
    ids = {db.frame_id("Depth"): "Depth", db.frame_id("Force"): "Force"}
    shift = int(round(jump_s / TICK_S))
    out = []
    for t, m in frames:
        name = ids.get(m.arbitration_id)
        if name is None or t < at_s:
            out.append((t, m))
            continue
        sig = db.decode_unchecked(name, bytes(m.data))
        sig["SensorTime"] = ((_sensor_ticks(db, name, m) + shift) % 65536) * TICK_S
        sig.pop("Crc", None)
        sig.pop("Counter", None)
        data = db.encode(name, sig, m.data[1] & 0x0F)
        out.append((t, can.Message(arbitration_id=m.arbitration_id, data=data,
                                   is_extended_id=False, timestamp=t)))
    return out


# ---------------------------------------------------------------------------------- flood
#: the bus the flood fills: 500 kbit/s, the bench's and the board's CAN bit rate
BUS_BITRATE_BPS = 500_000
#: one standard data frame of 8 bytes on the wire: 111 bits (SOF, 11-bit id, RTR, IDE, r0, DLC,
#: 64 data bits, 15-bit CRC: 98 bits that are stuffed; CRC and ACK delimiters, ACK, EOF, 3 bits of
#: intermission) plus stuff bits: up to 24 (one per 4 bits after the first of the 98), a few on
#: random data; 125 bits counts 14
FRAME_BITS = 125
#: frames per second a saturated bus carries: 4 000 at 500 kbit/s
CAPACITY_FPS = BUS_BITRATE_BPS // FRAME_BITS


def flood(frames: list[tuple[float, can.Message]], db: NteDatabase, t0: float, t1: float,
          rate_hz: float = CAPACITY_FPS, seed: int = 11,
          inputs_share: float = 0.5) -> list[tuple[float, can.Message]]:
    """`frames` with foreign frames at `rate_hz` in [t0, t1) s, evenly spaced: 8 random data
    bytes each; a share `inputs_share` on the node's Depth and Force ids (a babbling sender:
    they reach the node's code and fail its checks), the rest on random 11-bit ids outside the
    node's block (base .. base+0x1F: its inputs, Command and Setting among them, and outputs;
    the node's kernel filters drop them).  The genuine frames are neither altered nor moved
    (at equal times they go first).  Deterministic for a seed."""
    rng = np.random.default_rng(seed)
    base = db.frame_id("Depth")
    own = (db.frame_id("Depth"), db.frame_id("Force"))
    n = int(round((t1 - t0) * rate_hz))
    extra = []
    for k in range(n):
        if rng.random() < inputs_share:
            cid = own[int(rng.integers(2))]
        else:
            cid = int(rng.integers(0, 0x7E0))
            cid = cid if cid < base else cid + 0x20          # skip the node's block
        data = bytes(rng.integers(0, 256, size=8, dtype=np.uint8).tolist())
        t = t0 + k / rate_hz
        extra.append((t, can.Message(arbitration_id=cid, data=data, is_extended_id=False,
                                     timestamp=t)))
    merged = [(t, 0, i, m) for i, (t, m) in enumerate(frames)]
    merged += [(t, 1, i, m) for i, (t, m) in enumerate(extra)]
    merged.sort(key=lambda e: (e[0], e[1], e[2]))
    return [(t, m) for t, _, _, m in merged]


# ---------------------------------------------------------------------------------- fault table
#: the restart row: the node is killed at this scenario time (first insertion, 23.5 mm deep,
#: 10 mm/s) and a fresh one is up again RESTART_DOWN_S later (the frames between reach nobody)
RESTART_AT_S = 2.5
RESTART_DOWN_S = 0.5
#: the flood row: foreign frames at the bus's capacity over this span (insertion to dwell)
FLOOD_SPAN_S = (2.0, 7.0)


@dataclass
class FaultRow:
    """A row of the table: the faulted stream as `segments`, each fed to a freshly started
    node (one segment but for the restart), the fault's span [a, b] s, and whether the error is
    taken over the whole run (a fault that spans it, or the flood: its estimates during the
    flood are what it is about).  The flood's span is played on the bus in real time whatever
    the table's speed: its rate is its point (`realtime`)."""
    name: str
    segments: list[list[tuple[float, can.Message]]]
    a: float
    b: float
    whole: bool = False
    realtime: tuple[float, float] | None = None


def fault_rows(frames: list[tuple[float, can.Message]], db: NteDatabase,
               seed: int = 7) -> list[FaultRow]:
    """Every row of the table, in order."""
    rng = np.random.default_rng(seed)
    dep, frc = db.frame_id("Depth"), db.frame_id("Force")
    t_end = frames[-1][0]
    rows = []

    def whole(name: str, fr: list) -> None:
        rows.append(FaultRow(name, [fr], 0.0, t_end, whole=True))

    for p in (0.01, 0.05, 0.20):
        keep = rng.random(len(frames)) >= p
        whole(f"loss {p:.0%}", [f for f, k in zip(frames, keep) if k])
    dup = []
    for f in frames:
        dup.append(f)
        if rng.random() < 0.05:
            dup.append(f)
    whole("duplicates 5 %", dup)
    reo = list(frames)
    i = 0
    while i + 1 < len(reo):
        if rng.random() < 0.05 and reo[i][1].arbitration_id != reo[i + 1][1].arbitration_id:
            reo[i], reo[i + 1] = reo[i + 1], reo[i]
            i += 1
        i += 1
    whole("reorder 5 %", reo)
    whole("burst (seeded, 2/s)", burst(frames, db, seed=seed)[0])
    for gap in (1.0, 10.0):
        rows.append(FaultRow(f"depth dropout {gap:.0f} s", [
            [f for f in frames if not (f[1].arbitration_id == dep and 5.0 <= f[0] < 5.0 + gap)]],
            5.0, 5.0 + gap))
    stuck = None
    out = []
    for t, m in frames:
        if m.arbitration_id == frc and 5.0 <= t < 6.0:
            sig = db.decode_unchecked("Force", bytes(m.data))
            stuck = sig["Force"] if stuck is None else stuck
            m = reencode(db, "Force", m, Force=stuck)
        out.append((t, m))
    rows.append(FaultRow("stuck force 1 s", [out], 5.0, 6.0))
    rows.append(FaultRow("saturated force 1 s", [
        [(t, reencode(db, "Force", m, Force=EstimatorConfig.force_max_n))
         if m.arbitration_id == frc and 5.0 <= t < 6.0 else (t, m) for t, m in frames]],
        5.0, 6.0))
    # the same stuck force, flagged by its driver (SensorFault): predicted from the model
    rows.append(FaultRow("stuck force 1 s, SensorFault", [sensor_fault(out, db, [(5.0, 6.0)])],
                         5.0, 6.0))
    rows.append(FaultRow("force sensor lost 1 s", [sensor_lost(frames, db, [(5.0, 6.0)])],
                         5.0, 6.0))
    rows.append(FaultRow("clock jump +2 s", [clock_jump(frames, db, 5.0, 2.0)], 5.0, 5.0))
    rows.append(FaultRow("clock jump -1 s", [clock_jump(frames, db, 5.0, -1.0)], 5.0, 5.0))
    up = RESTART_AT_S + RESTART_DOWN_S
    # what the restarted node misses, to a node that keeps running: the bound for a restart
    # that keeps the node's state
    rows.append(FaultRow(f"bus silent {RESTART_DOWN_S:g} s mid-insertion",
                         [[f for f in frames if not RESTART_AT_S <= f[0] < up]], RESTART_AT_S, up))
    rows.append(FaultRow("node restart mid-insertion", [
        [f for f in frames if f[0] < RESTART_AT_S], [f for f in frames if f[0] >= up]],
        RESTART_AT_S, up))
    t0, t1 = FLOOD_SPAN_S
    rows.append(FaultRow(f"flood at bus capacity {t1 - t0:.0f} s",
                         [flood(frames, db, t0, t1)], t0, t1, whole=True, realtime=(t0, t1)))
    return rows


def score(est: np.ndarray, clean: np.ndarray, row: FaultRow, t_true: np.ndarray,
          f_true: np.ndarray) -> dict:
    """A row's recovery and error from its estimates (t_s, force, stale or fault) and the
    fault-free run's.  Recovery: from the fault's end to the first estimate after which none
    is stale or faulted (None for a row scored over the whole run); error: RMS of the fresh
    estimates against the true force from then on (the whole run for a whole-run row), as a
    ratio to the fault-free run's over the same span; and whether every estimate (time, force,
    flags) is the fault-free run's."""
    def rms(e: np.ndarray, t_from: float) -> float:
        sel = (e[:, 0] >= t_from) & (e[:, 2] == 0)
        d = e[sel, 1] - np.interp(e[sel, 0], t_true, f_true)
        return float(np.sqrt(np.mean(d * d))) if d.size else float("nan")

    t = est[:, 0]
    bad = np.nonzero((est[:, 2] != 0) & (t >= row.a))[0]
    t_rec = t[bad[-1] + 1] if bad.size and bad[-1] + 1 < len(t) else (row.b if not bad.size else np.inf)
    rec = None if row.whole else max(0.0, float(t_rec) - row.b)
    start = 0.0 if row.whole else max(row.b, float(t_rec))
    e_f, e_c = rms(est, start), rms(clean, start)
    return {"fault": row.name, "recovery_s": rec, "rms_mN": 1e3 * e_f,
            "clean_rms_mN": 1e3 * e_c, "error_pct": 100.0 * e_f / e_c,
            "same_as_fault_free": bool(np.array_equal(est, clean))}


def _moved(stats: list[dict], st0: dict) -> dict[str, int]:
    """The counters a row's nodes moved (summed over its segments) against the fault-free run."""
    ev: dict[str, int] = {}
    lost = 0
    for st in stats:
        for k, v in st["events"].items():
            ev[k] = ev.get(k, 0) + v
        lost += st["frames_lost"]
    moved = {k: v - st0["events"].get(k, 0) for k, v in ev.items()
             if v != st0["events"].get(k, 0)}
    if lost != st0["frames_lost"]:
        moved["frames_lost"] = lost - st0["frames_lost"]
    return moved


def table(node: str, csv: str, work: Path, rows: list[str] | None = None, bus: str = "replay",
          speed: float = 1.0, info: dict | None = None, keep: bool = False) -> list[dict]:
    """Every fault row (or those named in rows), each stream fed to a fresh node -- through
    nte-node --replay (bus "replay") or live on vcan0 (bus "vcan", host_bench.fault_bus, at
    `speed` times real time; `keep`: the nodes' received logs kept in work/bus) -- and scored
    by `score` against the fault-free run on the same vehicle, with the counters that moved.
    A killed node's outputs die with it on the bus: a row's score starts after its fault.  Over vcan each row also carries "bus": its runs'
    checks (host_bench.fault_bus.BusRun), and `info` (when given) receives the vehicle, the
    fault-free run's checks and the bus half's wall time."""
    db = NteDatabase()
    frames = scenario_frames(csv, db, 1000.0)
    # the true force beside the scenario, read by the tools' one reader (csvio)
    truth = read_trial(csv, required=("t_s", "depth_mm", "force_n", "force_true_n"),
                       sparse=("force_n",))
    t_true, f_true = truth.t_s, truth.columns["force_true_n"]
    every = fault_rows(frames, db)
    unknown = [n for n in rows or () if n not in {r.name for r in every}]
    if unknown:
        raise ValueError(f"--row: no row {unknown[0]!r} (rows: "
                         f"{', '.join(repr(r.name) for r in every)})")
    chosen = [(k, r) for k, r in enumerate(every) if rows is None or r.name in rows]
    runs = [NodeRun("clean", frames)]
    tags: dict[int, list[str]] = {}     # a row's runs: one per segment, all but the last killed
    for k, r in chosen:
        last = len(r.segments) - 1
        tags[k] = [f"row{k}" + (f"s{j}" if last else "") for j in range(last + 1)]
        runs += [NodeRun(tag, seg, "kill" if j < last else "stop", r.realtime)
                 for j, (tag, seg) in enumerate(zip(tags[k], r.segments))]
    if bus == "vcan":
        t_wall = time.monotonic()
        done, vehicle = play_on_vcan(node, runs, work, speed, db, keep)
        found = {tag: (b.est, b.stats) for tag, b in done.items()}
        if info is not None:
            info.update(vehicle=vehicle, clean=asdict_run(done["clean"]),
                        wall_s=time.monotonic() - t_wall)
    else:
        found = {}
        for run in runs:
            sent, st = replay(node, run.frames, work, run.tag)
            found[run.tag] = (estimates(db, sent), st)
    clean, st0 = found["clean"]
    out = []
    for k, r in chosen:
        est = np.concatenate([found[tag][0] for tag in tags[k]])
        res = score(est, clean, r, t_true, f_true)
        res["counters"] = _moved([found[tag][1] for tag in tags[k]], st0)
        if bus == "vcan":
            res["bus"] = [asdict_run(done[tag]) for tag in tags[k]]
        out.append(res)
    return out


def asdict_run(b: BusRun) -> dict:
    """A bus run's checks as plain values (its estimates left out)."""
    return {k: v for k, v in vars(b).items() if k != "est"}


def print_table(rows: list[dict]) -> None:
    print("| fault | recovery (s) | RMS error (mN) | fault-free (mN) | error % | counters moved |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        c = ", ".join(f"{k} {v:+d}" for k, v in r["counters"].items())
        rec = "whole run" if r["recovery_s"] is None else f"{r['recovery_s']:.3f}"
        print(f"| {r['fault']} | {rec} | {r['rms_mN']:.2f} | "
              f"{r['clean_rms_mN']:.2f} | {r['error_pct']:.0f} | {c} |")


def bus_checks(rows: list[dict], info: dict) -> list[str]:
    """What went wrong on the bus, one line each (none: every run received exactly the frames
    played on its input ids, sent what its replay sends, and counted what it counts)."""
    bad = []
    for name, runs in [("fault-free", [info["clean"]])] + [(r["fault"], r["bus"]) for r in rows]:
        for b in runs:
            if b["received_equal"] is False:
                bad.append(f"{name}: the node received {b['received']} frames, "
                           f"{b['played_inputs']} were played on its ids")
            if b["sent_equal"] is False:
                bad.append(f"{name}: the node's Estimate/Params frames differ from its replay's")
            if not b["counters_equal"]:
                bad.append(f"{name}: the node's counters differ from its replay's")
    return bad


def main(argv: list[str] | None = None) -> int:
    """python -m host_bench.faults: the fault table (markdown)."""
    import contextlib
    import subprocess
    import sys
    import tempfile
    from reference_py.tools.arguments import OneLineParser, bounded
    ap = OneLineParser(
        prog="python -m host_bench.faults",
        description="The node's fault table: every fault row's frame stream fed to a fresh "
                    "nte-node and scored against the fault-free run's.",
        epilog="""vehicles (--bus):
  replay  nte-node --replay on each stream: the same node code over candump logs,
          deterministic, no CAN needed (seconds)
  vcan    the node live on vcan0: host_bench/with-vcan finds or boots a kernel with vcan0
          (natively, user-mode Linux, or QEMU; WITH_VCAN_MODE, WITH_VCAN_CHANNEL apply) and
          runs host_bench/fault_bus.sh there: per run a fresh nte-node (kernel filters on)
          started in its own process group, the stream played by canplayer at --speed times
          real time (the flood itself always in real time), the node stopped by its group --
          killed for the restart row.  Checked per run: the node received exactly the frames
          played on its ids, and its Estimate and Params frames equal nte-node --replay's on
          them, which also times them (scenario time, never arrival time).

rows: losses, duplicates, reordering, a seeded burst, depth dropouts, a stuck and a saturated
force (unflagged, and flagged SensorFault), a lost force sensor, clock jumps, the bus silent
0.5 s mid-insertion (what a restart costs a node that keeps its state), a node restart
mid-insertion (killed at 2.5 s, a fresh node up 0.5 s of sensor time later), a flood of foreign
frames at the bus's capacity (4 000 frames/s: 500 kbit/s at 125 bits a frame) from 2 to 7 s.
Recovery: from the fault's end to the first estimate after which none is stale or faulted;
error: RMS of the fresh estimates against the true force from then on (over the whole run for
losses, duplicates, reordering, the burst and the flood), in % of the fault-free run's.

exit status: 0 the table was made (over vcan: and every bus check held), 1 a bus check failed
or the bus half could not run, 2 bad arguments.""")
    ap.add_argument("--node", default=str(ROOT / "build/host/bin/nte-node"),
                    help="nte-node binary (default build/host/bin/nte-node)")
    ap.add_argument("--csv", default=None, help="scenario CSV with force_true_n (default: two "
                    "paper insertions, 50 mm at 10 mm/s, 1 s dwell, seed 1)")
    ap.add_argument("--bus", choices=("replay", "vcan"), default="replay",
                    help="where the node runs (default replay; see below)")
    ap.add_argument("--speed", type=bounded(0.0, 16.0, lo_open=True), default=1.0,
                    help="--bus vcan: play the streams at this many times real time (default 1; "
                         "the results depend on the frames' own times only)")
    ap.add_argument("--row", action="append", default=None, metavar="NAME",
                    help="only this row (its name as in the table); may repeat")
    ap.add_argument("--json", metavar="FILE", default=None,
                    help="also write the rows (and over vcan the bus checks) as JSON")
    ap.add_argument("--keep", metavar="DIR", default=None,
                    help="work in DIR (created; its parent must exist) and keep it: the input "
                         "logs, the replays and, over vcan, DIR/bus with each node's own logs "
                         "(default: a temporary directory, removed)")
    a = ap.parse_args(argv)
    prog = "python -m host_bench.faults"
    if not Path(a.node).is_file():
        print(f"{prog}: error: --node: no such file {a.node} (make build)", file=sys.stderr)
        return 2
    if a.keep is not None:
        try:
            Path(a.keep).mkdir(exist_ok=True)
        except OSError as e:
            print(f"{prog}: error: --keep: cannot create {a.keep}: {e.strerror}", file=sys.stderr)
            return 2
    with (contextlib.nullcontext(a.keep) if a.keep else tempfile.TemporaryDirectory()) as d:
        work = Path(d)
        csv = a.csv
        if csv is None:
            csv = str(work / "paper.csv")
            subprocess.run([sys.executable, "-m", "reference_py", "simulate", "--preset",
                            "paper-10mms", "--depth", "50", "--dwell", "1", "--seed", "1",
                            "--cycles", "2", "--out", csv], check=True, stdout=subprocess.DEVNULL)
        info: dict = {}
        try:
            rows = table(a.node, csv, work, a.row, a.bus, a.speed, info, a.keep is not None)
        except BusError as e:
            print(f"{prog}: error: {e}", file=sys.stderr)
            return 1
        except ValueError as e:            # a bad --csv (csvio's CsvError), an unknown --row
            print(f"{prog}: error: {e}", file=sys.stderr)
            return 2
    print_table(rows)
    status = 0
    if a.bus == "vcan":
        bad = bus_checks(rows, info)
        n = 1 + sum(len(r["bus"]) for r in rows)
        print(f"\nover vcan0 ({info['vehicle']}), {n} node runs in {info['wall_s']:.0f} s: "
              + ("every run received exactly the frames played on its ids and sent what "
                 "nte-node --replay sends for them" if not bad else "; ".join(bad)))
        status = 1 if bad else 0
    if a.json:
        Path(a.json).write_text(json.dumps({"rows": rows, **info}, indent=1, default=float))
    return status


if __name__ == "__main__":
    raise SystemExit(main())
