"""nte-bench: drive the estimator node over CAN and check it against the reference.

    nte-bench replay FILE.csv|FILE.log --channel vcan0 [--interface socketcan|slcan]
                     [--speed X] [--depth-rate HZ] [--player python|canplayer] --out DIR

replay sends a scenario (CSV: t_s, depth_mm, velocity_mm_s, force_n -- depth frames at
--depth-rate, linearly interpolated from the CSV, force frames at the CSV's own rate; or a
candump log, whose input frames are sent as they are) onto the bus at t / speed, records every
frame the node publishes (DIR/node.csv with can.CSVWriter, DIR/node.log in candump -L format),
runs the reference (reference_py FilterBank, float32, the node's configuration) on the SAME
quantised frames through host_bench.node_mirror, compares the node's Estimate and Params
frames with it raw value for raw value, writes DIR/summary.json, DIR/force.png and
DIR/params.png (parameters with +-3 sigma bands), and prints the final parameters.

Exit status: 0 done and no mismatch, 1 mismatches or frames missing, 2 bad arguments/input.
"""
from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Sequence

import can
import numpy as np

from .dbc import TICK_S, NteDatabase, seconds_to_ticks, log10_to_std
from .node_mirror import NodeMirror, compare, node_outputs
from .replay import read_scenario

PARAM_LABELS = ("sigma0", "sigma1", "sigma2", "f1", "f2", "alpha", "beta")


def scenario_frames(csv_path: str, db: NteDatabase, depth_rate_hz: float) -> list[tuple[float, can.Message]]:
    """(t_s, message) for a scenario CSV: depth at depth_rate_hz (interpolated), force at the
    CSV rows that have one; at equal times depth first.  Times are on the 100 us tick grid."""
    rows = read_scenario(csv_path)
    t = np.array([r.t_s for r in rows])
    d = np.array([r.depth_mm for r in rows])
    v = np.array([r.velocity_mm_s for r in rows])
    tx = db.sender()
    step_ticks = max(1, int(round(1.0 / depth_rate_hz / TICK_S)))
    t0 = int(round(t[0] / TICK_S))
    t1 = int(round(t[-1] / TICK_S))
    events: list[tuple[int, int, float, float]] = []   # (ticks, kind 0 depth / 1 force, a, b)
    for k in range(t0, t1 + 1, step_ticks):
        ts = k * TICK_S
        events.append((k, 0, float(np.interp(ts, t, d)), float(np.interp(ts, t, v))))
    for r in rows:
        if r.force_n is not None:
            events.append((int(round(r.t_s / TICK_S)), 1, r.force_n, 0.0))
    events.sort(key=lambda e: (e[0], e[1]))
    out = []
    for k, kind, a, b in events:
        st = (k % 65536) * TICK_S
        if kind == 0:
            a = min(max(a, 0.0), 500.0)
            msg = tx.message("Depth", {"Depth": a, "Velocity": min(max(b, -500.0), 500.0),
                                       "SensorTime": st})
        else:
            msg = tx.message("Force", {"Force": min(max(a, -50.0), 50.0), "SensorTime": st})
        out.append((k * TICK_S, msg))
    return out


def log_frames(path: str) -> list[tuple[float, can.Message]]:
    msgs = list(can.LogReader(path))
    if not msgs:
        raise ValueError(f"{path}: no frames")
    t0 = msgs[0].timestamp
    return [(m.timestamp - t0, m) for m in msgs if not m.is_error_frame]


def write_candump(path: Path, frames: list[tuple[float, can.Message]], channel: str,
                  speed: float, start: float = 1_000_000.0) -> None:
    """candump -l format, times scaled by 1/speed (canplayer replays them in real time)."""
    with open(path, "w") as f:
        for t, m in frames:
            ts = start + t / speed
            ident = f"{m.arbitration_id:08X}" if m.is_extended_id else f"{m.arbitration_id:03X}"
            f.write(f"({ts:.6f}) {channel} {ident}#{bytes(m.data).hex().upper()}\n")


def _send_python(bus: can.BusABC, frames, speed: float, progress: bool) -> float:
    from tqdm import tqdm
    it = tqdm(frames, desc="replay", unit="frame", disable=None if progress else True, leave=False)
    t_first = frames[0][0]
    start = time.perf_counter()
    worst = 0.0
    for t, m in it:
        if speed > 0:
            target = start + (t - t_first) / speed
            while True:
                now = time.perf_counter()
                if now >= target:
                    break
                time.sleep(min(target - now, 0.002) if target - now > 0.0005 else 0)
            worst = max(worst, time.perf_counter() - target)
        for attempt in range(200):
            try:
                bus.send(can.Message(arbitration_id=m.arbitration_id, data=m.data,
                                     is_extended_id=m.is_extended_id))
                break
            except can.CanOperationError:      # ENOBUFS: the TX queue is full, retry
                time.sleep(0.0005)
    return worst


