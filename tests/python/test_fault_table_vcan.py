"""The fault table over a real vcan0: ``python -m host_bench.faults --bus vcan``, run as a user
runs it, in the session's one kernel (vcan_session.py: WITH_VCAN_CHANNEL), every row of the
table (tests/python/test_node_port.py FAULT_ROWS) fed to a fresh nte-node live on the bus.

- Every row within bounds -- recovery within 2 s of the fault's end, error after it at most
  110 % of the fault-free run's, that run also over vcan (test_node_port.FAULT_XFAIL lists a
  row that does not yet: none).
- The bus: every run's node received exactly the frames played on its input ids, in order,
  and sent exactly the Estimate and Params frames nte-node --replay sends for them, counting
  what it counts; so the table over vcan is the replay table, figure for figure (only the
  flood's foreign ids differ: the node's kernel filters drop them on the bus).
- The flood: 20 000 foreign frames in 5 s (4 000/s, the capacity of a 500 kbit/s bus), played
  in real time (the rest of its stream at SPEED); the node's estimates are the fault-free run's.
- The restart: the first node SIGKILLed after it had read every frame up to 2.5 s, a fresh one
  started, fed from 3.0 s on.
- Processes: every node the bus half started is gone afterwards (its process group ids, looked
  up in the kernel), also when a run fails (a missing log: the node running is stopped).

The streams are played at SPEED times real time: the node's results depend on the frames'
SensorTime only (nte_node.h TIME) and nothing is judged by arrival time, so the speed can only
lose frames -- which the frame-for-frame check would catch -- never change a figure.  At 4x the
22.7 s streams take 5.7 s each; the flood's 5 s are played in real time (its rate is its point).
The node read ~9 000 frames/s under QEMU's TCG on this loaded host (a 16x play), so 4x (about
4 800 frames/s, 5 200 during the flood) leaves it twice that, and its 8 MB receive queue.
Measured on this 2-core host (load 4 from other work): this module 177 s under user-mode Linux
(the bus half 132 s, canplayer 116 s of it), 279 s under QEMU TCG (bus half 218 s).
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import can
import pytest

from test_node_port import (FAULT_ROWS, FLOOD, RESTART, assert_within_bounds, fault_params,
                            node_binary)

ROOT = Path(__file__).resolve().parents[2]
WITH_VCAN = ROOT / "host_bench" / "with-vcan"
SPEED = 4.0
#: SIGKILL's exit status as a shell reports it
KILLED = 128 + 9


def _paper2(work: Path) -> Path:
    csv = work / "paper2.csv"
    subprocess.run([sys.executable, "-m", "reference_py", "simulate", "--preset", "paper-10mms",
                    "--depth", "50", "--dwell", "1", "--seed", "1", "--cycles", "2",
                    "--out", str(csv)], check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    return csv


@pytest.fixture(scope="module")
def tables(tmp_path_factory: pytest.TempPathFactory, vcan_env: dict) -> dict:
    """The table over vcan (the command's JSON, stdout, status) and, on the host, the same
    table through nte-node --replay."""
    from host_bench.faults import table
    work = tmp_path_factory.mktemp("faults_vcan")
    csv = _paper2(work)
    out = work / "table.json"
    keep = work / "keep"
    r = subprocess.run([sys.executable, "-m", "host_bench.faults", "--bus", "vcan",
                        "--speed", str(SPEED), "--node", str(node_binary()), "--csv", str(csv),
                        "--json", str(out), "--keep", str(keep)],
                       cwd=ROOT, env=dict(vcan_env, WITH_VCAN_TIMEOUT="2400"),
                       capture_output=True, text=True, timeout=3600)
    (work / "replay").mkdir()
    replayed = table(str(node_binary()), str(csv), work / "replay")
    return {"status": r.returncode, "stdout": r.stdout, "stderr": r.stderr, "keep": keep,
            "bus": json.loads(out.read_text()) if out.exists() else None,
            "replay": {row["fault"]: row for row in replayed}}


def _bus(tables: dict) -> dict:
    assert tables["status"] == 0 and tables["bus"] is not None, tables["stdout"] + tables["stderr"]
    return tables["bus"]


def _rows(tables: dict) -> dict:
    return {r["fault"]: r for r in _bus(tables)["rows"]}


def test_the_command_over_vcan(tables: dict) -> None:
    import vcan_session
    bus = _bus(tables)
    assert [r["fault"] for r in bus["rows"]] == FAULT_ROWS
    assert "every run received exactly the frames played on its ids" in tables["stdout"]
    print(f"\nfault table over vcan0 ({vcan_session.vehicle()}): {1 + len(bus['rows'])} rows, "
          f"bus half and checks {bus['wall_s']:.0f} s at {SPEED:g}x\n" + tables["stdout"])


@pytest.mark.parametrize("fault", fault_params())
def test_row_within_bounds_over_vcan(tables: dict, fault: str) -> None:
    assert_within_bounds(_rows(tables)[fault])


def test_every_run_checked_on_the_bus(tables: dict) -> None:
    """Every node received exactly what was played on its ids and sent what its replay sends;
    a node stopped by SIGTERM exits 0, the restart's first one was SIGKILLed (its logs die with
    it: its counters, read just before, equal its replay's)."""
    bus = _bus(tables)
    runs = [bus["clean"]] + [b for r in bus["rows"] for b in r["bus"]]
    assert len(runs) == 1 + len(FAULT_ROWS) + 1           # the restart is two runs
    for b in runs:
        assert b["counters_equal"], b
        if b["exit_status"] == KILLED:
            assert b["received"] is None and b["tag"].endswith("s0"), b
            continue
        assert b["exit_status"] == 0, b
        assert b["received"] == b["played_inputs"] > 0 and b["received_equal"], b
        assert b["sent_equal"], b
        assert b["stats"]["tx"]["estimate"] == b["replay_stats"]["tx"]["estimate"] > 0, b


@pytest.mark.parametrize("which", ["clean", FLOOD])
def test_received_log_is_what_was_played(tables: dict, which: str) -> None:
    """The digest the check above compares ("COUNT MD5" of the node's received log, computed in
    the kernel) against the node's whole received log, kept: frame for frame the frames played
    on its ids (the fault-free run, and the flood's, whose other ids it never saw)."""
    bus = _bus(tables)
    (b,) = [bus["clean"]] if which == "clean" else _rows(tables)[which]["bus"]
    d = tables["keep"] / "bus"
    played = [(m.arbitration_id, bytes(m.data)) for m in can.CanutilsLogReader(
        str(d / f"{b['tag']}.in.log")) if 0x200 <= m.arbitration_id <= 0x203]
    got = [(m.arbitration_id, bytes(m.data)) for m in can.CanutilsLogReader(
        str(d / f"{b['tag']}.recv.log"))]
    assert got == played and len(got) == b["received"] == b["played_inputs"]


def test_same_table_as_the_replay(tables: dict) -> None:
    """Figure for figure the replay's table (the node's frames equal, timed alike), counters
    too -- but the flood's foreign ids, which the kernel filters drop on the bus and a replay
    counts as unknown ids."""
    rows, rep = _rows(tables), tables["replay"]
    for name in FAULT_ROWS:
        a, b = rows[name], rep[name]
        for k in ("recovery_s", "rms_mN", "clean_rms_mN", "error_pct", "same_as_fault_free"):
            assert a[k] == b[k], (name, k, a[k], b[k])
        want = {k: v for k, v in b["counters"].items() if not (name == FLOOD and k == "unknown_id")}
        assert a["counters"] == want, (name, a["counters"], b["counters"])


def test_flood_at_bus_capacity(tables: dict) -> None:
    """20 000 foreign frames in 5 s on top of the stream, played in real time: the node's
    estimates are the fault-free run's; the half on its Depth and Force ids reached it and were
    refused, the rest never reached it."""
    bus = _bus(tables)
    row = _rows(tables)[FLOOD]
    (b,) = row["bus"]
    clean = bus["clean"]
    assert row["same_as_fault_free"] and row["error_pct"] == 100.0, row
    assert b["played"] - clean["played"] == 5 * 4000
    on_ids = b["played_inputs"] - clean["played_inputs"]
    assert 9000 < on_ids < 11000, b
    assert b["stats"]["rx_accepted"] == clean["stats"]["rx_accepted"], b
    refused = sum(v for k, v in b["stats"]["events"].items()
                  if k in ("wrong_dlc", "bad_crc", "counter_invalid", "counter_repeated",
                           "out_of_range", "time_jump_dropped", "time_backwards"))
    assert refused == on_ids, (refused, on_ids)          # each refused once, by one cause
    assert b["stats"]["events"]["unknown_id"] == 0          # its kernel filters at work
    # the flood at its real rate: its frames span 5 s of the played log (the rest at SPEED),
    # and canplayer never sends early
    log = list(can.CanutilsLogReader(str(tables["keep"] / "bus" / f"{b['tag']}.in.log")))
    foreign = [m.timestamp for m in log if not 0x200 <= m.arbitration_id < 0x220]
    assert len(foreign) == 10011 and abs(foreign[-1] - foreign[0] - 5.0) < 1e-3, foreign[-1]
    assert b["bus_s"][2] >= 5.0 + (log[-1].timestamp - log[0].timestamp - 5.0), b["bus_s"]


def test_restart_over_vcan(tables: dict) -> None:
    """The node SIGKILLed once it had read every frame before 2.5 s (its counters equal its
    replay's on them), a fresh one started and fed from 3.0 s: it publishes fresh estimates at
    once, equal to a fresh replay's on the same frames."""
    row = _rows(tables)[RESTART]
    first, second = row["bus"]
    assert first["exit_status"] == KILLED and first["counters_equal"], first
    assert first["stats"]["steps"] == first["replay_stats"]["steps"] == 500, first
    assert second["exit_status"] == 0 and second["received_equal"] and second["sent_equal"]
    assert row["recovery_s"] == 0.0, row


def _in_kernel(script: str, vcan_env: dict, tmp_path: Path) -> subprocess.CompletedProcess:
    return subprocess.run([str(WITH_VCAN), "bash", "-c", script], cwd=ROOT,
                          env=dict(vcan_env, TMPDIR=str(tmp_path), WITH_VCAN_TIMEOUT="600"),
                          capture_output=True, text=True, timeout=3600)


def test_no_node_left_behind(tables: dict, vcan_env: dict, tmp_path: Path) -> None:
    """Every process group the bus half started is gone (looked up in the kernel it ran in)."""
    pids = (tables["keep"] / "bus" / "pids").read_text().split()
    assert len(pids) == 1 + len(FAULT_ROWS) + 1
    r = _in_kernel(f"for g in {' '.join(pids)}; do kill -0 -- -$g 2>/dev/null && echo $g; "
                   "done; exit 0", vcan_env, tmp_path)
    assert r.returncode == 0 and r.stdout == "", r.stdout + r.stderr


def test_a_failed_run_stops_its_node(vcan_env: dict, tmp_path: Path) -> None:
    """A run whose log is missing fails after its node started: the script says which run and
    why, stops that node by its process group and starts no further run."""
    from host_bench.fault_bus import drain_marker
    from host_bench.replay import scenario_frames
    from reference_py.bus.candump import write_candump
    from reference_py.bus.dbc import NteDatabase
    db = NteDatabase()
    frames = scenario_frames(str(_paper2(tmp_path)), db, 1000.0)[:300]
    write_candump(tmp_path / "ok.in.log", frames + [(frames[-1][0], drain_marker(db))],
                  "vcan0", 1.0)
    (tmp_path / "plan").write_text("ok stop\nlost stop\nnever stop\n")
    node = node_binary()
    r = _in_kernel(f"bash host_bench/fault_bus.sh {node} {tmp_path}; echo status $?; "
                   f"for g in $(cat {tmp_path}/pids); do kill -0 -- -$g 2>/dev/null && "
                   "echo left $g; done; exit 0", vcan_env, tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.splitlines() == ["status 1"], r.stdout + r.stderr
    assert (tmp_path / "ok.done").exists() and (tmp_path / "ok.exit").read_text() == "0\n"
    why = (tmp_path / "lost.failed").read_text()
    assert why.startswith("run lost failed:") and "canplayer failed on lost.in.log" in why, why
    assert len((tmp_path / "pids").read_text().split()) == 2       # "never" never started
    assert not (tmp_path / "never.done").exists() and not (tmp_path / "never.failed").exists()


# ------------------------------------------------------------------------------------------
# The command's refusals (no bus needed).
@pytest.mark.parametrize("args, text", [
    (["--bus", "can0"], "argument --bus: invalid choice: 'can0'"),
    (["--speed", "0"], "argument --speed: must be > 0 and <= 16 (got 0)"),
    (["--row", "loss 2%"], "--row: no row 'loss 2%' (rows: 'loss 1%', "),
    (["--node", "/nonexistent/nte-node"], "--node: no such file /nonexistent/nte-node"),
    (["--csv", "/nonexistent/s.csv"], "/nonexistent/s.csv: cannot read"),
    (["--keep", "/nonexistent/dir"], "--keep: cannot create /nonexistent/dir"),
])
def test_bad_arguments_one_line(args: list[str], text: str) -> None:
    r = subprocess.run([sys.executable, "-m", "host_bench.faults", *args], cwd=ROOT,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and text in r.stderr, r.stderr
    assert r.stdout == ""


def test_no_vehicle_one_line(tmp_path: Path) -> None:
    """No kernel can bring vcan0 up (a stand-in user-mode kernel that exits at once): one line
    naming why, exit status 1, no table."""
    import os
    fake = tmp_path / "linux.uml"
    fake.write_text("#!/bin/sh\nexit 1\n")
    fake.chmod(0o755)
    env = {k: v for k, v in os.environ.items() if k != "WITH_VCAN_CHANNEL"}
    env.update(WITH_VCAN_MODE="uml", WITH_VCAN_UML_BIN=str(fake), TMPDIR=str(tmp_path))
    r = subprocess.run([sys.executable, "-m", "host_bench.faults", "--bus", "vcan", "--row",
                        "loss 1%", "--node", str(node_binary())], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 1, r.stdout + r.stderr
    assert r.stderr.count("\n") == 1, r.stderr
    assert "no vcan0: host_bench/with-vcan could not start a vehicle (uml: the kernel exited" \
        in r.stderr, r.stderr
    assert r.stdout == ""
