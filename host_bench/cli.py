"""nte-bench: drive the estimator node over CAN and check it against the reference.

    nte-bench replay FILE.csv|FILE.log --channel vcan0 [--interface socketcan|slcan]
                     [--speed X] [--depth-rate HZ] [--player python|canplayer] --out DIR
                     [--with-node [--node PATH]]
                     [--force-source T:sensor|model ...] [--sensor-fault T0:T1 ...]
                     [--sensor-lost T0:T1 ...]
    nte-bench check DIR [--model 1|2|3] [--preset NAME]
    nte-bench send FILE.csv [--channel vcan0] [--speed X] [--force-every N]
                   [--record-csv FILE] [--record-log FILE]
    nte-bench settings FILE.json [--channel vcan0] [--model 1|2|3]

replay sends a scenario (CSV: t_s, depth_mm, force_n, optional velocity_mm_s -- depth frames at
--depth-rate, linearly interpolated from the CSV, force frames at the CSV's own rate; or a
candump log, whose input frames are sent as they are) onto the bus at t / speed, records every
frame the node publishes (DIR/node.csv with can.CSVWriter, DIR/node.log in candump -L format),
runs the reference (reference_py FilterBank, float32, the node's configuration) on the SAME
quantised frames through host_bench.node_mirror, compares the node's Estimate and Params
frames with it raw value for raw value, writes DIR/summary.json, DIR/force.png and
DIR/params.png (parameters with +-3 sigma bands), and prints the final parameters.
--model 3 (the node started with --model 3): Model III with the contact front end, the CSV's
depth column the stage position; the Contact frames are compared too.
The force sensor's failures (the node's predict-only mode, nte_node.h PREDICT-ONLY): replay
--force-source T:model (or T:sensor) sends a Command with ForceSource at scenario time T s;
--sensor-fault T0:T1 sets SensorFault on the Force frames in [T0, T1) s (the driver flags them
bad); --sensor-lost T0:T1 leaves those Force frames out (a lost sensor).  Each may repeat.
replay --with-node starts nte-node on the channel first (the reference's model, preset, depth
timeout, Params per step and base id; ready when it says so) and stops it by its process group
after the replay, also when the replay fails: one command for replay, check and node.
replay --no-check stops after recording (DIR/record.json added); check DIR then does the
comparison and figures where no bus is needed -- on the host, when the bus lives in a slower
virtual machine (host_bench/with-vcan).
send sends a scenario CSV row by row (one Depth frame per row, a Force frame where force_n is
given) at its own timestamps and records the whole bus (host_bench.replay).
settings sends an estimator configuration file (the workflow's estimator_config.json, an
--export-config file) to the node as one transfer of Setting frames (nte_node.h SETTINGS;
host_bench.settings_file), the file read and checked by the readers' rules first; the node
applies it when the needle is out of tissue, as `nte-node --config FILE` would at start, and
restarts with the file's model (or --model's).  The transfer is not acknowledged by a frame:
settings then listens to the node's Heartbeat and says which model it runs.

The CSV is read by the tools' one reader (reference_py.tools.csvio). Values outside a signal's DBC range (read from
firmware/can/nte.dbc) are clipped to the range by replay, with a warning that counts them; send
refuses them. Every output is written by the tools' safe writer (all of DIR or nothing).
The socketcan interface needs a kernel with CAN (AF_CAN); elsewhere run the command under
host_bench/with-vcan, which provides vcan0.

Exit status: 0 done and no mismatch, 1 mismatches or frames missing, 2 bad arguments/input.
"""
from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from contextlib import ExitStack
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import can
import numpy as np

from reference_py.bus.candump import write_candump
from reference_py.bus.dbc import PARAM_NAMES, PARAM_SIGNALS, NteDatabase, log10_to_std
from reference_py.params import PRESETS
from reference_py.tools.arguments import (EXIT_BAD_INPUT, OneLineParser, add_unit_arguments,
                                          bounded, units_from)
from reference_py.tools.safe_write import Outputs

from .node_mirror import NODE, NodeMirror
from .node_outputs import compare, contact_outputs, health_outputs, node_outputs
from .one_cpu import pin_to_one_cpu
from .replay import paced, read_scenario, scenario_frames, send_retrying

