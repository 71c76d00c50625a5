"""nte-node started for one replay (`nte-bench replay --with-node`) and stopped after it.

The node runs on the replay's SocketCAN interface with the settings the reference is given
(model, preset, depth timeout, Params per step, base id), so the check compares like with like.
It is started in its own process group and stopped by that group -- SIGTERM, then SIGKILL after
NODE_STOP_S -- also when the replay fails or is interrupted.  Readiness is the node's own
``--ready FILE`` (written once its socket is bound), not a sleep.
"""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import tempfile
import time
from pathlib import Path

#: seconds to wait for the node's ready file (a kernel under QEMU starts processes slowly)
NODE_READY_S = 60.0
#: seconds between SIGTERM and SIGKILL when stopping it
NODE_STOP_S = 5.0
#: where `make build` puts the node
BUILT_NODE = Path(__file__).resolve().parents[1] / "build" / "host" / "bin" / "nte-node"


def node_program(given: str | None) -> str:
    """--node PATH, else the repository's build, else nte-node on PATH."""
    if given is not None:
        if not (os.path.isfile(given) and os.access(given, os.X_OK)):
            raise ValueError(f"--node {given}: not an executable file")
        return given
    if BUILT_NODE.is_file():
        return str(BUILT_NODE)
    found = shutil.which("nte-node")
    if found is None:
        raise ValueError("--with-node: nte-node not found (make build, or --node PATH)")
    return found


def node_arguments(channel: str, model: int, preset: str, depth_timeout_ms: float,
                   params_per_step: int, base_id: int | None) -> list[str]:
    """The node's flags for the reference's settings; refuses what the node cannot take."""
    if depth_timeout_ms != int(depth_timeout_ms) or not 1 <= depth_timeout_ms <= 3000:
        raise ValueError(f"--with-node: nte-node takes --depth-timeout-ms in whole "
                         f"milliseconds, 1..3000 (got {depth_timeout_ms:g})")
    args = ["--iface", channel, "--model", str(model), "--preset", preset,
            "--depth-timeout-ms", str(int(depth_timeout_ms)),
            "--params-per-step", str(params_per_step)]
    if base_id is not None:
        args += ["--base-id", f"0x{base_id:03X}"]
    return args


class StartedNode:
    """``with StartedNode(program, args): ...`` -- the node runs inside the block."""

    def __init__(self, program: str, args: list[str]) -> None:
        self.program = program
        self.args = args
        self.proc: subprocess.Popen[bytes] | None = None
        self._dir = tempfile.mkdtemp(prefix="nte-bench-node.")
        self.ready = Path(self._dir) / "ready"
        self.stderr_path = Path(self._dir) / "stderr"

    def __enter__(self) -> "StartedNode":
        with open(self.stderr_path, "wb") as err:
            self.proc = subprocess.Popen([self.program, *self.args, "--ready", str(self.ready)],
                                         stdout=subprocess.DEVNULL, stderr=err,
                                         start_new_session=True)
        deadline = time.monotonic() + NODE_READY_S
        while not self.ready.exists():
            if self.proc.poll() is not None:
                why = self.stderr_path.read_text(errors="replace").strip().splitlines()
                self._cleanup()
                raise ValueError(f"--with-node: nte-node exited with status "
                                 f"{self.proc.returncode} before it was ready"
                                 + (f": {why[-1]}" if why else ""))
            if time.monotonic() > deadline:
                self.stop()
                raise ValueError(f"--with-node: nte-node not ready within {NODE_READY_S:g} s")
            time.sleep(0.02)
        return self

    def stop(self) -> int | None:
        """Stop the node's process group; its exit status (None if it was never started)."""
        if self.proc is None:
            return None
        if self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGTERM)
                self.proc.wait(timeout=NODE_STOP_S)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()
            except ProcessLookupError:
                self.proc.wait()
        self._cleanup()
        return self.proc.returncode

    def _cleanup(self) -> None:
        shutil.rmtree(self._dir, ignore_errors=True)

    def __exit__(self, *exc: object) -> None:
        self.stop()


__all__ = ["StartedNode", "node_arguments", "node_program"]
