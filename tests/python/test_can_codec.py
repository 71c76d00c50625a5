"""The C CAN layer against independent Python implementations.

- The generated C pack/unpack code (cantools generate_c_source, float) against cantools' own
  Python codec on the same vectors: every signal at its range ends, one resolution step inside
  them, zero, random multiples of the resolution and random values; random payloads decoded.
- The C E2E module (firmware/can/nte_e2e.c) against the `autosar-e2e` package (profile 11,
  data id mode BOTH): same CRC on random payloads and data ids, same counter sequence, and the
  C check's verdicts on frames protected by the package.
- The committed generated code is what the DBC generates (firmware/can/regenerate.sh --check).
- The ids, offsets and data ids in nte_frames.h equal the DBC's attributes.

The C side runs through tests/c_can/can_vectors (built here with CMake into build/can).
"""
from __future__ import annotations

import math
import os
import random
import shutil
import struct
import subprocess
from pathlib import Path

import cantools
import pytest
from e2e.p11 import E2E_P11_DATAID_BOTH, e2e_p11_check, e2e_p11_protect

from reference_py.bus.dbc import DBC_PATH, NteDatabase

ROOT = Path(__file__).resolve().parents[2]
BUILD = ROOT / "build" / "can"


@pytest.fixture(scope="module")
def vectors_bin() -> Path:
    if shutil.which("cmake") is None:
        pytest.fail("cmake is required (apt-get install -y cmake)")
    subprocess.run(["cmake", "-S", str(ROOT / "tests" / "c_can"), "-B", str(BUILD)],
                   check=True, capture_output=True)
    subprocess.run(["cmake", "--build", str(BUILD), "--target", "can_vectors"],
                   check=True, capture_output=True)
    exe = BUILD / "bin" / "can_vectors"
    assert exe.is_file()
    return exe


class CTool:
    """Runs can_vectors once on a batch of command lines."""

    def __init__(self, exe: Path) -> None:
        self.exe = exe

    def run(self, lines: list[str]) -> list[list[str]]:
        proc = subprocess.run([str(self.exe)], input="\n".join(lines) + "\n", text=True,
                              capture_output=True, timeout=60, check=True)
        out = proc.stdout.splitlines()
        assert len(out) == len(lines), proc.stdout[-2000:]
        res = []
        for line, answer in zip(lines, out):
            parts = answer.split()
            assert parts[0] == "OK", f"{line!r} -> {answer!r}"
            res.append(parts[1:])
        return res


@pytest.fixture(scope="module")
def ctool(vectors_bin: Path) -> CTool:
    return CTool(vectors_bin)


@pytest.fixture(scope="module")
def db() -> cantools.database.can.Database:
    return cantools.database.load_file(str(DBC_PATH))


def f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


def fmt(x: float) -> str:
    return f"{x:.9g}" if isinstance(x, float) else str(x)


# ------------------------------------------------------------------ generated code is current