if TYPE_CHECKING:
    from .started_node import StartedNode

PARAM_LABELS = PARAM_NAMES


def sensor_failures(frames: list[tuple[float, can.Message]], db: NteDatabase,
                    commands: Sequence[tuple[float, str]] = (),
                    faults: Sequence[tuple[float, float]] = (),
                    lost: Sequence[tuple[float, float]] = ()) -> list[tuple[float, can.Message]]:
    """`frames` with the force sensor's failures of replay's options (host_bench.sensor_failures):
    SensorFault on the Force frames in the `faults` spans, the Force frames of the `lost` spans
    left out, ForceSource Commands at the `commands` times (s, scenario time)."""
    from .sensor_failures import force_source_commands, sensor_fault, sensor_lost
    if faults:
        frames = sensor_fault(frames, db, list(faults))
    if lost:
        frames = sensor_lost(frames, db, list(lost))
    if commands:
        frames = force_source_commands(frames, db, list(commands))
    return frames


def _time_source(text: str) -> tuple[float, str]:
    t, sep, src = text.partition(":")
    try:
        ts = float(t)
    except ValueError:
        ts = float("nan")
    if not sep or src not in ("sensor", "model") or not ts >= 0.0:
        raise argparse.ArgumentTypeError(f"expected T:sensor or T:model with T >= 0 s "
                                         f"(got {text!r})")
    return ts, src


def _span(text: str) -> tuple[float, float]:
    a, sep, b = text.partition(":")
    try:
        t0, t1 = float(a), float(b)
    except ValueError:
        t0 = t1 = float("nan")
    if not sep or not 0.0 <= t0 < t1:
        raise argparse.ArgumentTypeError(f"expected T0:T1 with 0 <= T0 < T1 s (got {text!r})")
    return t0, t1


def log_frames(path: str) -> list[tuple[float, can.Message]]:
    try:
        msgs = list(can.LogReader(path))
    except OSError as exc:
        raise ValueError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except (ValueError, IndexError) as exc:
        raise ValueError(f"{path}: not a CAN log python-can can read: {exc}") from None
    if not msgs:
        raise ValueError(f"{path}: no frames")
    t0 = msgs[0].timestamp
    return [(m.timestamp - t0, m) for m in msgs if not m.is_error_frame]


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
        self.ids = {db.frame_id(n) for n in ("Estimate", "Params", "Heartbeat", "Contact",
                                             "Health")}
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
            vn = PARAM_SIGNALS[j][0]
            last[PARAM_LABELS[j]] = (float(sig[vn]), log10_to_std(float(sig[vn + "StdLog10"])))
    return last


def plot(files: Sequence[Path], db: NteDatabase, mirror: NodeMirror,
         messages: list[can.Message], params_per_step: int) -> None:
    """The force figure to files[0] and the parameter figure to files[1] (PNG)."""
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
            vn = PARAM_SIGNALS[j][0]
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
    fig.savefig(str(files[0]), dpi=110, format="png")
    plt.close(fig)
    n_par = 10 if any(jj >= 7 for _, jj, _, _ in par) else 7   # Model III: g's and delta
    fig, axs = plt.subplots((n_par + 1) // 2, 2, figsize=(10, 9 if n_par == 7 else 11),
                            sharex=True)
    for j, ax in enumerate(axs.flat[:n_par]):
        pts = [(t[s] if s < len(t) else np.nan, v, sd) for s, jj, v, sd in par if jj == j]
        if pts:
            tt, vv, ss = (np.array(x) for x in zip(*pts))
            ax.fill_between(tt, vv - 3 * ss, vv + 3 * ss, color="C1", alpha=0.3, label="±3σ")
            ax.plot(tt, vv, color="C1", lw=1)
        ax.set_title(PARAM_LABELS[j], fontsize=9)
    axs.flat[n_par].axis("off")
    for ax in axs[-1]:
        ax.set_xlabel("sensor time, s")
    fig.suptitle("Node parameters (Params frames) with ±3σ")
    fig.tight_layout()
    fig.savefig(str(files[1]), dpi=110, format="png")
    plt.close(fig)


