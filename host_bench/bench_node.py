"""Benchmark of nte-node on vcan, inside one kernel, in one run (figures printed):

  1. latency, frame in -> estimate out: the paper scenario (1 kHz depth, 200 Hz force) played
     by canplayer; candump stamps every frame on arrival (kernel time stamps, one socket); for
     the k-th Force frame and the k-th Estimate frame, latency = t(Estimate) - t(Force);
     p50, p99, max;
  2. the highest force rate sustained without loss: 3 s streams with force (and depth, same
     time stamps) at increasing rates played by canplayer; a rate is sustained when the node
     accepted every input frame, stepped once per force frame and sent every output
     (node counters, SIGUSR1/exit stats), no queue overflow, no send failure.

    host_bench/with-vcan .venv/bin/python -m host_bench.bench_node [--node PATH] [--out DIR]
"""
from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import can
import numpy as np

from reference_py.bus.candump import write_candump
from reference_py.bus.dbc import TICK_S, NteDatabase

from .one_cpu import pin_to_one_cpu
from .replay import FrameEncoder, ScheduledFrame, scenario_frames

ROOT = Path(__file__).resolve().parents[1]
DB = NteDatabase()


def _node_path(arg: str | None) -> str:
    if arg:
        return arg
    for c in (ROOT / "build/host/bin/nte-node", ROOT / "build/node/bin/nte-node"):
        if c.exists():
            return str(c)
    raise SystemExit("nte-node not built")


class Node:
    def __init__(self, exe: str, out: Path, tag: str) -> None:
        self.stats = out / f"{tag}.stats.json"
        ready = out / f"{tag}.ready"
        ready.unlink(missing_ok=True)
        self.p = subprocess.Popen([exe, "--iface", "vcan0", "--ready", str(ready), "--stats",
                                   str(self.stats)], stderr=subprocess.DEVNULL)
        for _ in range(200):
            if ready.exists():
                return
            time.sleep(0.05)
        self.stop()
        raise RuntimeError("node did not start")

    def stop(self) -> dict:
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGTERM)
            self.p.wait(10)
        return json.loads(self.stats.read_text()) if self.stats.exists() else {}


def _play(log: Path) -> None:
    pin_to_one_cpu()   # the frames' order on vcan (one_cpu.py); canplayer inherits it
    subprocess.run(["canplayer", "-I", str(log)], check=True)


def latency(exe: str, out: Path) -> dict:
    csv = out / "paper.csv"
    subprocess.run([sys.executable, "-m", "reference_py", "simulate", "--preset", "paper-10mms",
                    "--depth", "50", "--dwell", "1", "--seed", "1", "--out", str(csv)],
                   check=True, stdout=subprocess.DEVNULL)
    write_candump(out / "lat_in.log", scenario_frames(str(csv), DB, 1000.0), "vcan0", 1.0)
    node = Node(exe, out, "lat")
    dump = subprocess.Popen(["candump", "-L", "-r", "16000000", "vcan0"], stdout=open(out / "lat_cap.log", "w"))
    time.sleep(0.3)
    try:
        _play(out / "lat_in.log")
        time.sleep(0.5)
    finally:
        dump.send_signal(signal.SIGTERM)
        dump.wait(10)
        node.stop()
    cap = list(can.CanutilsLogReader(str(out / "lat_cap.log")))
    tf = [m.timestamp for m in cap if m.arbitration_id == DB.frame_id("Force")]
    te = [m.timestamp for m in cap if m.arbitration_id == DB.frame_id("Estimate")]
    n = min(len(tf), len(te))
    lat = np.array(te[:n]) - np.array(tf[:n])
    return {"n": n, "forces": len(tf), "estimates": len(te),
            "p50_ms": float(np.percentile(lat, 50) * 1e3),
            "p99_ms": float(np.percentile(lat, 99) * 1e3), "max_ms": float(lat.max() * 1e3)}


def rate_stream(rate_hz: float, seconds: float) -> list[ScheduledFrame]:
    """A Depth and a Force frame every 1/rate_hz s (10 mm/s, 0.02 N/mm), by the bench's encoder."""
    enc = FrameEncoder(DB)
    step = max(1, int(round(1.0 / rate_hz / TICK_S)))
    out = []
    for k in range(0, int(seconds / TICK_S), step):
        t = k * TICK_S
        d = 10.0 * t
        out.append(ScheduledFrame(t, enc.depth(k, d, 10.0)))
        out.append(ScheduledFrame(t, enc.force(k, 0.02 * d)))
    return out


def throughput(exe: str, out: Path, rates: list[float], seconds: float) -> list[dict]:
    rows = []
    for r in rates:
        frames = rate_stream(r, seconds)
        log = out / f"rate_{int(r)}.log"
        write_candump(log, frames, "vcan0", 1.0)
        node = Node(exe, out, f"rate{int(r)}")
        t0 = time.monotonic()
        try:
            _play(log)
            play_s = time.monotonic() - t0
            time.sleep(0.5)
        finally:
            st = node.stop()
        nf = len(frames) // 2
        ev = st.get("events", {})
        ok = (st.get("rx_accepted", {}).get("force") == nf and st.get("steps") == nf
              and st.get("rx_accepted", {}).get("depth") == nf
              and st.get("tx", {}).get("estimate") == nf and ev.get("queue_overflow", 1) == 0
              and ev.get("send_failed", 1) == 0 and ev.get("stale", 1) == 0)
        rows.append({"force_hz": r, "frames_per_s_in": 2 * r, "forces": nf,
                     "steps": st.get("steps"), "estimates_sent": st.get("tx", {}).get("estimate"),
                     "play_s": round(play_s, 2), "lossless": ok})
        print(f"  force {r:7.0f} Hz (+ depth at the same rate): {'no loss' if ok else 'LOSS'}"
              f" steps {st.get('steps')}/{nf}, canplayer {play_s:.2f} s for {seconds:.1f} s",
              flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m host_bench.bench_node", description=__doc__)
    p.add_argument("--node", help="nte-node binary (default build/host or build/node)")
    p.add_argument("--out", help="directory for logs (default a temp dir)")
    p.add_argument("--rates", default="200,500,1000,2000,3333,5000,10000",
                   help="force rates to try, Hz (100 us sensor ticks: at most 10000)")
    p.add_argument("--seconds", type=float, default=3.0)
    a = p.parse_args(argv)
    exe = _node_path(a.node)
    out = Path(a.out) if a.out else Path(tempfile.mkdtemp(prefix="nte-bench-node."))
    out.mkdir(parents=True, exist_ok=True)
    lat = latency(exe, out)
    print(f"latency force frame -> estimate frame on vcan0 ({lat['n']} steps, 1 kHz depth + "
          f"200 Hz force): p50 {lat['p50_ms']:.3f} ms, p99 {lat['p99_ms']:.3f} ms, "
          f"max {lat['max_ms']:.3f} ms", flush=True)
    rows = throughput(exe, out, [float(x) for x in a.rates.split(",")], a.seconds)
    ok = [r["force_hz"] for r in rows if r["lossless"]]
    best = max(ok) if ok else 0.0
    print(f"highest force rate sustained without loss: {best:.0f} Hz "
          f"(of the rates tried: {a.rates})")
    (out / "bench.json").write_text(json.dumps({"latency": lat, "rates": rows,
                                                "max_lossless_force_hz": best}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
