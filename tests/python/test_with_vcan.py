"""host_bench/with-vcan: a real SocketCAN vcan0 natively, in user-mode Linux or in QEMU.

In the session's one kernel (vcan_session.py): candump captures cansend's frames, python-can's
socketcan interface round-trips a message, a 200 Hz request/answer stream is answered in full; a
failing command's status and output come back; a command that overruns its timeout is killed by
process group inside the kernel, which serves the next command.  One-shot runs: QEMU with
Debian's kernel boots and runs python-can inside (forced, so this path runs on every machine);
each vehicle that cannot start gives its one-line reason and the next one is tried; none
starting gives 125 with every reason.  The loop a served kernel runs starts no process while
idle (under TCG each one costs a host core milliseconds).  Stand-in kernels, emulators and `ip` (shell scripts written by the tests) make a vehicle fail
on purpose.
Needs (Debian): iproute2 can-utils and user-mode-linux kmod or qemu-system-x86 linux-image-amd64
busybox-static cpio (make test installs them).
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
WITH_VCAN = ROOT / "host_bench" / "with-vcan"
PY = str(ROOT / ".venv/bin/python") if (ROOT / ".venv/bin/python").exists() else "python3"


def run(args: list[str], tmp_path: Path, env: dict | None = None, timeout: float = 300,
        **extra: str) -> tuple[subprocess.CompletedProcess, float]:
    e = dict(env if env is not None else os.environ, TMPDIR=str(tmp_path), **extra)
    t = time.monotonic()
    r = subprocess.run([str(WITH_VCAN), *args], capture_output=True, text=True, env=e,
                       timeout=timeout, cwd=ROOT)
    return r, time.monotonic() - t


def _check_probe(out: Path, n: int) -> dict:
    res = json.loads(out.read_text())
    # candump -L: "(1700000000.123456) vcan0 123#DEADBEEF"
    frames = [line.split()[-1] for line in res["candump"]]
    assert frames == ["123#DEADBEEF", "5A1#0102", "7FF#0011223344556677"], res["candump"]
    assert all(re.match(r"^\(\d+\.\d{6}\) vcan0 ", line) for line in res["candump"])
    assert res["pycan"] == {"id": 0x321, "data": "010203fa", "dlc": 4, "ext": False}
    # every request answered; the round-trip times are figures, not gates (under QEMU's TCG
    # code runs several times slower than natively)
    assert res["answered"] == res["n"] == n, \
        f"{res['answered']} of {n} requests answered; first lost: request {res.get('first_lost')}"
    return res


def test_candump_pycan_and_200hz_round_trip(tmp_path: Path, vcan_env: dict) -> None:
    out = tmp_path / "probe.json"
    r, _ = run([PY, "tests/python/vcan_probe.py", str(out), "400"], tmp_path, vcan_env)
    assert r.returncode == 0, r.stdout + r.stderr
    res = _check_probe(out, 400)
    import vcan_session
    print(f"\nwith-vcan session kernel: {vcan_session.vehicle()}; 200 Hz round trip median "
          f"{res['rtt_median_ms']:.3f} ms, p99 {res['rtt_p99_ms']:.3f} ms, "
          f"max {res['rtt_max_ms']:.3f} ms over {res['n']}")


def test_failing_command_status_and_output(tmp_path: Path, vcan_env: dict) -> None:
    r, _ = run(["sh", "-c", 'echo "out $PWD"; echo "err $HOME" >&2; '
                "ip link show vcan0 | grep -q UP || exit 99; "
                'case ":$PATH:" in *":/usr/sbin:"*) ;; *) exit 98 ;; esac; exit 7'],
               tmp_path, vcan_env)
    assert r.returncode == 7, r.stdout + r.stderr
    assert r.stdout == f"out {ROOT}\n"
    assert f"err {os.environ.get('HOME', '/root')}" in r.stderr


def test_timeout_kills_the_command_not_the_kernel(tmp_path: Path, vcan_env: dict) -> None:
    # a command with a child of its own (durations no other command uses): the whole process
    # group must go
    r, _ = run(["sh", "-c", "sleep 3011 & sleep 3012"], tmp_path, vcan_env,
               WITH_VCAN_TIMEOUT="5")
    assert r.returncode == 124, r.stdout + r.stderr
    assert "the kernel stays up" in r.stderr
    # the same kernel serves the next command; nothing of the first one is left in it
    r, _ = run(["sh", "-c", "ps -eo args | grep -c '^sleep 301[12]$'; "
                "ip -br link show vcan0"], tmp_path, vcan_env)
    assert r.stdout.splitlines()[0] == "0", r.stdout + r.stderr
    assert "vcan0" in r.stdout


def _stand_in(tmp_path: Path, name: str, body: str) -> Path:
    p = tmp_path / name
    p.write_text("#!/bin/sh\n" + body + "\n")
    p.chmod(0o755)
    return p


def _panicking_uml(tmp_path: Path) -> Path:
    # what a user-mode kernel prints on an AVX-512/AMX host, then it hangs
    return _stand_in(tmp_path, "linux.uml",
                     'echo "userspace - ptrace set fp regs failed, errno = 14"\n'
                     'echo "Kernel panic - not syncing: Attempted to kill init! exitcode=0x0000000b"\n'
                     "exec sleep 120")


def test_qemu_runs_python_can_after_a_uml_panic(tmp_path: Path) -> None:
    """The QEMU vehicle, forced on every machine: a panicking user-mode kernel is left at once
    and Debian's kernel under QEMU runs python-can on a real vcan0."""
    out = tmp_path / "probe.json"
    timing = tmp_path / "timing.txt"
    env = dict(os.environ, WITH_VCAN_MODE="uml,qemu",
               WITH_VCAN_UML_BIN=str(_panicking_uml(tmp_path)), WITH_VCAN_TIMING=str(timing))
    env.pop("WITH_VCAN_CHANNEL", None)
    r, wall = run([PY, "tests/python/vcan_probe.py", str(out), "50"], tmp_path, env,
                  timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "uml: kernel panic: Kernel panic - not syncing" in r.stderr, r.stderr
    assert re.search(r"vehicle qemu \((kvm|tcg), Debian kernel ", r.stderr), r.stderr
    _check_probe(out, 50)
    m = re.match(r"vehicle=(qemu-\w+) boot_s=([\d.]+) cmd_s=([\d.]+) total_s=([\d.]+)",
                 timing.read_text())
    assert m, timing.read_text()
    assert not list(tmp_path.glob("with-vcan.*")), "temp dir not removed"
    print(f"\nwith-vcan one-shot {m.group(1)} after a UML panic: vcan0 up after "
          f"{float(m.group(2)):.1f} s, command {float(m.group(3)):.1f} s")


def test_no_vehicle_gives_125_and_every_reason(tmp_path: Path) -> None:
    (tmp_path / "bin").mkdir()
    # an `ip` that cannot create vcan0, as on a kernel without CAN (and no vcan0 to find)
    fake_ip = _stand_in(tmp_path / "bin", "ip",
                        'echo "RTNETLINK answers: Operation not supported" >&2; exit 2')
    broken_qemu = _stand_in(tmp_path, "qemu-system-x86_64",
                            'echo "qemu-system-x86_64: -virtfs: there is no option group" >&2; exit 1')
    env = dict(os.environ, WITH_VCAN_MODE="auto", PATH=f"{fake_ip.parent}:{os.environ['PATH']}",
               WITH_VCAN_UML_BIN=str(_panicking_uml(tmp_path)),
               WITH_VCAN_QEMU_BIN=str(broken_qemu), WITH_VCAN_QEMU_ACCEL="tcg")
    env.pop("WITH_VCAN_CHANNEL", None)
    r, wall = run(["true"], tmp_path, env, timeout=120)
    assert r.returncode == 125, r.stdout + r.stderr
    lines = r.stderr.splitlines()
    # each vehicle's one-line reason as it is left, in order, then all of them again
    assert re.search(r"^with-vcan: native: .*(cannot create vcan0|not root)", r.stderr, re.M), lines
    assert re.search(r"^with-vcan: uml: kernel panic: Kernel panic", r.stderr, re.M), lines
    assert re.search(r"^with-vcan: qemu \(tcg\): the kernel exited before vcan0 was up", r.stderr,
                     re.M), lines
    i = lines.index("with-vcan: no vehicle could bring up vcan0:")
    assert [ln.split(":")[0].strip() for ln in lines[i + 1:]] == ["native", "uml", "qemu (tcg)"]
    # the panic is read from the console, not waited out (boot limit 120 s)
    assert wall < 60.0
    assert not list(tmp_path.glob("with-vcan.*")), "temp dir not removed"


def test_bad_mode_and_missing_channel(tmp_path: Path) -> None:
    env = dict(os.environ, WITH_VCAN_MODE="docker")
    env.pop("WITH_VCAN_CHANNEL", None)
    r, _ = run(["true"], tmp_path, env)
    assert r.returncode == 2
    assert r.stderr == ("with-vcan: WITH_VCAN_MODE: unknown vehicle 'docker' (auto, native, uml, "
                        "qemu or a comma list)\n")
    r, _ = run(["true"], tmp_path, dict(os.environ, WITH_VCAN_CHANNEL=str(tmp_path / "none")))
    assert r.returncode == 125
    assert "no kernel is served there" in r.stderr


def test_an_idle_served_loop_starts_no_process(tmp_path: Path) -> None:
    # The loop a served kernel runs (here natively: the same script) looks at its queue with
    # bash builtins only.  Under QEMU's TCG every process started costs milliseconds of a host
    # core; a loop of ls/sort/head/sleep kept an idle guest at more than a whole core.  Every
    # program it could call is a stand-in that logs its name first: while idle the log stands
    # still, a queued job is still run, and `stop` ends the loop.
    shims, log, chan = tmp_path / "shims", tmp_path / "calls.log", tmp_path / "chan"
    shims.mkdir()
    for name in ("ls", "sort", "head", "sleep", "cat", "date", "mv", "timeout", "mkdir",
                 "mktemp", "mkfifo", "rm", "dirname", "find", "stat", "inotifywait"):
        real = subprocess.run(["bash", "-c", f"command -v {name}"], capture_output=True,
                              text=True).stdout.strip()
        body = f'echo {name} >>"{log}"\n' + (f'exec {real} "$@"' if real else "exit 127")
        _stand_in(shims, name, body)
    env = dict(os.environ, PATH=f"{shims}:{os.environ['PATH']}", TMPDIR=str(tmp_path))
    chan.mkdir()
    loop = subprocess.Popen([str(WITH_VCAN), "--serve-loop", str(chan)], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True)
    try:
        deadline = time.monotonic() + 30
        while "mkfifo" not in (log.read_text() if log.exists() else ""):
            assert time.monotonic() < deadline and loop.poll() is None, loop.stderr
            time.sleep(0.05)
        time.sleep(0.5)
        calls_before = log.read_text().split()
        time.sleep(2.0)  # 5 or more looks at the queue
        assert log.read_text().split() == calls_before
        job = tmp_path / "job"
        job.mkdir()
        _stand_in(job, "cmd.sh", "echo served; exit 3")
        (job / "limit_s").write_text("30\n")
        (chan / "queue").mkdir(exist_ok=True)
        job.rename(chan / "queue" / "0001")
        status = chan / "run" / "0001" / "status"
        while not status.exists():
            assert time.monotonic() < deadline + 30, "the queued job was not run"
            time.sleep(0.05)
        assert status.read_text() == "3\n"
        assert (chan / "run" / "0001" / "stdout").read_text() == "served\n"
        (chan / "stop").touch()
        assert loop.wait(timeout=10) == 0
    finally:
        if loop.poll() is None:
            os.killpg(loop.pid, 9)
            loop.wait()