def open_bus(interface: str, channel: str, bitrate: int,
             filters: list[dict] | None = None, command: str = "nte-bench") -> can.BusABC:
    """The python-can bus, or ValueError with one line saying why it cannot be opened."""
    try:
        if interface == "socketcan":
            return can.Bus(interface="socketcan", channel=channel, can_filters=filters,
                           receive_own_messages=False)
        return can.Bus(interface="slcan", channel=channel, bitrate=bitrate, sleep_after_open=0)
    except (OSError, can.CanError, ValueError) as exc:
        errno = getattr(exc, "errno", None) or getattr(exc.__cause__, "errno", None)
        if errno == 97 or "Address family not supported" in str(exc):
            raise ValueError(f"--interface socketcan: this host's kernel has no SocketCAN "
                             f"(AF_CAN); run it under host_bench/with-vcan, which provides vcan0: "
                             f"host_bench/with-vcan {command} ...") from None
        if errno == 19 or "No such device" in str(exc):
            raise ValueError(f"--channel {channel}: no such CAN interface (create vcan0 with "
                             f"'ip link add dev vcan0 type vcan', or run under "
                             f"host_bench/with-vcan)") from None
        raise ValueError(f"--channel {channel}: cannot open the {interface} bus: "
                         f"{exc}".splitlines()[0]) from None


def _note(text: str) -> None:
    """What the reader left out of a scenario, on stderr as the estimating tools write it."""
    print(text, file=sys.stderr)


def cmd_replay(a: argparse.Namespace) -> int:
    if a.speed <= 0 and a.player == "canplayer":
        raise ValueError("--player canplayer needs --speed > 0")
    db = NteDatabase(base_id=a.base_id)
    clipped: dict[str, int] = {}
    if a.file.endswith((".log", ".asc", ".blf", ".trc")):
        frames = log_frames(a.file)
    else:
        frames = scenario_frames(a.file, db, a.depth_rate, clipped, units_from(a), _note)
    frames = sensor_failures(frames, db, a.force_source, a.sensor_fault, a.sensor_lost)
    for sig, n in sorted(clipped.items()):
        lo, hi = db.signal_range("Force" if sig == "Force" else "Depth", sig)
        print(f"nte-bench: warning: {n} {sig} value(s) outside the DBC range "
              f"[{lo:g}, {hi:g}] clipped to it", file=sys.stderr)
    with Outputs() as outs:
        out = outs.directory(a.out, "--out")
        names = ["input.log", "node.csv", "node.log", "record.json"]
        if not a.no_check:
            names.append("summary.json")
            if not a.no_plot:
                names += ["force.png", "params.png"]
        tmp = {n: outs.add(out / n, "--out") for n in names}
        write_candump(tmp["input.log"], frames, a.channel, a.speed if a.speed > 0 else 1.0)
        collector = _Collect(db, [])
        filters = [{"can_id": i, "can_mask": 0x7FF, "extended": False} for i in collector.ids]
        node = _with_node(a)
        with ExitStack() as stack:
            if node is not None:
                stack.enter_context(node)       # stopped on the way out, whatever happens
            bus = open_bus(a.interface, a.channel, a.bitrate, filters, "nte-bench replay")
            writers: list[can.Listener] = [
                can.CSVWriter(str(tmp["node.csv"])),
                can.CanutilsLogWriter(str(tmp["node.log"]), channel=a.channel)]
            collector.writers = writers
            notifier = can.Notifier(bus, [collector])
            t_start = time.monotonic()
            try:
                pin_to_one_cpu()   # the frames' order on vcan (one_cpu.py); canplayer inherits it
                if a.player == "canplayer":
                    _send_canplayer(tmp["input.log"], (frames[-1][0] - frames[0][0]) / a.speed,
                                    not a.no_progress)
                else:
                    paced(frames, a.speed, lambda m: send_retrying(bus, m), not a.no_progress)
                time.sleep(a.tail)
            finally:
                notifier.stop()
                bus.shutdown()
                for w in writers:
                    w.stop()
            record = {"frames_sent": len(frames),
                      "wall_s": round(time.monotonic() - t_start, 3),
                      "input_values_clipped": clipped}
            if node is not None:
                record["node_exit_status"] = node.stop()
        outs.write_lines(tmp["record.json"], [json.dumps(record, indent=2)])
        if not a.no_check:
            res = check_against_reference(a, db, frames, collector.messages, record, tmp,
                                          outs, out)
        outs.commit()
    print(f"nte-bench: sent {len(frames)} frames in {record['wall_s']:.1f} s; recorded "
          f"{len(collector.messages)} frames from the node (Estimate, Params, Heartbeat, Contact, Health)")
    if a.no_check:
        print(f"recorded in {a.out}; compare with the reference: nte-bench check {a.out}")
        return 0
    return report(res)


