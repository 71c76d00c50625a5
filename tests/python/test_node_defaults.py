"""The node's defaults, written once in firmware/node/nte_node.h (NTE_NODE_DEFAULT_*).

nte_node_config_default (nte_node.c), the Linux port's options (port/linux/nte_node_main.c)
and the bench's node mirror (host_bench/node_mirror.py, which reads the header at import) take
them from there; the port's help text still writes them out, so it is checked against them,
and the C sources are checked to hold no literal copy.
"""
from __future__ import annotations

from pathlib import Path

from host_bench.cli import build_parser
from host_bench.node_mirror import NODE, NodeMirror

ROOT = Path(__file__).resolve().parents[2]
NODE_C = ROOT / "firmware" / "node" / "nte_node.c"
MAIN_C = ROOT / "firmware" / "port" / "linux" / "nte_node_main.c"


def test_mirror_defaults_are_the_header() -> None:
    m = NodeMirror.__dataclass_fields__
    assert m["model"].default == NODE["DEFAULT_MODEL"]
    assert m["depth_timeout_us"].default == NODE["DEFAULT_DEPTH_TIMEOUT_US"]
    assert m["resync_gap_us"].default == NODE["DEFAULT_RESYNC_GAP_US"]
    assert m["command_interval_us"].default == NODE["DEFAULT_COMMAND_INTERVAL_US"]
    assert m["params_per_step"].default == NODE["DEFAULT_PARAMS_PER_STEP"]


def test_bench_flags_default_to_the_header() -> None:
    a = build_parser().parse_args(["check", "DIR"])
    assert a.model == NODE["DEFAULT_MODEL"]
    assert a.depth_timeout_ms * 1000 == NODE["DEFAULT_DEPTH_TIMEOUT_US"]
    assert a.params_per_step == NODE["DEFAULT_PARAMS_PER_STEP"]


def test_c_takes_the_defines() -> None:
    body = NODE_C.read_text().split("void nte_node_config_default", 1)[1].split("\n}\n", 1)[0]
    for field in ("depth_timeout_us", "heartbeat_period_us", "params_per_step", "rx_budget",
                  "resync_gap_us", "command_interval_us"):
        assert f"cfg->{field} = NTE_NODE_DEFAULT_{field.upper()};" in body, field
    main = MAIN_C.read_text()
    assert "a->model = NTE_NODE_DEFAULT_MODEL;" in main
    assert "a->timeout_ms = NTE_NODE_DEFAULT_DEPTH_TIMEOUT_US / 1000u;" in main
    assert "a->heartbeat_ms = NTE_NODE_DEFAULT_HEARTBEAT_PERIOD_US / 1000u;" in main
    assert "a->resync_gap_ms = NTE_NODE_DEFAULT_RESYNC_GAP_US / 1000u;" in main


def test_port_help_states_the_defaults() -> None:
    main = MAIN_C.read_text()
    for text in (f"[--depth-timeout-ms {NODE['DEFAULT_DEPTH_TIMEOUT_US'] // 1000}]",
                 f"[--heartbeat-ms {NODE['DEFAULT_HEARTBEAT_PERIOD_US'] // 1000}]",
                 f"[--params-per-step {NODE['DEFAULT_PARAMS_PER_STEP']}]",
                 f"[--resync-gap-ms {NODE['DEFAULT_RESYNC_GAP_US'] // 1000}]",
                 f"--model (default {NODE['DEFAULT_MODEL']})"):
        assert text in main, text
