"""A configuration sent over the bus (the Setting frame; nte_node.h SETTINGS; nte-bench
settings): the node configured by one transfer of a file runs exactly as the node started with
``--config`` on that file, and a transfer that breaks off changes nothing that runs."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import can
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from host_bench.replay import scenario_frames  # noqa: E402
from host_bench.settings_file import item_numbers, setting_items, transfer  # noqa: E402
from reference_py.bus.dbc import NteDatabase  # noqa: E402
from reference_py.tools.estconfig import read_config_file  # noqa: E402
from test_node_port import node_binary  # noqa: E402
from test_node_port import replay_node_args as replay  # noqa: E402

DB = NteDatabase()
OUTPUTS = ("Estimate", "Params", "Contact")


def outputs(sent: list) -> list[tuple[int, bytes]]:
    """The node's Estimate, Params and Contact frames, (id, bytes), in order."""
    ids = {DB.frame_id(n) for n in OUTPUTS}
    return [(m.arbitration_id, bytes(m.data)) for m in sent if m.arbitration_id in ids]


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The layered phantom (lab, seed 101: four membranes) and nte-run's Model III export of
    it (its layer sets, strengths, time constants, turn-over length, r_n2)."""
    work = tmp_path_factory.mktemp("settings")
    csv, cfg = work / "lab101.csv", work / "m3.json"
    subprocess.run([str(ROOT / ".venv/bin/nte-ref"), "phantom", "lab", "--seed", "101",
                    "--out", str(csv)], check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    r = subprocess.run([str(node_binary().parent / "nte-run"), str(csv), "--model", "3",
                        "--out", str(work / "e.csv"), "--export-config", str(cfg)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    return csv, cfg


def with_transfer(frames: list, messages: list[can.Message], t: float) -> list:
    """`frames` with the transfer's messages inserted at scenario time t."""
    k = next(i for i, (ts, _) in enumerate(frames) if ts >= t)
    return frames[:k] + [(t, m) for m in messages] + frames[k:]


def test_items_name_every_key_the_file_gives(exported: tuple[Path, Path]) -> None:
    """The export's items: model, the seven parameters, and each Model III key it writes;
    the layer sets' items follow the set count, five per set; each item once, in order;
    values are float32."""
    _, cfg = exported
    fc = read_config_file(str(cfg))
    items = setting_items(fc, DB)
    n = item_numbers(DB)
    got = [i for i, _ in items]
    assert got == sorted(got) and len(set(got)) == len(got)
    assert got[:8] == [n["model"]] + list(range(n["sigma0"], n["beta"] + 1))
    sets = fc.m3.get("layer_sets") or ()
    assert len(sets) >= 1, "the layered phantom's export should carry layer sets"
    assert dict(items)[n["layer_sets"]] == len(sets)
    assert got[-5 * len(sets):] == list(range(n["layer_sets"] + 1,
                                              n["layer_sets"] + 1 + 5 * len(sets)))
    assert dict(items)[n["layer_sets"] + 1] == pytest.approx(sets[0].start_mm, rel=1e-7)
    for key in ("delta", "r_n2", "tau_fast_s", "tau_slow_s", "g_fast", "g_slow"):
        assert n[key] in dict(items), key


def test_transfer_configures_the_node_as_config_does(tmp_path: Path,
                                                     exported: tuple[Path, Path]) -> None:
    """A Model II node sent the export as Setting frames before the record publishes, frame
    for frame, what a node started with --config on the export publishes (Model III, its
    layer sets, strengths and constants); without the transfer it runs Model II."""
    csv, cfg = exported
    frames = scenario_frames(str(csv), DB, 1000.0)[:8000]      # the first 8 s
    items = setting_items(read_config_file(str(cfg)), DB)
    sent_bus, st_bus = replay(tmp_path, with_transfer(frames, transfer(items, DB.sender()),
                                                      frames[0][0]), "bus", ["--model", "2"])
    sent_cfg, st_cfg = replay(tmp_path, frames, "cfg", ["--config", str(cfg)])
    assert st_bus["settings_applied"] == 1 and st_bus["events"]["setting_refused"] == 0
    assert st_bus["rx_accepted"]["setting"] == len(items) + 2
    assert st_bus["model"] == 3 and st_cfg["model"] == 3
    got, want = outputs(sent_bus), outputs(sent_cfg)
    assert len(want) > 1000 and got == want
    sent_m2, st_m2 = replay(tmp_path, frames, "m2", ["--model", "2"])
    assert st_m2["model"] == 2 and outputs(sent_m2) != want