def _with_node(a: argparse.Namespace) -> "StartedNode | None":
    """--with-node: the node to start on the replay's interface (not yet started)."""
    if not a.with_node:
        return None
    if a.interface != "socketcan":
        raise ValueError("--with-node starts nte-node on a SocketCAN interface; with "
                         "--interface slcan the node is the board")
    from .started_node import StartedNode, node_arguments, node_program
    return StartedNode(node_program(a.node), node_arguments(
        a.channel, a.model, a.preset, a.depth_timeout_ms, a.params_per_step, a.base_id))


def check_against_reference(a: argparse.Namespace, db: NteDatabase,
                            frames: list[tuple[float, can.Message]], messages: list[can.Message],
                            record: dict, tmp: dict[str, Path], outs: Outputs,
                            out: Path) -> dict:
    """The reference (host_bench.node_mirror) fed the frames that were sent, compared with what
    the node published; summary.json and, unless --no-plot, the figures."""
    mirror = NodeMirror(preset=a.preset, model=a.model, base_id=a.base_id,
                        depth_timeout_us=int(a.depth_timeout_ms * 1000),
                        params_per_step=a.params_per_step)
    mirror.feed_all(m for _, m in frames)
    est, par, bad = node_outputs(db, messages)
    contacts, bad_c = contact_outputs(db, messages)
    healths, bad_h = health_outputs(db, messages)
    res = compare(mirror, est, par, contacts, healths)
    bad += bad_c + bad_h
    res.update({"frames_sent": record["frames_sent"], "output_frames_received": len(messages),
                "output_e2e_errors": bad, "wall_s": record["wall_s"],
                "mirror_events": mirror.events,
                "input_values_clipped": record["input_values_clipped"]})
    res["final_parameters"] = {k: {"value": v, "sd": s}
                               for k, (v, s) in final_parameters(db, messages).items()}
    if not a.no_plot:
        plot([tmp["force.png"], tmp["params.png"]], db, mirror, messages, a.params_per_step)
        res["figures"] = [str(out / "force.png"), str(out / "params.png")]
    outs.write_lines(tmp["summary.json"], [json.dumps(res, indent=2)])
    return res


def report(res: dict) -> int:
    """Print the agreement and the final parameters; 0 when the node equals the reference."""
    print(f"node published {res['estimates_node']} estimates (reference "
          f"{res['estimates_reference']}), {res['params_node']} params frames")
    print(f"agreement with the reference (same quantised inputs, float32): "
          f"{res['estimate_mismatches']} estimate mismatches, "
          f"{res['param_value_mismatches']} parameter value mismatches, "
          f"{res['param_std_mismatches']} sd mismatches "
          f"({res['param_std_beyond_1lsb']} beyond 1 LSB)")
    print("final parameters (value ± sd):")
    for k, v in res["final_parameters"].items():
        print(f"  {k:7s} {v['value']:.6g} ± {v['sd']:.3g}")
    n_clip = sum(res["input_values_clipped"].values())
    events = ", ".join(f"{k} {v}" for k, v in sorted(res.get("mirror_events", {}).items()))
    print(f"frames: {res['frames_sent']} sent, {n_clip} input values clipped to the DBC ranges; "
          f"reference node events: {events or 'none'}")
    if res.get("contact_reference") or res.get("contact_node"):
        print(f"Contact frames: {res['contact_node']} (reference {res['contact_reference']}), "
              f"{res['contact_mismatches']} mismatches")
    print(f"Health frames: {res['health_node']} (reference {res['health_reference']}), "
          f"{res['health_mismatches']} mismatches")
    ok = (res["estimate_mismatches"] == 0 and res["param_value_mismatches"] == 0
          and res["estimates_node"] == res["estimates_reference"]
          and res.get("contact_mismatches", 0) == 0
          and res.get("contact_node", 0) == res.get("contact_reference", 0)
          and res["health_mismatches"] == 0 and res["health_node"] == res["health_reference"]
          and res["output_e2e_errors"] == 0)
    return 0 if ok else 1


