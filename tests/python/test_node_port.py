"""nte-node natively (this machine's kernel has no AF_CAN): a clear message and exit status 3;
bad arguments exit 2.  On a kernel with CAN, an absent interface gives exit status 4."""
from __future__ import annotations

import socket
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def node_binary() -> Path:
    for c in (ROOT / "build/host/bin/nte-node", ROOT / "build/node/bin/nte-node"):
        if c.exists():
            return c
    pytest.skip("nte-node not built (cmake -S tests/c_node -B build/node && cmake --build build/node)")


def _have_af_can() -> bool:
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
        return True
    except OSError:
        return False


def test_without_af_can_or_interface() -> None:
    r = subprocess.run([str(node_binary()), "--iface", "nte_absent0"], capture_output=True,
                       text=True, timeout=20)
    if _have_af_can():
        assert r.returncode == 4, r.stderr
        assert "no CAN interface 'nte_absent0'" in r.stderr
    else:
        assert r.returncode == 3, r.stderr
        assert "AF_CAN (SocketCAN) is not available in this kernel" in r.stderr
        assert "host_bench/with-vcan" in r.stderr
    assert r.stdout == ""


@pytest.mark.parametrize("args, text", [
    ([], "required: --iface"),
    (["--iface", "vcan0", "--model", "3"], "--model"),
    (["--iface", "vcan0", "--preset", "nope"], "unknown preset 'nope'"),
    (["--iface", "vcan0", "--base-id", "0x7F0"], "invalid node configuration"),
    (["--iface", "vcan0", "--params-per-step", "9"], "invalid node configuration"),
])
def test_bad_arguments(args: list[str], text: str) -> None:
    r = subprocess.run([str(node_binary()), *args], capture_output=True, text=True, timeout=20)
    assert r.returncode == 2
    assert text in r.stderr
