"""Faults injected into a stream of bus frames (lists of (t_s, can.Message) in send order).

burst(): a seeded burst of foreign frames on the node's input ids -- random lengths and data
(almost all fail the CRC) and frames crafted to pass the CRC with a sensor time far ahead of or
behind their stream, carrying the alive counter the next genuine frame of that stream will have
(the worst case for the counter check).  The genuine frames are never altered or removed, so a
node that cannot be blinded publishes the same estimates with and without the burst.
"""
from __future__ import annotations

from dataclasses import dataclass

import can
import numpy as np

from reference_py.bus.candump import write_candump
from reference_py.bus.dbc import TICK_S, NteDatabase
from reference_py.config import EstimatorConfig
from reference_py.tools.csvio import read_trial

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


# ---------------------------------------------------------------------------------- fault table
def fault_rows(frames: list[tuple[float, can.Message]], db: NteDatabase, seed: int = 7):
    """(name, frames with the fault, fault start s, fault end s) for every row of the table."""
    rng = np.random.default_rng(seed)
    dep, frc = db.frame_id("Depth"), db.frame_id("Force")
    t_end = frames[-1][0]
    rows = []
    for p in (0.01, 0.05, 0.20):
        keep = rng.random(len(frames)) >= p
        rows.append((f"loss {p:.0%}", [f for f, k in zip(frames, keep) if k], 0.0, t_end))
    dup = []
    for f in frames:
        dup.append(f)
        if rng.random() < 0.05:
            dup.append(f)
    rows.append(("duplicates 5 %", dup, 0.0, t_end))
    reo = list(frames)
    i = 0
    while i + 1 < len(reo):
        if rng.random() < 0.05 and reo[i][1].arbitration_id != reo[i + 1][1].arbitration_id:
            reo[i], reo[i + 1] = reo[i + 1], reo[i]
            i += 1
        i += 1
    rows.append(("reorder 5 %", reo, 0.0, t_end))
    rows.append(("burst (seeded, 2/s)", burst(frames, db, seed=seed)[0], 0.0, t_end))
    for gap in (1.0, 10.0):
        rows.append((f"depth dropout {gap:.0f} s",
                     [f for f in frames if not (f[1].arbitration_id == dep and 5.0 <= f[0] < 5.0 + gap)],
                     5.0, 5.0 + gap))
    stuck = None
    out = []
    for t, m in frames:
        if m.arbitration_id == frc and 5.0 <= t < 6.0:
            sig = db.decode_unchecked("Force", bytes(m.data))
            stuck = sig["Force"] if stuck is None else stuck
            m = reencode(db, "Force", m, Force=stuck)
        out.append((t, m))
    rows.append(("stuck force 1 s", out, 5.0, 6.0))
    rows.append(("saturated force 1 s",
                 [(t, reencode(db, "Force", m, Force=EstimatorConfig.force_max_n))
                  if m.arbitration_id == frc and 5.0 <= t < 6.0 else (t, m)
                  for t, m in frames], 5.0, 6.0))
    # the same stuck force, flagged by its driver (SensorFault): predicted from the model
    rows.append(("stuck force 1 s, SensorFault", sensor_fault(out, db, [(5.0, 6.0)]), 5.0, 6.0))
    rows.append(("force sensor lost 1 s", sensor_lost(frames, db, [(5.0, 6.0)]), 5.0, 6.0))
    rows.append(("clock jump +2 s", clock_jump(frames, db, 5.0, 2.0), 5.0, 5.0))
    rows.append(("clock jump -1 s", clock_jump(frames, db, 5.0, -1.0), 5.0, 5.0))
    return rows


def run_replay(node: str, frames: list[tuple[float, can.Message]], work: "Path", tag: str,
               preset: str = "paper-10mms", model: int = 2):
    """nte-node --replay on frames: (t_s, force_est_n, stale or fault) per Estimate, counters."""
    import json
    import subprocess

    log, rec, st = work / f"{tag}.in.log", work / f"{tag}.out.log", work / f"{tag}.stats.json"
    write_candump(log, frames, "vcan0", 1.0, start=1000.0)
    subprocess.run([node, "--replay", str(log), "--record", str(rec), "--stats", str(st),
                    "--model", str(model), "--preset", preset], check=True,
                   capture_output=True, timeout=600)
    db = NteDatabase()
    rx = db.receiver()
    out = []
    for m in can.CanutilsLogReader(str(rec)):
        name, sig, _ = rx.decode(m.arbitration_id, bytes(m.data))
        if name == "Estimate" and sig is not None:
            out.append((m.timestamp - 1000.0, float(sig["ForceEst"]),
                        bool(sig["Stale"]) or bool(sig["Fault"])))
    return np.array(out, dtype=float).reshape(-1, 3), json.loads(st.read_text())