def cmd_check(a: argparse.Namespace) -> int:
    """The check half of replay, on a directory that `replay --no-check` recorded: it needs no
    bus, so it runs outside the kernel that carried the bus."""
    d = Path(a.dir)
    node_log = Path(a.node_log) if a.node_log else d / "node.log"
    for f in (d / "input.log", d / "record.json", node_log):
        if not f.is_file():
            raise ValueError(f"{f}: missing (record it with nte-bench replay --no-check "
                             f"--out {d})")
    try:
        record = json.loads((d / "record.json").read_text())
        record["frames_sent"], record["wall_s"], record["input_values_clipped"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{d / 'record.json'}: not a replay record ({exc})") from None
    db = NteDatabase(base_id=a.base_id)
    frames = log_frames(str(d / "input.log"))
    try:
        ids = _Collect(db, []).ids
        messages = [m for m in can.CanutilsLogReader(str(node_log))
                    if not m.is_error_frame and m.arbitration_id in ids]
    except (ValueError, IndexError) as exc:
        raise ValueError(f"{node_log}: not a candump log: {exc}") from None
    with Outputs() as outs:
        out = outs.directory(a.dir, "DIR")
        names = ["summary.json"] + ([] if a.no_plot else ["force.png", "params.png"])
        tmp = {n: outs.add(out / n, "DIR") for n in names}
        res = check_against_reference(a, db, frames, messages, record, tmp, outs, out)
        outs.commit()
    return report(res)


def cmd_send(a: argparse.Namespace) -> int:
    from .replay import replay, schedule
    db = NteDatabase(base_id=a.base_id)
    frames = schedule(read_scenario(a.file, units_from(a), _note), db,
                      force_every=a.force_every)
    with Outputs() as outs:
        rec_csv = outs.add(a.record_csv, "--record-csv") if a.record_csv else None
        rec_log = outs.add(a.record_log, "--record-log") if a.record_log else None
        bus = open_bus(a.interface, a.channel, a.bitrate, None, "nte-bench send")
        writers: list[can.Listener] = []
        if rec_csv is not None:
            writers.append(can.CSVWriter(str(rec_csv)))
        if rec_log is not None:
            writers.append(can.CanutilsLogWriter(str(rec_log), channel=a.channel))
        try:
            res = replay(bus, frames, speed=a.speed, writers=writers, tail_s=a.tail, db=db)
        finally:
            bus.shutdown()
            for w in writers:
                w.stop()
        outs.commit()
    sent = ", ".join(f"{k} {v}" for k, v in sorted(res.sent_by_name.items()))
    print(f"replay: sent {res.sent} frames ({sent}) in {res.duration_s:.3f} s, received "
          f"{res.received}, worst lateness {res.max_late_s * 1e3:.2f} ms")
    return 0


def cmd_settings(a: argparse.Namespace) -> int:
    from dataclasses import replace
    from reference_py.tools.estconfig import read_config_file
    from .settings_file import setting_items, transfer
    db = NteDatabase(base_id=a.base_id)
    fc = read_config_file(a.file)        # a ConfigFileError is main's one line, exit 2
    if a.model is not None:
        fc = replace(fc, model=a.model)
    frames = transfer(setting_items(fc, db), db.sender())
    heartbeat = db.frame_id("Heartbeat")
    bus = open_bus(a.interface, a.channel, a.bitrate, None, "nte-bench settings")
    try:
        for m in frames:
            bus.send(m)
        models: list[int] = []
        deadline = time.monotonic() + a.listen
        while time.monotonic() < deadline:
            m = bus.recv(timeout=max(0.0, deadline - time.monotonic()))
            if m is not None and m.arbitration_id == heartbeat and not m.is_extended_id:
                models.append(int(db.decode_unchecked("Heartbeat", bytes(m.data))["ActiveModel"]))
    finally:
        bus.shutdown()
    print(f"settings: sent {len(frames)} Setting frames ({len(frames) - 2} items of "
          f"{a.file}, model {fc.model})")
    if not models:
        print(f"settings: no Heartbeat within {a.listen:g} s: is the node on {a.channel}?")
        return 1
    running = models[-1] + 1
    if running != fc.model:
        print(f"settings: the node runs Model {running}, not {fc.model}: refused (needle in "
              f"tissue, a lost frame: nte-node --stats counts setting_refused); send it again")
        return 1
    print(f"settings: the node runs Model {running}")
    return 0


def _bus_flags(r: argparse.ArgumentParser, tail_s: float | None) -> None:
    """The bus's flags; with tail_s (not None) the sending's --speed and --tail too."""
    r.add_argument("--channel", default="vcan0",
                   help="socketcan interface name, or slcan serial port / pyserial URL such as "
                        "socket://127.0.0.1:PORT")
    r.add_argument("--interface", default="socketcan", choices=("socketcan", "slcan"),
                   help="python-can interface")
    r.add_argument("--bitrate", type=bounded(10_000, 1_000_000, " bit/s", integer=True),
                   default=500000, help="slcan bit rate")
    r.add_argument("--base-id", type=_base_id, default=None,
                   help="base CAN id, 0x000-0x7F0 (default: the DBC's NteBaseId, 0x200)")
    if tail_s is None:
        return
    r.add_argument("--speed", type=bounded(0.0, 100.0), default=1.0,
                   help="time scale: 1 real time, 0.5 half speed, 0 as fast as possible")
    r.add_argument("--tail", type=bounded(0.0, 60.0, " s"), default=tail_s, metavar="S",
                   help="keep recording S seconds after the last frame")


def _base_id(text: str) -> int:
    try:
        value = int(text, 0)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if not 0 <= value <= 0x7F0:
        raise argparse.ArgumentTypeError(f"must be within 0x000..0x7F0 (got {text})")
    return value


def _node_flags(r: argparse.ArgumentParser) -> None:
    """The node's settings the reference must share (defaulting to the node's, nte_node.h)."""
    r.add_argument("--model", type=int, choices=(1, 2, 3), default=NODE["DEFAULT_MODEL"],
                   help="the node's model (3: Model III with the contact front end, the depth "
                        "column the stage position)")
    r.add_argument("--preset", default="paper-10mms", choices=sorted(PRESETS), metavar="NAME",
                   help=f"the node's preset, one of {', '.join(sorted(PRESETS))}")
    r.add_argument("--depth-timeout-ms", type=bounded(0.0, 60_000.0, " ms", lo_open=True),
                   default=NODE["DEFAULT_DEPTH_TIMEOUT_US"] / 1000.0,
                   help="the node's depth timeout, ms")
    r.add_argument("--params-per-step", type=bounded(1, 7, integer=True),
                   default=NODE["DEFAULT_PARAMS_PER_STEP"],
                   help="the node's setting: Params frames per estimator step")


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="nte-bench", description=__doc__.split("\n\n")[0],
                      epilog=__doc__.split("\n\n", 1)[1])
    sub = p.add_subparsers(dest="cmd", required=True, parser_class=OneLineParser)
    r = sub.add_parser("replay", help="replay a scenario CSV or candump log to the node and "
                                      "compare its outputs with the reference",
                       description="Replay a scenario CSV or candump log to the node and compare "
                                   "its Estimate and Params frames with the reference.")
    r.add_argument("file", help="scenario CSV (t_s, depth_mm, force_n, optional velocity_mm_s) "
                                "or a candump log (.log)")
    _bus_flags(r, 0.5)
    r.add_argument("--depth-rate", type=bounded(0.0, 10_000.0, " Hz", lo_open=True),
                   default=1000.0, help="depth frame rate, Hz")
    r.add_argument("--player", choices=("python", "canplayer"), default="python",
                   help="who sends: python-can, or can-utils canplayer (full rate)")
    _node_flags(r)
    add_unit_arguments(r)
    r.add_argument("--force-source", type=_time_source, action="append", default=[],
                   metavar="T:SOURCE", help="send a Command with ForceSource SOURCE (sensor: "
                   "identify, model: predict-only) at scenario time T s; may repeat")
    r.add_argument("--sensor-fault", type=_span, action="append", default=[], metavar="T0:T1",
                   help="set SensorFault on the Force frames in [T0, T1) s; may repeat")
    r.add_argument("--sensor-lost", type=_span, action="append", default=[], metavar="T0:T1",
                   help="leave out the Force frames in [T0, T1) s (a lost sensor); may repeat")
    r.add_argument("--no-plot", action="store_true", help="do not draw force.png, params.png")
    r.add_argument("--with-node", action="store_true",
                   help="start nte-node on --channel with the reference's settings (--model, "
                        "--preset, --depth-timeout-ms, --params-per-step, --base-id) before the "
                        "replay and stop it after (SocketCAN only)")
    r.add_argument("--node", metavar="PATH", default=None,
                   help="the nte-node program for --with-node (default: the repository's "
                        "build/host/bin/nte-node, else nte-node on PATH)")
    r.add_argument("--no-check", action="store_true",
                   help="send and record only (input.log, node.log, node.csv, record.json); "
                        "compare later, outside the bus's kernel, with nte-bench check DIR")
    r.add_argument("--no-progress", action="store_true", help="no progress bar")
    r.add_argument("--out", required=True, help="output directory (created if absent; its "
                                                "parent must exist)")
    r.set_defaults(run=cmd_replay)
    c = sub.add_parser("check", help="compare a recorded replay with the reference",
                       description="Compare what `nte-bench replay --no-check --out DIR` "
                                   "recorded with the reference fed the same frames: "
                                   "DIR/summary.json and the figures.  Needs no bus.")
    c.add_argument("dir", metavar="DIR", help="the directory replay --no-check wrote")
    c.add_argument("--base-id", type=_base_id, default=None,
                   help="the node's base CAN id (as in replay)")
    c.add_argument("--node-log", metavar="FILE", default=None,
                   help="the node's outputs from this candump log instead of DIR/node.log, e.g. "
                        "the node's own record of what it sent (nte-node --record), which is "
                        "complete even where a recorder on a loaded machine drops frames")
    _node_flags(c)
    c.add_argument("--no-plot", action="store_true", help="do not draw force.png, params.png")
    c.set_defaults(run=cmd_check)
    s = sub.add_parser("send", help="send a scenario CSV row by row and record the bus",
                       description="Send a scenario CSV as Depth and Force frames of "
                                   "firmware/can/nte.dbc (E2E protected) at their timestamps, "
                                   "recording everything received.")
    s.add_argument("file", help="scenario CSV (t_s, depth_mm, force_n, optional velocity_mm_s)")
    _bus_flags(s, 0.2)
    s.add_argument("--force-every", type=bounded(1, 1000, integer=True), default=1, metavar="N",
                   help="send every N-th force sample only")
    add_unit_arguments(s)
    s.add_argument("--record-csv", metavar="FILE", help="write all frames with can.CSVWriter")
    s.add_argument("--record-log", metavar="FILE",
                   help="write all frames in candump -L format (can.CanutilsLogWriter)")
    s.set_defaults(run=cmd_send)

    g = sub.add_parser("settings", help="send an estimator configuration file to the node",
                       description="Send an estimator configuration file (--config's schema) "
                                   "to the node as one transfer of Setting frames; the node "
                                   "applies it out of tissue as nte-node --config would.")
    g.add_argument("file", help="estimator configuration JSON (nte-estimator-config/1)")
    _bus_flags(g, None)
    g.add_argument("--model", type=int, choices=(1, 2, 3), default=None,
                   help="the model to run (default: the file's)")
    g.add_argument("--listen", type=bounded(0.0, 10.0, " s", lo_open=True), default=0.5,
                   metavar="S", help="listen S seconds for the node's Heartbeat after sending")
    g.set_defaults(run=cmd_settings)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    try:
        return int(a.run(a))
    except ValueError as exc:       # CsvError, OutputError, a bad scenario, an unopenable bus
        print(f"nte-bench: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT


if __name__ == "__main__":
    sys.exit(main())