def test_transfer_carries_the_layer_sets_to_predict_only(tmp_path: Path,
                                                         exported: tuple[Path, Path]) -> None:
    """The whole record in predict-only mode (Command ForceSource 2 from the start: the
    export's known surface, its layer sets entered at their depths): the node configured over
    the bus publishes what the --config node publishes, frame for frame, and the sets matter
    (the same transfer without them publishes other forces)."""
    csv, cfg = exported
    frames = scenario_frames(str(csv), DB, 1000.0)
    fc = read_config_file(str(cfg))
    items = setting_items(fc, DB)
    assert len(fc.m3["layer_sets"]) == 3
    t0 = frames[0][0]
    sender = DB.sender()
    model_only = [DB.sender().message("Command", {"ForceSource": 2})]
    bus = with_transfer(frames, transfer(items, sender) + model_only, t0)
    sent_bus, st_bus = replay(tmp_path, bus, "p-bus", ["--model", "2"])
    sent_cfg, _ = replay(tmp_path, with_transfer(frames, model_only, t0), "p-cfg",
                         ["--config", str(cfg)])
    assert st_bus["settings_applied"] == 1 and st_bus["predict_on"] >= 1
    assert len(outputs(sent_cfg)) > 4000 and outputs(sent_bus) == outputs(sent_cfg)
    print(f"\npredict-only over the whole record: {len(outputs(sent_cfg))} frames equal")
    n = item_numbers(DB)
    no_sets = [(i, v) for i, v in items if i < n["layer_sets"]]
    bus0 = with_transfer(frames, transfer(no_sets, DB.sender()) + model_only, t0)
    sent0, _ = replay(tmp_path, bus0, "p-nosets", ["--model", "2"])
    assert outputs(sent0) != outputs(sent_bus)


def _model_command(model: int) -> can.Message:
    return DB.sender().message("Command", {"ModelSel": model})


@pytest.mark.parametrize("spoil", ["lost", "repeated", "count", "value", "no_model",
                                   "in_tissue"])
def test_a_transfer_that_breaks_off_changes_nothing_that_runs(
        tmp_path: Path, exported: tuple[Path, Path], spoil: str) -> None:
    """Each way a transfer can fail: refused (setting_refused counted, nothing applied), the
    node runs on as it was (its outputs equal a node's never sent anything), a model change
    after it is refused (the configurations hold the partial transfer); sent again whole,
    out of tissue, it is applied."""
    csv, cfg = exported
    frames = scenario_frames(str(csv), DB, 1000.0)[:8000]
    items = setting_items(read_config_file(str(cfg)), DB)
    n = item_numbers(DB)
    sender = DB.sender()
    t0 = frames[0][0]
    if spoil == "lost":
        bad = transfer(items, sender)
        del bad[3]                                            # counter skips: a lost frame
    elif spoil == "repeated":
        bad = transfer(items[:3] + items[2:], sender)[:-1]    # an item twice, count + 1 ...
        bad.append(sender.message("Setting", {"Item": n["commit"], "Value": len(items) + 1}))
    elif spoil == "count":
        bad = transfer(items, sender)[:-1]
        bad.append(sender.message("Setting", {"Item": n["commit"], "Value": len(items) - 1}))
    elif spoil == "value":
        bad = transfer([(n["model"], 4.0)] + items[1:], sender)
    elif spoil == "no_model":
        bad = transfer(items[1:], sender)
    else:
        bad = transfer(items, sender)
    in_tissue = 4.0 if spoil == "in_tissue" else t0           # lab-101 touches at ~1 s
    command = _model_command(3)
    stream = with_transfer(frames, bad, in_tissue)
    stream = with_transfer(stream, [command], in_tissue + 0.2)
    sent, st = replay(tmp_path, stream, spoil, ["--model", "2"])
    assert st["settings_applied"] == 0 and st["events"]["setting_refused"] >= 1
    assert st["model"] == 2
    # a model change after it is refused: in tissue as ever, out of tissue because the
    # configurations hold the partial transfer (it never runs)
    assert st["events"]["command_refused"] == 1 and st["commands_applied"] == 0
    if spoil != "in_tissue":
        # the control: without the broken transfer the same command is taken (out of tissue)
        _, st_c = replay(tmp_path, with_transfer(frames, [_model_command(3)], in_tissue + 0.2),
                         spoil + "-control", ["--model", "2"])
        assert st_c["commands_applied"] == 1 and st_c["model"] == 3
    sent_m2, _ = replay(tmp_path, frames, "m2", ["--model", "2"])
    assert outputs(sent) == outputs(sent_m2)
    # sent again whole once the needle is out (after the record's last retraction): applied
    whole = scenario_frames(str(csv), DB, 1000.0)
    t_end = whole[-1][0]
    stream2 = with_transfer(whole, bad, in_tissue)
    stream2 = with_transfer(stream2, transfer(items, sender), t_end)
    _, st2 = replay(tmp_path, stream2, spoil + "2", ["--model", "2"])
    assert st2["events"]["setting_refused"] >= 1
    assert st2["settings_applied"] == 1 and st2["model"] == 3


