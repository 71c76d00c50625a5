"""One kernel with vcan0 for the whole test session: every bus test and every xdist worker.

The first test that needs the bus starts ``host_bench/with-vcan --serve DIR`` (whichever vehicle
with-vcan chooses, or the one WITH_VCAN_MODE forces) in its own process group; every bus test
then runs its commands inside that kernel by calling with-vcan with WITH_VCAN_CHANNEL=DIR (see
``env()``).  Commands run one at a time (they share vcan0); one that overruns its timeout is
killed by process group inside the kernel, which stays up.  The pytest process that owns the
session (the xdist controller, or pytest itself without xdist) stops the kernel at the end:
first by asking (DIR/stop), then by its process group id -- never by name.  If that process
dies, with-vcan notices (WITH_VCAN_SERVE_PARENT) and stops its kernel by itself.

The state shared between workers lives in a directory named by NTE_VCAN_SESSION_DIR, which the
owner creates before any worker starts (tests/conftest.py, loaded by the controller before xdist
starts its workers); a file lock makes exactly one worker start the kernel.
"""
from __future__ import annotations

import atexit
import fcntl
import os
import shutil
import signal
import subprocess
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
WITH_VCAN = ROOT / "host_bench" / "with-vcan"
SESSION_ENV = "NTE_VCAN_SESSION_DIR"
OWNER_ENV = "NTE_VCAN_SESSION_OWNER"
BOOT_TIMEOUT_S = 240.0

_started: subprocess.Popen | None = None   # the serve process, in the process that started it


class BusUnavailable(RuntimeError):
    """No vehicle could bring vcan0 up (the reasons are in the message)."""


def configure() -> None:
    """In the owning process, before workers start: create the shared session directory."""
    if SESSION_ENV not in os.environ:
        os.environ[SESSION_ENV] = tempfile.mkdtemp(prefix="nte-vcan-session.")
        os.environ[OWNER_ENV] = str(os.getpid())


def _session_dir() -> Path:
    if SESSION_ENV not in os.environ:
        # no owner prepared one (tests/conftest.py not loaded): this process owns the session
        # and stops its kernel when it exits
        configure()
        atexit.register(shutdown)
    return Path(os.environ[SESSION_ENV])


def channel() -> Path:
    """The channel directory of the session's kernel, started on first use."""
    global _started
    d = _session_dir()
    chan = d / "channel"
    with open(d / "lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        failed = d / "failed"
        if failed.exists():
            raise BusUnavailable(failed.read_text())
        if (chan / "ready").exists():
            return chan
        env = dict(os.environ, WITH_VCAN_SERVE_PARENT=os.environ[OWNER_ENV])
        env.pop("WITH_VCAN_CHANNEL", None)
        log = open(d / "serve.log", "w")
        proc = subprocess.Popen([str(WITH_VCAN), "--serve", str(chan)], cwd=ROOT, env=env,
                                stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True)
        _started = proc
        (d / "serve.pgid").write_text(str(proc.pid))
        t0 = time.monotonic()
        while not (chan / "ready").exists():
            if proc.poll() is not None or time.monotonic() - t0 > BOOT_TIMEOUT_S:
                _stop_group(proc.pid, proc)
                why = (d / "serve.log").read_text().strip() or "no output"
                failed.write_text(f"with-vcan --serve could not start a kernel: {why}")
                raise BusUnavailable(failed.read_text())
            time.sleep(0.05)
        (d / "boot_s").write_text(f"{time.monotonic() - t0:.3f}")
        return chan


def env(**extra: str) -> dict[str, str]:
    """The environment for a with-vcan command that runs in the session's kernel."""
    return dict(os.environ, WITH_VCAN_CHANNEL=str(channel()), **extra)


def vehicle() -> str:
    """Which vehicle the session's kernel runs on (from with-vcan's own words)."""
    log = (_session_dir() / "serve.log").read_text()
    for line in log.splitlines():
        if line.startswith("with-vcan: vehicle "):
            return line.split("vehicle ", 1)[1]
    return "unknown"


def _gone(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return True
    return state == "Z"


def _stop_group(pgid: int, proc: subprocess.Popen | None) -> None:
    """Ask nicely is done by the caller; here: TERM the group, then KILL it."""
    for sig, wait_s in ((signal.SIGTERM, 10.0), (signal.SIGKILL, 5.0)):
        if _gone(pgid):
            break
        try:
            os.killpg(pgid, sig)
        except ProcessLookupError:
            break
        t0 = time.monotonic()
        while not _gone(pgid) and time.monotonic() - t0 < wait_s:
            time.sleep(0.05)
    if proc is not None:
        try:
            proc.wait(5)
        except subprocess.TimeoutExpired:
            pass


def shutdown() -> None:
    """In the owning process at the end of the session: stop the kernel, remove the directory."""
    if os.environ.get(OWNER_ENV) != str(os.getpid()):
        return
    d = Path(os.environ[SESSION_ENV])
    pgid_file = d / "serve.pgid"
    if pgid_file.exists():
        pgid = int(pgid_file.read_text())
        (d / "channel").mkdir(exist_ok=True)
        (d / "channel" / "stop").touch()
        t0 = time.monotonic()
        while not _gone(pgid) and time.monotonic() - t0 < 15.0:
            if _started is not None and _started.poll() is not None:
                break
            time.sleep(0.05)
        _stop_group(pgid, _started)
    shutil.rmtree(d, ignore_errors=True)