def table(node: str, csv: str, work: "Path", rows: list[str] | None = None) -> list[dict]:
    """Every fault row (or those named in rows): recovery time after the fault (first estimate
    after which none is stale or faulted; None for a fault that spans the run), RMS error of the
    fresh estimates against the true force after recovery (the whole run for a fault that spans
    it), as a ratio to the fault-free run's over the same span, and the counters that moved."""
    from .replay import scenario_frames
    db = NteDatabase()
    frames = scenario_frames(csv, db, 1000.0)
    # the true force beside the scenario, read by the tools' one reader (csvio)
    truth = read_trial(csv, required=("t_s", "depth_mm", "force_n", "force_true_n"),
                       sparse=("force_n",))
    t_true, f_true = truth.t_s, truth.columns["force_true_n"]
    clean, st0 = run_replay(node, frames, work, "clean")
    t0 = 0.0  # Estimate times are scenario times (log time - 1000 s)

    def rms(est: np.ndarray, t_from: float) -> float:
        sel = (est[:, 0] + t0 >= t_from) & (est[:, 2] == 0)
        e = est[sel, 1] - np.interp(est[sel, 0] + t0, t_true, f_true)
        return float(np.sqrt(np.mean(e * e))) if e.size else float("nan")

    out = []
    for k, (name, fr, a, b) in enumerate(fault_rows(frames, db)):
        if rows is not None and name not in rows:
            continue
        est, st = run_replay(node, fr, work, f"row{k}")
        t = est[:, 0] + t0
        bad = np.nonzero((est[:, 2] != 0) & (t >= a))[0]
        t_rec = t[bad[-1] + 1] if bad.size and bad[-1] + 1 < len(t) else (b if not bad.size else np.inf)
        whole = a <= frames[0][0] and b >= frames[-1][0]        # the fault spans the run
        rec = None if whole else max(0.0, float(t_rec) - b)
        start = 0.0 if whole else max(b, float(t_rec))
        e_f, e_c = rms(est, start), rms(clean, start)
        moved = {key: v - st0["events"].get(key, 0) for key, v in st["events"].items()
                 if v != st0["events"].get(key, 0)}
        if st["frames_lost"] != st0["frames_lost"]:
            moved["frames_lost"] = st["frames_lost"] - st0["frames_lost"]
        out.append({"fault": name, "recovery_s": rec, "rms_mN": 1e3 * e_f,
                    "clean_rms_mN": 1e3 * e_c, "error_pct": 100.0 * e_f / e_c, "counters": moved})
    return out


def main(argv: list[str] | None = None) -> int:
    """python -m host_bench.faults [--node PATH] [--csv FILE]: the fault table (markdown)."""
    import argparse
    import subprocess
    import sys
    import tempfile
    from pathlib import Path
    ap = argparse.ArgumentParser(prog="python -m host_bench.faults",
                                 description="The node's fault table, replayed through nte-node "
                                 "--replay (deterministic; no CAN needed).")
    root = Path(__file__).resolve().parents[1]
    ap.add_argument("--node", default=str(root / "build/host/bin/nte-node"),
                    help="nte-node binary (default build/host/bin/nte-node)")
    ap.add_argument("--csv", default=None, help="scenario CSV with force_true_n (default: two "
                    "paper insertions, 50 mm at 10 mm/s, 1 s dwell, seed 1)")
    a = ap.parse_args(argv)
    if not Path(a.node).is_file():
        print(f"python -m host_bench.faults: error: --node: no such file {a.node} (make build)",
              file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as d:
        work = Path(d)
        csv = a.csv
        if csv is None:
            csv = str(work / "paper.csv")
            subprocess.run([sys.executable, "-m", "reference_py", "simulate", "--preset",
                            "paper-10mms", "--depth", "50", "--dwell", "1", "--seed", "1",
                            "--cycles", "2", "--out", csv], check=True, stdout=subprocess.DEVNULL)
        rows = table(a.node, csv, work)
    print("| fault | recovery (s) | RMS error (mN) | fault-free (mN) | error % | counters moved |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        c = ", ".join(f"{k} {v:+d}" for k, v in r["counters"].items())
        rec = "whole run" if r["recovery_s"] is None else f"{r['recovery_s']:.3f}"
        print(f"| {r['fault']} | {rec} | {r['rms_mN']:.2f} | "
              f"{r['clean_rms_mN']:.2f} | {r['error_pct']:.0f} | {c} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