def test_bench_refuses_a_bad_file(tmp_path: Path) -> None:
    """nte-bench settings reads the file by the readers' rules first: a bad key is one line
    naming it, exit 2, and nothing is sent (no bus is opened)."""
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"schema": "nte-estimator-config/1", "model": 4,
                               "params": {}}))
    r = subprocess.run([str(ROOT / ".venv/bin/nte-bench"), "settings", str(bad),
                        "--channel", "nte_absent0"], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [f"nte-bench: error: {bad}: key 'model': must be "
                                             f"1, 2 or 3"]


def test_the_header_items_are_the_dbc_items() -> None:
    """nte_frames.h's NTE_FRAMES_SETTING_* are the DBC's Setting.Item values; the layer sets'
    items follow the set count, one field more than a set has values (its start)."""
    import re
    from reference_py.params import LAYER_SET_NAMES
    text = (ROOT / "firmware/can/nte_frames.h").read_text()
    c = {m.group(1).lower(): int(m.group(2))
         for m in re.finditer(r"NTE_FRAMES_SETTING_([A-Z0-9_]+) = (\d+)", text)}
    n = item_numbers(DB)
    for name in ("begin", "model", "r_n2", "surface_mm", "tau_fast_s", "tau_slow_s",
                 "relax_branches", "relaxation", "direction_memory", "layer_sets", "commit"):
        assert c[name] == n[name], name
    assert c["param0"] == n["sigma0"] and n["delta"] == n["sigma0"] + 9
    assert c["layer0"] == n["layer_sets"] + 1
    assert c["layer_fields"] == 1 + len(LAYER_SET_NAMES)
    assert c["last_value"] == c["layer0"] + c["layer_fields"] * c["layer_sets_max"] - 1
    from host_bench.settings_file import FRAME_ITEMS_LAST, FRAME_LAYER_SETS
    assert (FRAME_LAYER_SETS, FRAME_ITEMS_LAST) == (c["layer_sets_max"], c["last_value"])


def test_the_mirror_counts_broken_transfers_as_the_node(tmp_path: Path,
                                                        exported: tuple[Path, Path]) -> None:
    """300 seeded Setting frames (random items and values, a begin now and then, broken CRCs,
    skipped counters, short frames) amid the phantom's first 4 s: nte-node and the bench's
    mirror count the same events, refuse the same Command after them and publish the same
    frames; a transfer the node would apply makes the mirror refuse to go on (it runs
    presets)."""
    import random
    from host_bench.node_mirror import NodeMirror
    from host_bench.node_outputs import node_outputs
    csv, cfg = exported
    frames = scenario_frames(str(csv), DB, 1000.0)[:4000]
    n = item_numbers(DB)
    rng = random.Random(2026)
    sender = DB.sender()
    noise = []
    for k in range(300):
        roll = rng.random()
        item = n["begin"] if roll < 0.1 else rng.choice([rng.randrange(0, 256), n["model"],
                                                         n["relax_branches"], n["layer_sets"],
                                                         n["commit"], 20 + rng.randrange(40)])
        value = rng.choice([float(rng.randrange(0, 6)), rng.uniform(-2, 70), 1.5])
        m = sender.message("Setting", {"Item": item, "Value": value})
        if roll > 0.95:
            m.data = bytearray(m.data)
            m.data[5] ^= 0x10                                 # a broken CRC
        elif roll > 0.9:
            sender.encode("Setting", {"Item": 1, "Value": 1.0})   # a frame lost: skip
        elif roll > 0.88:
            m.data = bytearray(m.data[:6])
            m.dlc = 6
        noise.append(m)
    t0 = frames[0][0]
    stream = with_transfer(frames, noise, t0)
    stream = with_transfer(stream, [_model_command(3)], t0 + 0.2)
    sent, st = replay(tmp_path, stream, "fuzz", ["--model", "2"])
    mirror = NodeMirror(model=2).feed_all(m for _, m in stream)
    events = {k: v for k, v in st["events"].items() if v}
    assert events == mirror.events
    assert events["setting_refused"] > 50 and events["bad_crc"] > 0
    assert st["settings_applied"] == 0 and st["events"]["command_refused"] == 1
    est, par, _ = node_outputs(DB, sent)
    assert [e.key() for e in est] == [e.key() for e in mirror.estimates]
    items = setting_items(read_config_file(str(cfg)), DB)
    with pytest.raises(ValueError, match="does not follow a configuration"):
        NodeMirror(model=2).feed_all(transfer(items, DB.sender()))