def test_generated_code_up_to_date() -> None:
    script = ROOT / "firmware" / "can" / "regenerate.sh"
    r = subprocess.run([str(script), "--check"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr


def test_regenerate_check_detects_a_change(tmp_path: Path) -> None:
    gen = ROOT / "firmware" / "can" / "generated"
    for f in ("nte_can.h", "nte_can.c"):
        shutil.copy(gen / f, tmp_path / f)
    text = (tmp_path / "nte_can.c").read_text()
    (tmp_path / "nte_can.c").write_text(text.replace("0.001f", "0.0011f", 1))
    env = dict(os.environ, NTE_CAN_GENERATED_DIR=str(tmp_path))
    r = subprocess.run([str(ROOT / "firmware" / "can" / "regenerate.sh"), "--check"],
                       capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 1
    assert "0.0011f" in r.stderr


# ------------------------------------------------------------------------ ids and signals

def test_ids_offsets_data_ids_match_dbc(ctool: CTool) -> None:
    nd = NteDatabase()
    (ids,) = ctool.run(["IDS"])
    seen = {}
    for item in ids:
        name, off, did = item.split(":")
        seen[name] = (int(off), int(did))
    assert seen == {n: (nd.offsets[n], nd.data_ids[n]) for n in nd.message_names()}
    assert nd.base_id == 0x200
    for m in nd.db.messages:  # the DBC's frame ids are base + offset
        assert m.frame_id == 0x200 + nd.offsets[m.name]
        assert m.length == 8 and not m.is_extended_frame


def test_signal_names(ctool: CTool, db) -> None:
    names = [m.name for m in db.messages]
    got = ctool.run([f"SIGNALS {n}" for n in names])
    for n, sigs in zip(names, got):
        assert set(sigs) == {s.name for s in db.get_message_by_name(n).signals}
        assert len(sigs) == len(db.get_message_by_name(n).signals)


# --------------------------------------------------------------------------- codec vectors

def _signal_values(sig, rng: random.Random) -> list[float]:
    """Range ends, one step inside, zero, random multiples of the resolution."""
    if sig.is_float:
        vals = [0.0, 9.99e29, -9.99e29, 1e-30, 7.9e-3, 2.46, -2.11e-2, 3.3e-7, 123456.7]
        vals += [rng.uniform(-10, 10) * 10 ** rng.randint(-5, 3) for _ in range(20)]
        return [f32(v) for v in vals]
    lo, hi, sc = sig.minimum, sig.maximum, sig.scale
    vals = [lo, hi, lo + sc, hi - sc]
    if lo <= 0.0 <= hi:
        vals.append(0.0)
    kmin, kmax = round(lo / sc), round(hi / sc)
    vals += [rng.randint(kmin, kmax) * sc for _ in range(20)]
    if sc == 1 and sig.offset == 0:
        vals = [int(round(v)) for v in vals]
    return vals


def _message_vectors(msg, rng: random.Random) -> list[dict]:
    """Vectors (python dicts of physical values) covering every signal's values."""
    e2e = {"Crc", "Counter"}
    if msg.is_multiplexed():
        groups = {}
        for s in msg.signals:
            if s.multiplexer_ids:
                groups.setdefault(s.multiplexer_ids[0], []).append(s)
        vecs = []
        for mux, sigs in sorted(groups.items()):
            per = {s.name: _signal_values(s, rng) for s in sigs}
            n = max(len(v) for v in per.values())
            for i in range(n):
                v = {"Crc": rng.randint(0, 255), "Counter": rng.randint(0, 14), "ParamIndex": mux}
                for s in sigs:
                    v[s.name] = per[s.name][i % len(per[s.name])]
                vecs.append(v)
        return vecs
    sigs = [s for s in msg.signals if s.name not in e2e]
    per = {s.name: _signal_values(s, rng) for s in sigs}
    vecs = []
    for s in sigs:  # each signal through all its values, the others random
        for val in per[s.name]:
            v = {"Crc": rng.randint(0, 255), "Counter": rng.randint(0, 14)}
            for o in sigs:
                v[o.name] = val if o is s else rng.choice(per[o.name])
            vecs.append(v)
    return vecs


def _close(c: float, py: float, sig) -> bool:
    if sig.is_float:
        return (math.isnan(c) and math.isnan(py)) or f32(c) == f32(py)
    # the C side decodes raw * scale in float32: relative error <= 1 float ulp or so
    return abs(c - py) <= 3e-7 * abs(py) + 1e-9


def test_encode_decode_vectors_match_cantools(ctool: CTool, db) -> None:
    rng = random.Random(6)
    lines, expect = [], []
    for msg in db.messages:
        order = ctool.run([f"SIGNALS {msg.name}"])[0]
        for v in _message_vectors(msg, rng):
            full = {n: v.get(n, 0) for n in order}
            lines.append(f"ENC {msg.name} " + " ".join(fmt(full[n]) for n in order))
            data = msg.encode(v, scaling=True, strict=True)
            expect.append((msg, v, data))
    got = ctool.run(lines)
    dec_lines = [f"DEC {m.name} {d.hex()}" for m, _, d in expect]
    dec = ctool.run(dec_lines)
    n_checked = 0
    orders: dict[str, list[str]] = {}
    for (msg, v, data), enc, vals in zip(expect, got, dec):
        assert enc[0] == data.hex(), f"{msg.name} {v}: C {enc[0]} cantools {data.hex()}"
        # each message's own signal order (the C tool's SIGNALS answer)
        if msg.name not in orders:
            orders[msg.name] = ctool.run([f"SIGNALS {msg.name}"])[0]
        order = orders[msg.name]
        py = msg.decode(data, decode_choices=False, scaling=True)
        for name, cval in zip(order, vals):
            if name not in py:
                continue
            sig = msg.get_signal_by_name(name)
            assert _close(float(cval), float(py[name]), sig), (msg.name, name, cval, py[name])
            if not sig.is_float and name in v:  # the value itself survived to a resolution step
                assert abs(float(py[name]) - float(v[name])) <= sig.scale * 0.5 + 1e-9
            n_checked += 1
    assert len(expect) > 300 and n_checked > 1500


def test_random_values_and_payloads_match_cantools(ctool: CTool, db) -> None:
    """Values off the resolution grid (rounding) and random payloads (decoding)."""
    rng = random.Random(61)
    lines, expect = [], []
    for msg in db.messages:
        if msg.is_multiplexed():
            continue
        order = ctool.run([f"SIGNALS {msg.name}"])[0]
        for _ in range(200):
            v, ambiguous = {}, False
            for s in msg.signals:
                if s.scale == 1 and s.offset == 0:
                    v[s.name] = rng.randint(int(s.minimum), int(s.maximum))
                    continue
                x = f32(rng.uniform(s.minimum, s.maximum))
                q = x / s.scale
                if abs(q - math.floor(q) - 0.5) < 0.1 or not (s.minimum <= round(q) * s.scale <= s.maximum):
                    ambiguous = True  # float32 vs double division may round differently
                v[s.name] = x
            if ambiguous:
                continue
            lines.append(f"ENC {msg.name} " + " ".join(fmt(v[n]) for n in order))
            expect.append(msg.encode(v, scaling=True, strict=True).hex())
    got = ctool.run(lines)
    assert len(lines) > 600
    assert [g[0] for g in got] == expect

    # random payloads: cantools and C unpack the same bits
    dec_lines, dec_expect = [], []
    for msg in db.messages:
        for _ in range(200):
            data = bytearray(rng.getrandbits(8) for _ in range(8))
            if msg.is_multiplexed():
                data[1] = (data[1] & 0x0F) | (rng.randint(0, 6) << 4)
            dec_lines.append(f"DEC {msg.name} {data.hex()}")
            dec_expect.append((msg, msg.decode(bytes(data), decode_choices=False, scaling=True)))
    orders = {m.name: ctool.run([f"SIGNALS {m.name}"])[0] for m in db.messages}
    for (msg, py), vals in zip(dec_expect, ctool.run(dec_lines)):
        for name, cval in zip(orders[msg.name], vals):
            if name in py:
                assert _close(float(cval), float(py[name]), msg.get_signal_by_name(name)), \
                    (msg.name, name, cval, py[name])


# ------------------------------------------------------------------------------ E2E

def test_crc_matches_autosar_e2e(ctool: CTool) -> None:
    rng = random.Random(11)
    lines, expect = [], []
    for _ in range(2000):
        n = rng.randint(2, 8)
        data = bytearray(rng.getrandbits(8) for _ in range(n))
        data[1] = (data[1] & 0xF0) | rng.randint(0, 14)
        did = rng.getrandbits(16)
        ref = bytearray(data)
        e2e_p11_protect(ref, did, data_id_mode=E2E_P11_DATAID_BOTH, increment_counter=False)
        lines.append(f"CRC {did} {data.hex()}")
        expect.append(ref[0])
    got = [int(g[0]) for g in ctool.run(lines)]
    assert got == expect


def test_protect_sequence_matches_autosar_e2e(ctool: CTool) -> None:
    rng = random.Random(12)
    for did in (0x4E00, 0x4E12, 0x0000, 0xFFFF, 0x1234):
        payload = bytearray(rng.getrandbits(8) for _ in range(8))
        (frames,) = ctool.run([f"PROTECT {did} 40 {payload.hex()}"])
        ref = bytearray(payload)
        ref[1] = (ref[1] & 0xF0) | 14  # the package increments before protecting: 14 -> 0
        for k, fhex in enumerate(frames):
            e2e_p11_protect(ref, did, data_id_mode=E2E_P11_DATAID_BOTH, increment_counter=True)
            frame = bytearray.fromhex(fhex)
            assert frame == ref, (did, k)
            assert frame[1] & 0x0F == k % 15
            assert frame[1] & 0xF0 == payload[1] & 0xF0  # signal nibble kept
            assert e2e_p11_check(bytearray(frame), did, data_id_mode=E2E_P11_DATAID_BOTH)


def _py_frame(did: int, counter: int, payload: bytes) -> str:
    f = bytearray(payload)
    f[1] = (f[1] & 0xF0) | counter
    e2e_p11_protect(f, did, data_id_mode=E2E_P11_DATAID_BOTH, increment_counter=False)
    return f.hex()


def test_check_verdicts_on_autosar_e2e_frames(ctool: CTool) -> None:
    did, other = 0x4E01, 0x4E00
    p = bytes(range(0x10, 0x18))
    flipped = bytearray.fromhex(_py_frame(did, 9, p))
    flipped[5] ^= 0x20
    counter15 = bytearray(p)
    counter15[1] |= 0x0F
    e2e_p11_protect(counter15, did, data_id_mode=E2E_P11_DATAID_BOTH, increment_counter=False)
    seq = [
        (_py_frame(did, 13, p), "0:0"),   # first frame: ok whatever the counter
        (_py_frame(did, 14, p), "0:0"),   # +1
        (_py_frame(did, 0, p), "0:0"),    # wrap 14 -> 0
        (_py_frame(did, 0, p), "-4:0"),   # repeated
        (_py_frame(did, 3, p), "1:2"),    # two lost
        (flipped.hex(), "-3:0"),          # bad crc
        (_py_frame(other, 4, p), "-3:0"),  # another message's data id (masquerade)
        (_py_frame(did, 4, p)[:14], "-2:0"),  # 7 bytes: wrong length
        (counter15.hex(), "-5:0"),        # counter 15 never sent
        (_py_frame(did, 4, p), "0:0"),    # continues from 3
        (_py_frame(did, 3, p), "1:13"),   # 14 steps ahead = 13 lost
    ]
    (got,) = ctool.run([f"CHECK {did} " + " ".join(f for f, _ in seq)])
    assert got == [e for _, e in seq]
    # the bench's Python receiver gives the same verdicts
    nd = NteDatabase()
    rx = nd.receiver()
    names = {0: "ok", 1: "skipped", -2: "wrong_length", -3: "bad_crc", -4: "repeated",
             -5: "bad_counter"}
    for f, e in seq:
        status, lost = rx.check("Force", bytes.fromhex(f))
        code, nlost = e.split(":")
        assert (status, lost) == (names[int(code)], int(nlost))


def test_bench_encoder_matches_c(ctool: CTool, db) -> None:
    """reference_py.bus.dbc (cantools + autosar-e2e) and C (generated + nte_e2e) give the same frame."""
    nd = NteDatabase()
    tx = nd.sender()
    msg = db.get_message_by_name("Depth")
    order = ctool.run(["SIGNALS Depth"])[0]
    sig = {"Depth": 42.123, "Velocity": -9.87, "SensorTime": 6.5535}
    bench = [tx.encode("Depth", sig) for _ in range(3)]
    raw = msg.encode({**sig, "Crc": 0, "Counter": 0}, scaling=True, strict=True)
    (c_frames,) = ctool.run([f"PROTECT {nd.data_ids['Depth']} 3 {raw.hex()}"])
    assert [b.hex() for b in bench] == c_frames
    assert order  # signal order known
