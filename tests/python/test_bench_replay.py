"""The bench replay engine (host_bench.replay) on a real vcan0 (host_bench/with-vcan).

A 1 s scenario (1 kHz depth, 200 Hz force, starting at t = 6.4 s so that the 16-bit sensor
clock wraps in the middle) is replayed at half speed; candump captures the bus. The capture is
decoded with reference_py.bus.dbc and must hold every sample, in order, E2E-valid with continuous
counters, values within half a resolution step, sensor times equal to the scenario's; its
timing is printed. The pacing rule (never early, catch up after a stall, worst lateness
reported) is asserted on a virtual clock, where load cannot move it. The replay's own records (CSV and candump-format
log) must hold what it sent (T) and what the stand-in node sent (R).
Plus offline tests of the scenario reader and the scheduler.
"""
from __future__ import annotations

import math
import os
import statistics
import subprocess
from pathlib import Path

import can
import pytest

from reference_py.bus.dbc import TICK_S, NteDatabase, seconds_to_ticks
from host_bench.replay import read_scenario, schedule
from reference_py.config import EstimatorConfig

ROOT = Path(__file__).resolve().parents[2]
T0 = 6.4
N = 1000
#: the envelope's ends (EstimatorConfig): the range ends a scenario may reach
DEPTH_MAX = EstimatorConfig.depth_max_mm
SPEED_MAX = EstimatorConfig.speed_max_mm_s
FORCE_MAX = EstimatorConfig.force_max_n


def write_scenario(path: Path) -> list[tuple[float, float, float, float | None]]:
    rows = []
    for k in range(N):
        t = T0 + k * 1e-3
        tau = k * 1e-3
        depth = 10.0 * tau + 0.0004 * (k % 3)        # off-grid by < half a um step at times
        vel = 10.0 + 0.004 * (k % 2)
        force = 0.05 + 0.2 * math.sin(6.0 * tau) if k % 5 == 0 else None
        rows.append((t, depth, vel, force))
    rows[0] = (T0, 0.0, 0.0, -FORCE_MAX)             # range ends travel too
    rows[-1] = (rows[-1][0], DEPTH_MAX, -SPEED_MAX, None)
    rows[-5] = (rows[-5][0], DEPTH_MAX - 0.001, SPEED_MAX, FORCE_MAX)
    with open(path, "w") as f:
        f.write("t_s,depth_mm,velocity_mm_s,force_n\n")
        for t, d, v, fo in rows:
            f.write(f"{t:.6f},{d!r},{v!r},{'' if fo is None else repr(fo)}\n")
    return rows


def test_scenario_reader_rejects_bad_input(tmp_path: Path) -> None:
    p = tmp_path / "s.csv"
    p.write_text("t_s,depth_mm,velocity_mm_s,force_n\n0,0,0,\n-1,1,0,0.1\n")
    with pytest.raises(ValueError, match="increase"):
        read_scenario(p)
    p.write_text("t_s,depth_mm,velocity_mm_s\n0,0,0\n")
    with pytest.raises(ValueError, match=r"s.csv:1: column 'force_n': missing from the header"):
        read_scenario(p)
    p.write_text("t_s,depth_mm,velocity_mm_s,force_n\n0,0,0,\n0.001,0,0,inf\n")
    with pytest.raises(ValueError, match=r"s.csv:3: column 'force_n': not finite: 'inf'"):
        read_scenario(p)
    # a force written nan (or NA) is no force sample, like an empty cell; a depth's dropout
    # leaves the row out (no Depth frame)
    p.write_text("t_s,depth_mm,velocity_mm_s,force_n\n0,0,0,NaN\n0.001,0,0,NA\n"
                 "0.002,,0,0.5\n0.003,0,0,0.25\n")
    said: list[str] = []
    rows = read_scenario(p, note=said.append)
    assert [r.force_n for r in rows] == [None, None, 0.25] and rows[2].t_s == 0.003
    assert said == [f"{p}: 1 of 4 rows left out, a value missing in column 'depth_mm' or "
                    f"'velocity_mm_s' (a dropout: line 4)"]
    p.write_text("t_s,depth_mm,velocity_mm_s,force_n\n0,-1e-9,0,\n0.001,600,0,\n")
    rows = read_scenario(p)
    assert rows[0].depth_mm == 0.0 and rows[0].force_n is None   # tiny negative clamped
    with pytest.raises(ValueError, match="row 1"):
        schedule(rows, NteDatabase())                              # 600 mm is out of range