def _send_canplayer(log: Path, duration_s: float, progress: bool) -> None:
    from tqdm import tqdm
    exe = shutil.which("canplayer")
    if exe is None:
        raise RuntimeError("canplayer not found (apt-get install can-utils)")
    proc = subprocess.Popen([exe, "-I", str(log)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    try:
        bar = tqdm(total=max(duration_s, 0.001), desc="canplayer", unit="s", disable=None if progress else True,
                   leave=False, bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} s")
        t0 = time.monotonic()
        while proc.poll() is None:
            time.sleep(0.1)
            bar.n = min(time.monotonic() - t0, duration_s)
            bar.refresh()
        bar.close()
        if proc.returncode != 0:
            raise RuntimeError(f"canplayer failed: {proc.stderr.read().decode(errors='replace') if proc.stderr else ''}")
    finally:
        if proc.poll() is None:
            proc.terminate()
            proc.wait(5)


class _Collect(can.Listener):
    def __init__(self, db: NteDatabase, writers: Sequence[can.Listener]) -> None:
        self.ids = {db.frame_id(n) for n in ("Estimate", "Params", "Heartbeat")}
        self.writers = list(writers)
        self.messages: list[can.Message] = []

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id not in self.ids or msg.is_error_frame:
            return
        msg.is_rx = True
        self.messages.append(msg)
        for w in self.writers:
            w.on_message_received(msg)


def final_parameters(db: NteDatabase, messages: list[can.Message]) -> dict[str, tuple[float, float]]:
    rx = db.receiver()
    last: dict[str, tuple[float, float]] = {}
    for m in messages:
        name, sig, _ = rx.decode(m.arbitration_id, bytes(m.data))
        if name == "Params" and sig is not None:
            j = int(sig["ParamIndex"])
            vn = ("Sigma0", "Sigma1", "Sigma2", "F1", "F2", "Alpha", "Beta")[j]
            last[PARAM_LABELS[j]] = (float(sig[vn]), log10_to_std(float(sig[vn + "StdLog10"])))
    return last


def plot(out: Path, db: NteDatabase, mirror: NodeMirror, messages: list[can.Message],
         params_per_step: int) -> list[str]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rx = db.receiver()
    est_f, par = [], []
    for m in messages:
        name, sig, _ = rx.decode(m.arbitration_id, bytes(m.data))
        if sig is None:
            continue
        if name == "Estimate":
            est_f.append(float(sig["ForceEst"]))
        elif name == "Params":
            j = int(sig["ParamIndex"])
            vn = ("Sigma0", "Sigma1", "Sigma2", "F1", "F2", "Alpha", "Beta")[j]
            par.append((len(par) // params_per_step, j, float(sig[vn]),
                        log10_to_std(float(sig[vn + "StdLog10"]))))
    t = np.array([tr[0] for tr in mirror.trace])
    meas = np.array([tr[1] for tr in mirror.trace])
    n = min(len(t), len(est_f))
    fig, ax = plt.subplots(figsize=(9, 4))
    ax.plot(t[:n], meas[:n], ".", ms=2, color="0.6", label="measured force (sent)")
    ax.plot(t[:n], est_f[:n], "-", lw=1, color="C0", label="node estimate (Estimate frames)")
    ax.set_xlabel("sensor time, s")
    ax.set_ylabel("force, N")
    ax.legend()
    ax.set_title("Force loop over CAN")
    fig.tight_layout()
    files = [str(out / "force.png")]
    fig.savefig(files[0], dpi=110)
    plt.close(fig)
    fig, axs = plt.subplots(4, 2, figsize=(10, 9), sharex=True)
    for j, ax in enumerate(axs.flat[:7]):
        pts = [(t[s] if s < len(t) else np.nan, v, sd) for s, jj, v, sd in par if jj == j]
        if pts:
            tt, vv, ss = (np.array(x) for x in zip(*pts))
            ax.fill_between(tt, vv - 3 * ss, vv + 3 * ss, color="C1", alpha=0.3, label="±3σ")
            ax.plot(tt, vv, color="C1", lw=1)
        ax.set_title(PARAM_LABELS[j], fontsize=9)
    axs.flat[7].axis("off")
    for ax in axs[-1]:
        ax.set_xlabel("sensor time, s")
    fig.suptitle("Node parameters (Params frames) with ±3σ")
    fig.tight_layout()
    files.append(str(out / "params.png"))
    fig.savefig(files[1], dpi=110)
    plt.close(fig)
    return files


def cmd_replay(a: argparse.Namespace) -> int:
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    db = NteDatabase(base_id=a.base_id)
    try:
        if a.file.endswith((".log", ".asc", ".blf", ".trc")):
            frames = log_frames(a.file)
        else:
            frames = scenario_frames(a.file, db, a.depth_rate)
    except (OSError, ValueError) as exc:
        print(f"nte-bench: {exc}", file=sys.stderr)
        return 2
    if a.speed <= 0 and a.player == "canplayer":
        print("nte-bench: --player canplayer needs --speed > 0", file=sys.stderr)
        return 2
    write_candump(out / "input.log", frames, a.channel, a.speed if a.speed > 0 else 1.0)
    writers: list[can.Listener] = [can.CSVWriter(str(out / "node.csv")),
                                   can.CanutilsLogWriter(str(out / "node.log"), channel=a.channel)]
    collector = _Collect(db, writers)
    if a.interface == "socketcan":
        filters = [{"can_id": i, "can_mask": 0x7FF, "extended": False} for i in collector.ids]
        bus = can.Bus(interface="socketcan", channel=a.channel, can_filters=filters,
                      receive_own_messages=False)
    else:
        bus = can.Bus(interface="slcan", channel=a.channel, bitrate=a.bitrate, sleep_after_open=0)
    notifier = can.Notifier(bus, [collector])
    t_start = time.monotonic()
    try:
        if a.player == "canplayer":
            _send_canplayer(out / "input.log", (frames[-1][0] - frames[0][0]) / a.speed,
                            not a.no_progress)
        else:
            _send_python(bus, frames, a.speed, not a.no_progress)
        time.sleep(a.tail)
    finally:
        notifier.stop()
        bus.shutdown()
        for w in writers:
            w.stop()
    wall = time.monotonic() - t_start
    mirror = NodeMirror(preset=a.preset, model=a.model, base_id=a.base_id,
                        depth_timeout_us=int(a.depth_timeout_ms * 1000),
                        params_per_step=a.params_per_step)
    mirror.feed_all(m for _, m in frames)
    est, par, bad = node_outputs(db, collector.messages)
    res = compare(mirror, est, par)
    res.update({"frames_sent": len(frames), "output_frames_received": len(collector.messages),
                "output_e2e_errors": bad, "wall_s": round(wall, 3),
                "mirror_events": mirror.events})
    res["final_parameters"] = {k: {"value": v, "sd": s}
                               for k, (v, s) in final_parameters(db, collector.messages).items()}
    if not a.no_plot:
        res["figures"] = plot(out, db, mirror, collector.messages, a.params_per_step)
    (out / "summary.json").write_text(json.dumps(res, indent=2) + "\n")
    print(f"nte-bench: sent {len(frames)} frames in {wall:.1f} s; node published "
          f"{res['estimates_node']} estimates (reference {res['estimates_reference']}), "
          f"{res['params_node']} params frames")
    print(f"agreement with the reference (same quantised inputs, float32): "
          f"{res['estimate_mismatches']} estimate mismatches, "
          f"{res['param_value_mismatches']} parameter value mismatches, "
          f"{res['param_std_mismatches']} sd mismatches "
          f"({res['param_std_beyond_1lsb']} beyond 1 LSB)")
    print("final parameters (value ± sd):")
    for k, v in res["final_parameters"].items():
        print(f"  {k:7s} {v['value']:.6g} ± {v['sd']:.3g}")
    ok = (res["estimate_mismatches"] == 0 and res["param_value_mismatches"] == 0
          and res["estimates_node"] == res["estimates_reference"] and bad == 0)
    return 0 if ok else 1


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="nte-bench", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog=__doc__.split("\n\n", 1)[1])
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("replay", help="replay a scenario CSV or candump log to the node and "
                                      "compare its outputs with the reference")
    r.add_argument("file", help="scenario CSV (t_s, depth_mm, velocity_mm_s, force_n) or a "
                                "candump log (.log)")
    r.add_argument("--channel", default="vcan0", help="CAN interface or slcan port (vcan0)")
    r.add_argument("--interface", default="socketcan", choices=("socketcan", "slcan"))
    r.add_argument("--bitrate", type=int, default=500000, help="slcan bit rate")
    r.add_argument("--speed", type=float, default=1.0,
                   help="time scale: 1 real time, 0.5 half speed, 0 as fast as possible")
    r.add_argument("--depth-rate", type=float, default=1000.0, help="depth frame rate, Hz")
    r.add_argument("--player", choices=("python", "canplayer"), default="python",
                   help="who sends: python-can, or can-utils canplayer (full rate)")
    r.add_argument("--base-id", type=lambda s: int(s, 0), default=None)
    r.add_argument("--model", type=int, choices=(1, 2), default=2, help="the node's model")
    r.add_argument("--preset", default="paper-10mms", help="the node's preset")
    r.add_argument("--depth-timeout-ms", type=float, default=50.0, help="the node's timeout")
    r.add_argument("--params-per-step", type=int, default=1, help="the node's setting")
    r.add_argument("--tail", type=float, default=0.5, help="record S s after the last frame")
    r.add_argument("--no-plot", action="store_true")
    r.add_argument("--no-progress", action="store_true")
    r.add_argument("--out", required=True, help="output directory")
    a = p.parse_args(argv)
    return cmd_replay(a)


if __name__ == "__main__":
    sys.exit(main())