def test_schedule_counts_and_force_every(tmp_path: Path) -> None:
    p = tmp_path / "s.csv"
    write_scenario(p)
    db = NteDatabase(base_id=0x300)
    frames = schedule(read_scenario(p), db, force_every=2)
    ids = [f.message.arbitration_id for f in frames]
    assert ids.count(0x300) == N and ids.count(0x301) == 100
    assert all(a.t_s <= b.t_s for a, b in zip(frames, frames[1:]))


class _VirtualClock:
    """Stands in for the replay's time module: sleep advances the clock, nothing waits."""

    def __init__(self) -> None:
        self.now = 1000.0
        self.sleeps = 0

    def perf_counter(self) -> float:
        return self.now

    def time(self) -> float:
        return self.now

    def sleep(self, s: float) -> None:
        self.sleeps += 1
        self.now += max(s, 1e-5)    # sleep(0) still lets a little time pass, as a real one


class _StampingBus(can.BusABC):
    """A bus that records the virtual time of every send and can stall once."""

    def __init__(self, clock: _VirtualClock, stall_at: int = -1, stall_s: float = 0.0) -> None:
        self.clock, self.stall_at, self.stall_s = clock, stall_at, stall_s
        self.sent: list[float] = []
        super().__init__(channel="virtual-clock")

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.sent.append(self.clock.now)
        if len(self.sent) - 1 == self.stall_at:
            self.clock.now += self.stall_s     # the host stalls right after this send

    def _recv_internal(self, timeout: float | None):  # type: ignore[no-untyped-def]
        return None, False


@pytest.mark.parametrize("speed", [0.5, 1.0, 4.0])
def test_replay_paces_by_schedule(monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
                                  speed: float) -> None:
    """Each frame leaves at start + (t - t0) / speed, never earlier; after a stall the
    replay catches up (no frame delayed past the stall) and reports its worst lateness."""
    import host_bench.replay as rp
    rows = read_scenario(str(write_scenario_path(tmp_path)))
    frames = schedule(rows, NteDatabase())
    clock = _VirtualClock()
    monkeypatch.setattr(rp, "time", clock)
    stall_at, stall_s = 300, 0.25
    bus = _StampingBus(clock, stall_at, stall_s)
    res = rp.replay(bus, frames, speed=speed, tail_s=0.0)
    bus.shutdown()
    start = bus.sent[0]
    assert res.sent == len(frames) == len(bus.sent) == N + 200
    targets = [start + (f.t_s - frames[0].t_s) / speed for f in frames]
    assert all(ts >= tg - 1e-9 for ts, tg in zip(bus.sent, targets))       # never early
    stall_end = bus.sent[stall_at] + stall_s
    for k, (ts, tg) in enumerate(zip(bus.sent, targets)):
        if k <= stall_at:
            assert ts - tg <= 0.0005 + 1e-9, k    # on time, within the sleep's resolution
        else:
            assert ts <= max(tg, stall_end) + 0.0005 + 1e-9, k   # caught up after the stall
    assert res.max_late_s == pytest.approx(stall_end - targets[stall_at + 1], abs=0.0006)


def write_scenario_path(tmp_path: Path) -> Path:
    scen = tmp_path / "scenario.csv"
    write_scenario(scen)
    return scen


def test_replay_on_vcan(tmp_path: Path, vcan_env: dict) -> None:
    scen = tmp_path / "scenario.csv"
    rows = write_scenario(scen)
    py = str(ROOT / ".venv" / "bin" / "python") if (ROOT / ".venv/bin/python").exists() else "python3"
    env = dict(vcan_env, TMPDIR=str(tmp_path), WITH_VCAN_TIMEOUT="600")
    frames = N + sum(1 for row in rows if row[3] is not None) + 5   # depth, force, heartbeats
    r = subprocess.run([str(ROOT / "host_bench" / "with-vcan"), py, "tests/python/replay_probe.py",
                        str(scen), str(tmp_path), "0.5", str(frames)], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=3600)  # may wait for the kernel
    assert r.returncode == 0, r.stdout + r.stderr + (tmp_path / "replay.out").read_text()
    print("\n" + (tmp_path / "replay.out").read_text().strip())

    db = NteDatabase()
    rx = db.receiver()
    cap = list(can.CanutilsLogReader(str(tmp_path / "candump.log")))
    decoded = []
    for m in cap:
        name, sig, status = rx.decode(m.arbitration_id, m.data)
        assert status == "ok", (name, status, m)
        decoded.append((m.timestamp, name, sig))
    depth = [(ts, s) for ts, n, s in decoded if n == "Depth"]
    force = [(ts, s) for ts, n, s in decoded if n == "Force"]
    hb = [s for _, n, s in decoded if n == "Heartbeat"]
    frows = [row for row in rows if row[3] is not None]
    assert len(depth) == N and len(force) == len(frows) == 200 and len(hb) == 5
    assert sum(rx.lost.values()) == 0 and rx.errors == {}
    for (ts, s), (t, d, v, _) in zip(depth, rows):
        assert abs(s["Depth"] - d) <= 0.0005 + 1e-9
        assert abs(s["Velocity"] - v) <= 0.005 + 1e-9
        assert round(s["SensorTime"] / TICK_S) == seconds_to_ticks(t)
    for (ts, s), (t, _, _, fo) in zip(force, frows):
        assert abs(s["Force"] - fo) <= 0.00005 + 1e-9
        assert round(s["SensorTime"] / TICK_S) == seconds_to_ticks(t)
    # the sensor clock wrapped inside the scenario (6.5536 s)
    ticks = [round(s["SensorTime"] / TICK_S) for _, s in depth]
    assert sum(1 for a, b in zip(ticks, ticks[1:]) if b < a) == 1
    # timing at speed 0.5 (depth every 2 ms) on the real bus is a figure, not a gate: inside the
    # user-mode kernel (one CPU, shared with candump and the stand-in node) on a loaded host,
    # stalls of up to 0.6 s were seen and a median bound failed on a correct build.  The pacing
    # rule itself is asserted on a virtual clock (test_replay_paces_by_schedule).
    caps = [ts for ts, _ in depth]
    intervals = sorted(b - a for a, b in zip(caps, caps[1:]))
    med_interval = intervals[len(intervals) // 2]
    late = [(ts - caps[0]) - (t - T0) / 0.5 for ts, (t, *_r) in zip(caps, rows)]
    offset = statistics.median(late)
    dev = sorted(abs(x - offset) for x in late)
    print(f"depth interval median {med_interval * 1e3:.3f} ms (schedule 2 ms), schedule "
          f"deviation median {dev[len(dev) // 2] * 1e3:.3f} ms, p95 "
          f"{dev[int(0.95 * len(dev))] * 1e3:.2f} ms, max {dev[-1] * 1e3:.1f} ms")

    # the replay's own records: its frames as T, the heartbeats as R, in both formats
    log = list(can.CanutilsLogReader(str(tmp_path / "record.log")))
    assert sum(1 for m in log if not m.is_rx) == N + 200
    rx_hb = [m for m in log if m.is_rx and m.arbitration_id == db.frame_id("Heartbeat")]
    assert len(rx_hb) == 5
    csv_lines = (tmp_path / "record.csv").read_text().splitlines()
    assert csv_lines[0].startswith("timestamp,arbitration_id")
    assert len(csv_lines) - 1 == len(log)


# -- nte-bench: every bad input is one line and exit status 2, nothing written ----------------

def _bench(argv, capsys) -> tuple[int, str]:
    from host_bench.cli import main
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as exc:            # argparse's refusals (the console script's status)
        rc = int(exc.code or 0)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return rc, err[0]


def _small(tmp_path: Path) -> Path:
    p = tmp_path / "s.csv"
    p.write_text("t_s,depth_mm,force_n\n" + "".join(f"{k * 0.01!r},{k * 0.1!r},0.01\n"
                                                     for k in range(50)))
    return p


BENCH_CASES = [
    (["--depth-rate", "0"], "nte-bench replay: error: argument --depth-rate: must be > 0 and "
                            "<= 10000 Hz (got 0) (see nte-bench replay --help)"),
    (["--depth-rate", "nan"], "argument --depth-rate: must be > 0 and <= 10000 Hz (got nan)"),
    (["--speed", "-1"], "argument --speed: must be >= 0 and <= 100 (got -1)"),
    (["--tail", "1e9"], "argument --tail: must be >= 0 and <= 60 s (got 1e9)"),
    (["--bitrate", "fast"], "argument --bitrate: not an integer: 'fast'"),
    (["--base-id", "0x7ff"], "argument --base-id: must be within 0x000..0x7F0 (got 0x7ff)"),
    (["--params-per-step", "0"], "argument --params-per-step: must be >= 1 and <= 7 (got 0)"),
    (["--depth-timeout-ms", "0"], "argument --depth-timeout-ms: must be > 0 and <= 60000 ms"),
    (["--preset", "nope"], "argument --preset: invalid choice: 'nope'"),
    (["--player", "canplayer", "--speed", "0"],
     "nte-bench: error: --player canplayer needs --speed > 0"),
    (["--interface", "slcan", "--channel", "/nonexistent/tty"],
     "nte-bench: error: --channel /nonexistent/tty: cannot open the slcan bus: "),
    (["--with-node", "--interface", "slcan"],
     "nte-bench: error: --with-node starts nte-node on a SocketCAN interface; with "
     "--interface slcan the node is the board"),
    (["--with-node", "--depth-timeout-ms", "2.5"],
     "nte-bench: error: --with-node: nte-node takes --depth-timeout-ms in whole milliseconds, "
     "1..3000 (got 2.5)"),
    (["--with-node", "--node", "/nonexistent/nte-node"],
     "nte-bench: error: --node /nonexistent/nte-node: not an executable file"),
    (["--with-node", "--channel", "nte_absent0"],
     "nte-bench: error: --with-node: nte-node exited with status "),
]


@pytest.mark.parametrize("flags,message", BENCH_CASES, ids=[c[0][0] + " " + c[0][1]
                                                             for c in BENCH_CASES])
def test_bench_replay_bad_flags(tmp_path, capsys, flags, message):
    out = tmp_path / "out"
    rc, line = _bench(["replay", _small(tmp_path), "--out", out, *flags], capsys)
    assert rc == 2 and message in line, line
    assert not out.exists()


def test_bench_bad_files(tmp_path, capsys):
    out = tmp_path / "out"
    rc, line = _bench(["replay", tmp_path / "absent.log", "--out", out], capsys)
    assert rc == 2 and line == f"nte-bench: error: {tmp_path}/absent.log: cannot read: " \
                               f"No such file or directory"
    bad = tmp_path / "bad.csv"
    bad.write_text("t_s,depth_mm,force_n\n0,0,0\n-0.5,0,0\n")
    rc, line = _bench(["replay", bad, "--out", out], capsys)
    assert rc == 2 and line.endswith("bad.csv:3: column 't_s': time -0.5 does not increase "
                                     "(previous 0.0)")
    rc, line = _bench(["replay", _small(tmp_path), "--out", tmp_path / "no" / "dir"], capsys)
    assert rc == 2 and line == (f"nte-bench: error: --out {tmp_path}/no/dir: directory "
                                f"{tmp_path}/no does not exist (it is not created)")
    rc, line = _bench(["send", _small(tmp_path), "--record-log", "/dev/null"], capsys)
    assert rc == 2 and line == ("nte-bench: error: --record-log /dev/null: is a character "
                                "device, not a regular file; refusing to replace it")
    assert not out.exists()


@pytest.mark.parametrize("errno,message", [
    (97, "--interface socketcan: this host's kernel has no SocketCAN (AF_CAN); run it under "
         "host_bench/with-vcan, which provides vcan0: host_bench/with-vcan nte-bench replay"),
    (19, "--channel vcan9: no such CAN interface (create vcan0 with 'ip link add dev vcan0 "
         "type vcan', or run under host_bench/with-vcan)")])
def test_bench_without_can_points_to_with_vcan(tmp_path, capsys, monkeypatch, errno, message):
    """The kernel's refusals (errno 97 EAFNOSUPPORT: no AF_CAN; 19 ENODEV: no such interface)
    become one line with the hint; the output directory is not left behind."""
    import host_bench.cli as bench

    def refuse(**kwargs):
        raise OSError(errno, os.strerror(errno))

    monkeypatch.setattr(bench.can, "Bus", refuse)
    out = tmp_path / "out"
    rc, line = _bench(["replay", _small(tmp_path), "--channel", "vcan9", "--out", out], capsys)
    assert rc == 2 and line.startswith("nte-bench: error: " + message), line
    assert not out.exists()


def test_bench_on_this_host_without_af_can(tmp_path):
    """The console script itself, where the kernel really has no AF_CAN (the build machines)."""
    import socket
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
        pytest.skip("this kernel has SocketCAN")
    except OSError:
        pass
    exe = ROOT / ".venv" / "bin" / "nte-bench"
    r = subprocess.run([str(exe), "replay", str(_small(tmp_path)), "--out",
                        str(tmp_path / "out")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip() == ("nte-bench: error: --interface socketcan: this host's kernel "
                                "has no SocketCAN (AF_CAN); run it under host_bench/with-vcan, "
                                "which provides vcan0: host_bench/with-vcan nte-bench replay ...")


def test_out_of_range_values_are_clipped_and_counted(tmp_path):
    from host_bench.replay import scenario_frames
    p = tmp_path / "s.csv"
    p.write_text("t_s,depth_mm,velocity_mm_s,force_n\n0,0,0,0\n0.001,10,700,60\n"
                 "0.002,20,0,-75\n0.003,30,0,1\n")
    clipped: dict[str, int] = {}
    db = NteDatabase()
    frames = scenario_frames(str(p), db, 1000.0, clipped)
    assert clipped == {"Velocity": 1, "Force": 2}
    rx = db.receiver()
    forces = [rx.decode(m.arbitration_id, m.data)[1]["Force"] for _, m in frames
              if m.arbitration_id == db.frame_id("Force")]
    assert forces == pytest.approx([0.0, FORCE_MAX, -FORCE_MAX, 1.0], abs=1e-4)


def test_bench_says_the_rows_it_leaves_out(tmp_path, capsys):
    """nte-bench tells, in the estimating tools' words and before it opens a bus, which rows
    of the scenario it does not send: a depth's dropout, a repeated time."""
    from host_bench.cli import main
    p = tmp_path / "s.csv"
    p.write_text("t_s,depth_mm,force_n\n0,0,0\n0.01,,0.1\n0.02,0.2,0.2\n0.02,0.2,0.2\n"
                 "0.03,0.3,\n")
    for cmd in ("send", "replay"):
        extra = ["--out", str(tmp_path / "out")] if cmd == "replay" else []
        rc = main([cmd, str(p), "--interface", "socketcan", "--channel", "nte-no-such0"] + extra)
        err = capsys.readouterr().err.splitlines()
        assert rc == 2 and err[:2] == [
            f"{p}: 1 of 5 rows left out, a value missing in column 'depth_mm' (a dropout: "
            f"line 3)",
            f"{p}: 1 of 5 rows left out, the time equal to the previous sample's (a repeat: "
            f"line 5)"], (cmd, err)
        assert len(err) == 3 and err[2].startswith("nte-bench: error: "), err


def test_help_lists_every_flag_with_its_default(capsys):
    from host_bench.cli import build_parser
    for cmd in ("replay", "send"):
        with pytest.raises(SystemExit) as e:
            build_parser().parse_args([cmd, "--help"])
        assert e.value.code == 0
        text = capsys.readouterr().out
        sub = build_parser()._subparsers._group_actions[0].choices[cmd]   # type: ignore[union-attr]
        for act in sub._actions:
            for flag in act.option_strings:
                assert flag in text, (cmd, flag)
            if act.option_strings and act.default is not None and act.default is not False \
                    and act.default != "==SUPPRESS==":
                assert f"(default: {act.default})" in " ".join(text.split()), (cmd, act.dest)


def test_bench_refuses_implausible_units_naming_the_option(tmp_path, capsys):
    p = tmp_path / "mn.csv"
    p.write_text("t_s,depth_mm,force_n\n" + "".join(f"{k * 0.01!r},{k * 0.1!r},400\n"
                                                    for k in range(50)))
    out = tmp_path / "out"
    rc, line = _bench(["replay", p, "--out", out], capsys)
    assert rc == 2 and line == (f"nte-bench: error: {p}: column 'force_n': 100 % of the forces "
                                f"exceed the configured range ±50 N (up to 400): probably "
                                f"millinewtons, or grams-force (a load cell read in grams): "
                                f"convert with --force-unit mN or --force-unit gf")
    assert not out.exists()
    from host_bench.replay import scenario_frames
    from reference_py.tools.csvio import Units
    frames = scenario_frames(str(p), NteDatabase(), 100.0, {}, Units(force="mN"))
    rx = NteDatabase().receiver()
    forces = {round(rx.decode(m.arbitration_id, m.data)[1]["Force"], 4) for _, m in frames
              if m.arbitration_id == NteDatabase().frame_id("Force")}
    assert forces == {0.4}


def test_candump_input_log_written_by_python_can(tmp_path):
    """The canplayer input (write_candump) is python-can's candump -l format: every frame read
    back by can.LogReader with its id and data, at start + t / speed, marked sent (T)."""
    from host_bench.replay import scenario_frames
    from reference_py.bus.candump import write_candump
    p = tmp_path / "s.csv"
    write_scenario(p)
    frames = scenario_frames(str(p), NteDatabase(), 1000.0)
    log = tmp_path / "in.log"
    write_candump(log, frames, "vcan0", 0.5)
    lines = log.read_text().splitlines()
    assert len(lines) == len(frames) == 1200
    assert lines[0] == f"(1000012.800000) vcan0 200#{bytes(frames[0][1].data).hex().upper()} T"
    back = list(can.LogReader(str(log)))
    for (t, m), b in zip(frames, back):
        assert (b.arbitration_id, bytes(b.data), b.channel) == (m.arbitration_id, bytes(m.data),
                                                                "vcan0")
        assert abs(b.timestamp - (1_000_000.0 + t / 0.5)) < 1e-6 and not b.is_rx


def test_check_refuses_a_directory_without_a_record(tmp_path, capsys):
    """nte-bench check (the host half of replay --no-check): a directory that holds no replay
    record is refused in one line naming the missing file, and nothing is written there."""
    d = tmp_path / "rec"
    d.mkdir()
    rc, line = _bench(["check", d], capsys)
    assert rc == 2 and line == (f"nte-bench: error: {d / 'input.log'}: missing (record it with "
                                f"nte-bench replay --no-check --out {d})"), line
    (d / "input.log").write_text("(1000000.000000) vcan0 201#0000000000000000 T\n")
    (d / "node.log").write_text("")
    (d / "record.json").write_text('{"frames_sent": 1}')
    rc, line = _bench(["check", d], capsys)
    assert rc == 2 and line.startswith(f"nte-bench: error: {d / 'record.json'}: not a replay "
                                       f"record"), line
    assert sorted(p.name for p in d.iterdir()) == ["input.log", "node.log", "record.json"]


def test_check_model3_against_the_node(tmp_path, capsys):
    """nte-bench check --model 3 (the host half of a Model III replay): the phantom's first 6 s
    through nte-node --replay --model 3 (stage position in the Depth frames, the raw force):
    Estimate, Params (0..9) and Contact frames all equal the reference -> exit 0 with 0
    mismatches; the same record checked as Model II disagrees -> exit 1."""
    import json
    from host_bench.replay import scenario_frames
    from reference_py.bus.candump import write_candump
    node = next((p for p in (ROOT / "build/host/bin/nte-node", ROOT / "build/node/bin/nte-node")
                 if p.exists()), None)
    if node is None:
        pytest.skip("nte-node not built")
    csv = tmp_path / "lab101.csv"
    subprocess.run([str(ROOT / ".venv/bin/nte-ref"), "phantom", "lab", "--seed", "101", "--out",
                    str(csv)], check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    db = NteDatabase()
    frames = [(t, m) for t, m in scenario_frames(str(csv), db, 1000.0) if t <= 6.0]
    d = tmp_path / "rec"
    d.mkdir()
    write_candump(d / "input.log", frames, "vcan0", 1.0)
    subprocess.run([str(node), "--replay", str(d / "input.log"), "--record", str(d / "node.log"),
                    "--model", "3"], check=True, timeout=120)
    (d / "record.json").write_text(json.dumps({"frames_sent": len(frames), "wall_s": 0.0,
                                               "input_values_clipped": {}}))
    from host_bench.cli import main
    assert main(["check", str(d), "--model", "3", "--no-plot"]) == 0
    s = json.loads((d / "summary.json").read_text())
    assert s["estimates_node"] == s["estimates_reference"] > 400
    assert s["estimate_mismatches"] == s["param_value_mismatches"] == 0
    assert s["contact_node"] == s["contact_reference"] > 0 and s["contact_mismatches"] == 0
    assert set(s["final_parameters"]) == {"sigma0", "sigma1", "sigma2", "f1", "f2", "alpha",
                                          "beta", "g_fast", "g_slow", "delta"}
    assert main(["check", str(d), "--model", "2", "--no-plot"]) == 1
    capsys.readouterr()


def test_replay_with_node_on_vcan(tmp_path: Path, vcan_env: dict) -> None:
    """nte-bench replay --with-node: one command starts nte-node on vcan0 (the reference's
    settings), replays a paper insertion, checks every Estimate and Params frame against the
    reference and stops the node (by its process group: exit status 0 after SIGTERM)."""
    import json
    scen = tmp_path / "paper.csv"
    subprocess.run([str(ROOT / ".venv/bin/nte-ref"), "simulate", "--preset", "paper-10mms",
                    "--depth", "8", "--dwell", "0.2", "--seed", "3", "--out", str(scen)],
                   check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    out = tmp_path / "run"
    env = dict(vcan_env, TMPDIR=str(tmp_path), WITH_VCAN_TIMEOUT="600")
    r = subprocess.run([str(ROOT / "host_bench" / "with-vcan"), str(ROOT / ".venv/bin/nte-bench"),
                        "replay", str(scen), "--channel", "vcan0", "--with-node", "--out",
                        str(out), "--no-plot", "--no-progress"], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=3600)
    assert r.returncode == 0, r.stdout + r.stderr
    summary = json.loads((out / "summary.json").read_text())
    record = json.loads((out / "record.json").read_text())
    print("\n" + r.stdout.strip().splitlines()[-1])
    assert record["node_exit_status"] == 0
    assert summary["estimate_mismatches"] == 0 and summary["param_value_mismatches"] == 0
    assert summary["estimates_node"] == summary["estimates_reference"] > 100
