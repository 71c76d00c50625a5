"""The board image: the float library on the Cortex-M4F under QEMU (mps2-an386)
prints the same bits as the host's float build, and the image holds no allocation and no
double-precision routine.

Builds the images (the top-level project with cmake/arm-none-eabi.cmake: build/m4) and the host
twin (target nte-selftest-host of build/host) unless NTE_BOARD_NO_BUILD=1 (then both must
already be built).  Skips only when arm-none-eabi-gcc or
qemu-system-arm is missing (the Makefile's board target installs them).  QEMU is started and
stopped by its PID, also on failure.
"""
from __future__ import annotations

import math
import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PORT = ROOT / "firmware" / "port" / "mps2-an386"
M4 = ROOT / "build" / "m4"
HOST = ROOT / "build" / "host"
SELFTEST = M4 / "bin" / "nte-selftest.elf"
BOARD = M4 / "bin" / "nte-board.elf"
TWIN = HOST / "bin" / "nte-selftest-host"
QEMU_TIMEOUT_S = 120

MISSING = [t for t in ("arm-none-eabi-gcc", "arm-none-eabi-nm", "qemu-system-arm")
           if shutil.which(t) is None]
SKIP_REASON = (f"{', '.join(MISSING)} not installed (apt-get install -y "
               "--no-install-recommends gcc-arm-none-eabi libnewlib-arm-none-eabi "
               "qemu-system-arm; `make board` does it)")


def _run(args: list[str]) -> None:
    r = subprocess.run(args, cwd=ROOT, capture_output=True, text=True)
    if r.returncode != 0:
        pytest.fail(f"{' '.join(args)} failed ({r.returncode}):\n{r.stdout}\n{r.stderr}")


@pytest.fixture(scope="module")
def built() -> None:
    if MISSING:
        pytest.skip(SKIP_REASON)
    if os.environ.get("NTE_BOARD_NO_BUILD") != "1":
        _run(["cmake", "-S", str(ROOT), "-B", str(M4),
              "-DCMAKE_TOOLCHAIN_FILE=cmake/arm-none-eabi.cmake"])
        _run(["cmake", "--build", str(M4), "-j2"])
        if not (HOST / "CMakeCache.txt").exists():
            _run(["cmake", "-S", str(ROOT), "-B", str(HOST), "-DCMAKE_BUILD_TYPE=Release"])
        _run(["cmake", "--build", str(HOST), "-j2", "--target", "nte-selftest-host"])
    for f in (SELFTEST, BOARD, TWIN):
        assert f.exists(), f"{f} not built"


def run_qemu(elf: Path, timeout_s: float = QEMU_TIMEOUT_S) -> tuple[int, str, str]:
    """Runs an image that exits through semihosting; returns (status, stdout, stderr)
    (semihosting writes to QEMU's stderr).  Stops QEMU by its PID on a timeout."""
    args = ["qemu-system-arm", "-M", "mps2-an386", "-cpu", "cortex-m4", "-display", "none",
            "-monitor", "none", "-serial", "null", "-semihosting-config",
            "enable=on,target=native", "-kernel", str(elf)]
    p = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        out, err = p.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        p.send_signal(signal.SIGTERM)
        try:
            out, err = p.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            p.kill()
            out, err = p.communicate()
        pytest.fail(f"QEMU did not exit within {timeout_s} s (did the image boot?)\n"
                    f"stdout:\n{out[-4000:]}\nstderr:\n{err[-4000:]}")
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    return p.returncode, out, err


@pytest.fixture(scope="module")
def board_run(built) -> tuple[int, str, str]:
    return run_qemu(SELFTEST)


@pytest.fixture(scope="module")
def host_lines(built) -> list[str]:
    r = subprocess.run([str(TWIN)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return r.stdout.splitlines()


def test_selftest_boots_and_exits_zero(board_run) -> None:
    status, out, err = board_run
    assert status == 0, f"QEMU exit status {status}\nstdout:\n{out[-4000:]}\nstderr:\n{err[-4000:]}"
    assert "FAULT" not in err
    lines = err.splitlines()
    assert lines and lines[0].startswith("R 0 "), f"no self-test output:\n{err[-4000:]}"
    assert lines[-1].startswith("F stack_used="), lines[-1]


def test_selftest_bit_identical_to_host(board_run, host_lines) -> None:
    status, _out, err = board_run
    assert status == 0
    board = [ln for ln in err.splitlines() if not ln.startswith("F ")]
    assert len(board) == len(host_lines)
    for k, (b, h) in enumerate(zip(board, host_lines)):
        assert b == h, f"line {k + 1} differs:\n  board {b}\n  host  {h}"
    # five runs over the whole scenario (the last one Model III), every sample printed; the
    # robust run (2) goes on at the surface until its refinement is adopted
    n_samples = _scenario_len()
    for run in range(5):
        got = sum(1 for ln in board if ln.startswith(f"S {run} "))
        assert got == n_samples or (run == 2 and n_samples < got), (run, got)
    assert sum(1 for ln in board if ln.startswith("E ")) == 5


def _default_slices() -> int:
    """Samples the default refinement takes: 2 (fit_iterations + 1) simulations of
    buffer_len - 1 entries, slice_entries a sample (nte.h THE ROBUST ESTIMATOR)."""
    from reference_py.robust import RobustConfig
    rc = RobustConfig()
    return -(-2 * (rc.fit_iterations + 1) * (rc.buffer_len - 1) // rc.slice_entries)


def _scenario_len() -> int:
    return int(re.search(r"#define NTE_SCENARIO_LEN (\d+)",
                         (PORT / "scenario.h").read_text()).group(1))


def test_selftest_exercises_the_refinement(host_lines) -> None:
    """The robust run refines once (status bit 9, REFINED), in 1 710 slices (bit 15, REFINING:
    one buffer entry a sample) from the sample that leaves the tissue on (nte.h THE ROBUST
    ESTIMATOR, the defaults); the run goes on past the scenario, at the surface, until the
    refinement is adopted and ends there, while the other runs end with the scenario."""
    robust = [int(ln.split()[7], 16) for ln in host_lines if ln.startswith("S 2 ")]
    refined = [k for k, st in enumerate(robust) if st & (1 << 9)]
    slicing = [k for k, st in enumerate(robust) if st & (1 << 15)]
    assert _default_slices() == 1710
    assert refined == [len(robust) - 1]
    assert slicing == list(range(refined[0] - 1709, refined[0] + 1))
    assert len(robust) > _scenario_len()
    for run in (0, 1, 3, 4):
        assert sum(ln.startswith(f"S {run} ") for ln in host_lines) == _scenario_len(), run


def _figures():
    import importlib.util
    spec = importlib.util.spec_from_file_location("nte_board_figures", PORT / "figures.py")
    mod = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    spec.loader.exec_module(mod)
    return mod


FLASH_BUDGET_B = 32 * 1024
RAM_BUDGET_B = 8 * 1024


def test_stack_high_water_mark(board_run) -> None:
    """The painted high-water mark of the self-test (incl. a robust refinement) is within the
    call graph's bound, and the stack region holds it plus an exception frame and the deepest
    handler with the stated margin (mps2.ld: >= 20 %)."""
    _status, _out, err = board_run
    m = re.search(r"^F stack_used=(\d+) stack_size=(\d+) sizeof_nte_t=(\d+)$", err, re.M)
    assert m, err[-2000:]
    used, size = int(m.group(1)), int(m.group(2))
    fig = _figures()
    f = fig.image_figures(M4, "nte-selftest")
    assert 0 < used <= f["main_stack"], (used, f["main_stack"])
    worst = used + fig.EXCEPTION_FRAME_B + f["handler_stack"]
    assert size == f["stack"]
    assert size >= fig.STACK_MARGIN * worst, f"stack {size} B for a worst case of {worst} B"


@pytest.mark.parametrize("name", ["nte-board", "nte-selftest"])
def test_image_fits_flash_and_ram_budget(built, name: str) -> None:
    """arm-none-eabi-size: flash (text + data) <= 32 KiB and RAM (data + bss, the stack
    region included) <= 8 KiB; the stack region >= 1.2 x the call graph's worst case."""
    fig = _figures()
    f = fig.image_figures(M4, name)
    assert f["flash"] <= FLASH_BUDGET_B, f
    assert f["ram"] <= RAM_BUDGET_B, f
    worst = f["main_stack"] + fig.EXCEPTION_FRAME_B + f["handler_stack"]
    assert f["stack"] >= fig.STACK_MARGIN * worst, f


ALLOCATION = re.compile(r"^(malloc|free|calloc|realloc|_malloc_r|_free_r|_calloc_r|"
                        r"_realloc_r|_sbrk|_sbrk_r)$")
DOUBLE = re.compile(r"^(__aeabi_d\w+|__aeabi_f2d|__aeabi_[il]2d|__aeabi_ui2d|__aeabi_ul2d|"
                    r"__\w*df[23]?|__\w*df\w+|__ieee754_(exp|log|pow|sqrt|fmod|log10)|"
                    r"exp|log|log10|pow|sqrt|fmod|sin|cos|tan|atan2?|_printf_float)$")


def _symbols(elf: Path) -> list[str]:
    nm = subprocess.run(["arm-none-eabi-nm", str(elf)], capture_output=True, text=True,
                        check=True).stdout
    return [ln.split()[-1] for ln in nm.splitlines() if ln.strip()]


@pytest.mark.parametrize("elf", [SELFTEST, BOARD], ids=["selftest", "board"])
def test_image_has_no_allocation(built, elf: Path) -> None:
    bad = sorted(n for n in _symbols(elf) if ALLOCATION.match(n))
    assert not bad, f"{elf.name} links {bad}"
    text = elf.with_suffix(".map").read_text()
    for sym in ("malloc", "free", "_sbrk"):
        assert re.search(rf"^{sym}\s", text, re.M) is None, f"{elf.name}.map lists {sym}"


def test_float_image_has_no_double_routine(built) -> None:
    """The self-test image is the float library alone: no double routine may be linked
    (soft-float helpers __aeabi_d*, __adddf3, ..., or a double libm function)."""
    bad = sorted(n for n in _symbols(SELFTEST) if DOUBLE.match(n))
    assert not bad, f"{SELFTEST.name} links {bad}"
    text = SELFTEST.with_suffix(".map").read_text()
    for sym in ("__aeabi_dadd", "__aeabi_dmul", "__aeabi_ddiv", "__aeabi_f2d", "__adddf3",
                "__muldf3", "__divdf3", "__extendsfdf2"):
        assert re.search(rf"^{sym}\s", text, re.M) is None, f"map lists {sym}"


def test_board_image_has_no_double_routine(built) -> None:
    """The node image (estimator, CAN layer, node loop, SLCAN port) links no double routine:
    the generated codec's unsigned encode helper converts float -> uint32_t (regenerate.sh
    normalises cantools' double -> uint64_t helper), so no soft double routine is even pulled
    from libgcc (the link map lists none)."""
    # newlib's single-precision internals (__ieee754_fmodf for the heartbeat's uptime wrap)
    # end in "f" and are not double routines, although DOUBLE's "__*df" pattern matches them
    bad = sorted(n for n in _symbols(BOARD)
                 if (DOUBLE.match(n) and not re.match(r"^__ieee754_\w+f$", n))
                 or n in ("__aeabi_f2ulz", "__fixunssfdi"))
    assert not bad, f"{BOARD.name} links {bad}"
    text = BOARD.with_suffix(".map").read_text()
    for sym in ("__aeabi_dmul", "__aeabi_dsub", "__aeabi_d2uiz", "__aeabi_f2ulz"):
        assert re.search(rf"^{sym}\s", text, re.M) is None, f"map lists {sym}"


def test_vector_table_at_zero_and_fpu_enabled_first(built) -> None:
    """The reset vector points at the reset handler, whose first stores enable CP10/CP11."""
    nm = subprocess.run(["arm-none-eabi-nm", str(SELFTEST)], capture_output=True, text=True,
                        check=True).stdout
    syms = {ln.split()[-1]: int(ln.split()[0], 16) for ln in nm.splitlines()
            if len(ln.split()) == 3}
    assert syms["nte_vectors"] == 0
    assert syms["__stack_top"] >= 0x20000000
    dis = subprocess.run(["arm-none-eabi-objdump", "-d", "--disassemble=nte_reset_handler",
                          str(SELFTEST)], capture_output=True, text=True, check=True).stdout
    body = [ln for ln in dis.splitlines() if re.match(r"^\s+[0-9a-f]+:\t", ln)]
    mnemonics = [ln.split("\t")[2].split()[0] for ln in body[:8]]
    assert mnemonics[:6] == ["ldr", "ldr", "orr.w", "str", "dsb", "isb"], mnemonics


def test_generated_scenario_is_current() -> None:
    pytest.importorskip("numpy")
    r = subprocess.run([sys.executable, str(PORT / "gen_scenario.py"), "--check"], cwd=ROOT,
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


# ------------------------------------------------------------------ the node over SLCAN
def _free_port() -> int:
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class _Slcan:
    """A minimal SLCAN host on a TCP socket (what python-can's slcan interface writes; no
    pyserial needed): commands, 'tIIIL<data>\\r' frames out, received lines parsed."""

    def __init__(self, port: int, deadline_s: float = 10.0) -> None:
        import socket
        import time
        end = time.monotonic() + deadline_s
        while True:
            try:
                self.sock = socket.create_connection(("127.0.0.1", port), timeout=1.0)
                break
            except OSError:
                if time.monotonic() > end:
                    raise
                time.sleep(0.05)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.buf = b""
        self.lines: list[bytes] = []

    def write(self, data: bytes) -> None:
        self.sock.sendall(data)

    def pump(self, timeout: float) -> None:
        import socket
        self.sock.settimeout(timeout)
        try:
            chunk = self.sock.recv(65536)
        except socket.timeout:
            return
        if not chunk:
            raise ConnectionError("QEMU closed the serial socket")
        self.buf += chunk
        while True:
            cut = [i for i in (self.buf.find(b"\r"), self.buf.find(b"\a")) if i >= 0]
            if not cut:
                break
            i = min(cut)
            self.lines.append(self.buf[:i + 1])
            self.buf = self.buf[i + 1:]

    def frames(self):
        import can
        out = []
        for ln in self.lines:
            if ln.startswith(b"t") and ln.endswith(b"\r"):
                ident, dlc = int(ln[1:4], 16), int(ln[4:5])
                out.append(can.Message(arbitration_id=ident, is_extended_id=False,
                                       data=bytes.fromhex(ln[5:5 + 2 * dlc].decode())))
        return out

    def close(self) -> None:
        self.sock.close()


def _short_insertion_frames(tmp_path: Path, db) -> list:
    """The frames (E2E-protected, depth and force at 200 Hz) of a short paper insertion, 8 mm at
    the preset's speed with a 0.1 s dwell: the input both board-over-SLCAN tests replay."""
    sys.path.insert(0, str(ROOT))
    from host_bench.replay import scenario_frames
    csv = tmp_path / "s.csv"
    subprocess.run([sys.executable, "-m", "reference_py", "simulate", "--preset", "paper-10mms",
                    "--depth", "8", "--dwell", "0.1", "--seed", "1", "--out", str(csv)],
                   cwd=ROOT, check=True, stdout=subprocess.DEVNULL)
    return [m for _t, m in scenario_frames(str(csv), db, 200.0)]


def test_board_node_over_slcan_matches_mirror(built, tmp_path: Path) -> None:
    """nte-board.elf under QEMU, UART0 on a TCP socket: the SLCAN open sequence is answered
    with '\\r', and the node's Estimate/Params frames for a short paper insertion equal the
    Python node mirror's (host_bench/node_mirror.py) bit for bit."""
    import time
    can = pytest.importorskip("can")
    pytest.importorskip("numpy")
    sys.path.insert(0, str(ROOT))
    from reference_py.bus.dbc import NteDatabase
    from host_bench.node_mirror import NodeMirror
    from host_bench.node_outputs import compare, node_outputs

    db = NteDatabase()
    frames = _short_insertion_frames(tmp_path, db)
    heartbeat = b"t%03X" % db.frame_id("Heartbeat")

    port = _free_port()
    args = ["qemu-system-arm", "-M", "mps2-an386", "-cpu", "cortex-m4", "-display", "none",
            "-monitor", "none", "-serial",
            f"tcp:127.0.0.1:{port},server=on,wait=off,nodelay=on", "-kernel", str(BOARD)]
    log = tmp_path / "qemu.log"
    with open(log, "w") as qlog:
        qemu = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=qlog, stderr=qlog,
                                start_new_session=True)
    link = None
    try:
        try:
            link = _Slcan(port)
        except OSError as e:
            pytest.fail(f"cannot connect to QEMU's serial port ({e}); QEMU exit "
                        f"{qemu.poll()}:\n{log.read_text()[-4000:]}")
        # python-can's open sequence: C, S6, a bare CR, O twice -- five '\r' replies
        link.write(b"C\rS6\r\rO\rO\r")
        end = time.monotonic() + 10
        while len(link.lines) < 5 and time.monotonic() < end:
            link.pump(0.2)
        assert link.lines[:5] == [b"\r"] * 5, (link.lines, log.read_text()[-2000:])
        link.lines.clear()
        for m in frames:
            link.write(b"t%03X%d%s\r" % (m.arbitration_id, len(m.data),
                                         bytes(m.data).hex().upper().encode()))
            link.pump(0.0005)
        # until every frame the mirror publishes has come (heartbeats every 100 ms aside), then
        # 0.3 s more for any extra frame; not a quiet period: the link's pace depends on load
        mirror = NodeMirror()
        mirror.feed_all(frames)
        want = len(mirror.estimates) + len(mirror.params)
        hard_end = time.monotonic() + 120
        while time.monotonic() < hard_end:
            link.pump(0.1)
            if sum(1 for ln in link.lines if not ln.startswith(heartbeat)) >= want:
                break
        end = time.monotonic() + 0.3
        while time.monotonic() < end:
            link.pump(0.05)
        assert qemu.poll() is None, f"QEMU stopped:\n{log.read_text()[-4000:]}"
        assert b"\a" not in b"".join(link.lines), "the board answered BEL to a frame"
        out = link.frames()
        est, par, bad = node_outputs(db, out)
        res = compare(mirror, est, par)
        assert bad == 0
        forces = sum(1 for m in frames if m.arbitration_id == db.frame_id("Force"))
        assert res["estimates_node"] == res["estimates_reference"] == forces, res
        assert res["estimate_mismatches"] == 0, res
        assert res["params_node"] == res["params_reference"], res
        assert res["param_value_mismatches"] == 0 and res["param_std_mismatches"] == 0, res
        print(f"board node over SLCAN: {res['estimates_node']} estimates, "
              f"{res['params_node']} params frames, all equal to the mirror")
    finally:
        if link is not None:
            link.close()
        if qemu.poll() is None:
            qemu.terminate()
            try:
                qemu.wait(10)
            except subprocess.TimeoutExpired:
                qemu.kill()
                qemu.wait()


def test_board_over_python_can_slcan_matches_mirror(built, tmp_path: Path) -> None:
    """The board under QEMU driven through python-can's slcan interface (pyserial opens
    socket://127.0.0.1:PORT, what `nte-bench replay --interface slcan` uses): a paper insertion
    sent as fast as the link takes it, the node's frames received until every expected
    Estimate and Params frame is in (not for a fixed time: the link's pace depends on the
    machine's load; the node's results depend only on the frames' own timestamps), then
    compared with the node mirror: every estimate and parameter bit-identical."""
    import time
    can = pytest.importorskip("can")
    pytest.importorskip("serial")  # pyserial: python-can's slcan interface opens the URL with it
    pytest.importorskip("numpy")
    sys.path.insert(0, str(ROOT))
    from reference_py.bus.dbc import NteDatabase
    from host_bench.node_mirror import NodeMirror
    from host_bench.node_outputs import compare, node_outputs

    db = NteDatabase()
    frames = _short_insertion_frames(tmp_path, db)
    mirror = NodeMirror()
    mirror.feed_all(frames)
    want_est, want_par = len(mirror.estimates), len(mirror.params)
    assert want_est == sum(1 for m in frames if m.arbitration_id == db.frame_id("Force"))

    port = _free_port()
    args = ["qemu-system-arm", "-M", "mps2-an386", "-cpu", "cortex-m4", "-display", "none",
            "-monitor", "none", "-serial",
            f"tcp:127.0.0.1:{port},server=on,wait=off,nodelay=on", "-kernel", str(BOARD)]
    log = tmp_path / "qemu.log"
    with open(log, "w") as qlog:
        qemu = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=qlog, stderr=qlog,
                                start_new_session=True)
    bus = None
    try:
        _Slcan(port).close()  # QEMU listens
        bus = can.Bus(interface="slcan", channel=f"socket://127.0.0.1:{port}", bitrate=500000,
                      sleep_after_open=0)
        got: list = []
        for m in frames:
            bus.send(m)
            while (r := bus.recv(0)) is not None:
                got.append(r)
        deadline = time.monotonic() + 120
        est, par, bad = node_outputs(db, got)
        while (len(est) < want_est or len(par) < want_par) and time.monotonic() < deadline:
            r = bus.recv(0.5)
            if r is not None:
                got.append(r)
                est, par, bad = node_outputs(db, got)
        assert qemu.poll() is None, f"QEMU stopped:\n{log.read_text()[-4000:]}"
        res = compare(mirror, est, par)
        assert bad == 0, res
        assert res["estimates_node"] == res["estimates_reference"] == want_est, res
        assert res["estimate_mismatches"] == 0, res
        assert res["params_node"] == res["params_reference"] > 0, res
        assert res["param_value_mismatches"] == 0 and res["param_std_mismatches"] == 0, res
        print(f"board over python-can slcan: {want_est} estimates, {want_par} params frames, "
              "all equal to the mirror")
    finally:
        if bus is not None:
            bus.shutdown()
        if qemu.poll() is None:
            qemu.terminate()
            try:
                qemu.wait(10)
            except subprocess.TimeoutExpired:
                qemu.kill()
                qemu.wait()


def _hold_last_row(csv: Path, samples: int) -> None:
    """Extends the scenario's CSV to `samples` rows as the self-test does past its end: the
    last row held, the time going on by the last interval (selftest.c scenario_sample)."""
    head, *rows = csv.read_text().splitlines()
    t_us = [math.floor(float(r.split(",")[0]) * 1e6 + 0.5) for r in rows[-2:]]
    rest = rows[-1].split(",")[1:]
    for j in range(1, samples - len(rows) + 1):
        rows.append(",".join([f"{(t_us[1] + j * (t_us[1] - t_us[0])) / 1e6:.6f}", *rest]))
    csv.write_text("\n".join([head, *rows]) + "\n")


@pytest.mark.parametrize("run,args", [
    (0, ["--model", "1"]),
    (1, ["--model", "2", "--schedule", "rotate"]),
    (2, ["--model", "2", "--estimator", "robust"]),
    (3, ["--model", "2", "--schedule", "all"]),
], ids=["model1-bank-all", "model2-bank-rotate", "model2-robust", "model2-bank-all"])
def test_selftest_equals_float32_reference(host_lines, tmp_path: Path, run: int,
                                           args: list[str]) -> None:
    """The self-test's lines (= the board's, bit for bit) equal `nte-ref estimate --precision
    float32` on the scenario gen_scenario.py was generated from: every output, every bit."""
    np = pytest.importorskip("numpy")
    csv = tmp_path / "s.csv"
    est = tmp_path / "e.csv"
    subprocess.run([sys.executable, "-m", "reference_py", "simulate", "--preset", "paper-10mms",
                    "--depth", "8", "--dwell", "0.1", "--rate", "200", "--noise", "0.002",
                    "--seed", "1", "--out", str(csv)], cwd=ROOT, check=True,
                   stdout=subprocess.DEVNULL)
    mine = [ln.split() for ln in host_lines if ln.startswith(f"S {run} ")]
    _hold_last_row(csv, len(mine))
    subprocess.run([sys.executable, "-m", "reference_py", "estimate", str(csv),
                    "--precision", "float32", *args, "--out", str(est)], cwd=ROOT, check=True,
                   stdout=subprocess.DEVNULL)
    ref_rows = [r.split(",") for r in est.read_text().splitlines()[1:]]
    assert len(mine) == len(ref_rows)

    def bits(x: str) -> str:
        return "%08x" % int(np.array([float(x)], dtype=np.float32).view(np.uint32)[0])

    robust = "robust" in args
    for k, (m, r) in enumerate(zip(mine, ref_rows)):
        # S run k force z innov nis status confidence n {id value sd}
        n = int(m[9])
        got = [m[3], m[4], m[5], "%d" % int(m[7], 16)]
        want = [bits(r[1]), bits(r[2]), bits(r[3]), r[4]]
        for j in range(n):
            got += [m[11 + 3 * j], m[12 + 3 * j]]
            want += [bits(r[5 + 2 * j]), bits(r[6 + 2 * j])]
        if robust:
            got.append(m[8])
            want.append(bits(r[5 + 2 * n]))
        assert got == want, f"run {run} sample {k}:\n  C   {got}\n  ref {want}"


# ------------------------------------------------------------------ the cycle model
def _cycles():
    import importlib.util
    spec = importlib.util.spec_from_file_location("nte_board_cycles", PORT / "cycles.py")
    mod = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    spec.loader.exec_module(mod)
    return mod


# Upper-bound cycles measured by cycles.py on this image (arm-none-eabi-gcc 12.2 -O2 -flto, the
# library with -fno-inline-functions; QEMU 7.2): the model is deterministic, so a step that gets
# more than 5 % slower fails here
# (update the figure, and the README's table, when a change is meant to cost cycles).
MEASURED_WORST_HI = {
    "Model I bank, all": 9_349,
    "Model II bank, all": 8_434,
    "Model II bank, rotate": 7_453,
    "Model II robust, normal sample": 10_844,
    # the worst of the refinement's 1 710 slices (one buffer entry each, on a normal step;
    # 385 410 with slices of 96 entries, one simulation of the buffer each)
    "Model II robust, refinement": 17_521,
    # Model III (direction memory with its identified turn-over length, two relaxation
    # branches, the step bound): 1.37 x Model II's bank, all
    "Model III bank, all": 11_569,
}
#: issue 21's budget: Model III's bank costs at most this many times Model II's (worst steps)
MODEL3_OVER_MODEL2_MAX = 1.5
CYCLE_TOLERANCE = 1.05
#: the whole refinement of one insertion, CPU seconds at 168 MHz (upper-bound cycles)
REFINEMENT_BUDGET_S = 0.050


@pytest.fixture(scope="module")
def cycle_model(built) -> dict:
    return _cycles().model(SELFTEST)


def test_cycle_model_covers_every_configuration(cycle_model) -> None:
    assert set(cycle_model) == set(MEASURED_WORST_HI), sorted(cycle_model)
    for label, s in cycle_model.items():
        assert 0 < s["median_lo"] <= s["median_hi"] <= s["worst_hi"], (label, s)
        assert s["worst_lo"] <= s["worst_hi"] <= 2 * s["worst_lo"], (label, s)
        # at least one cycle per instruction (the IT instruction aside)
        assert s["worst_hi"] >= s["worst_insns"], (label, s)
    n_samples = _scenario_len()
    robust = [s["steps"] for label, s in cycle_model.items() if "robust" in label]
    # the robust run goes on at the surface until its refinement is adopted (selftest.h)
    assert cycle_model["Model II robust, refinement"]["steps"] == _default_slices()
    assert n_samples < sum(robust) <= n_samples + _default_slices()
    assert all(s["steps"] == n_samples for label, s in cycle_model.items()
               if "robust" not in label)


@pytest.mark.parametrize("label", sorted(MEASURED_WORST_HI))
def test_cycles_per_step_within_measured_bound(cycle_model, label: str) -> None:
    """The worst step's upper-bound cycles stay within 5 % of the figure measured today."""
    got = cycle_model[label]["worst_hi"]
    bound = MEASURED_WORST_HI[label] * CYCLE_TOLERANCE
    assert got <= bound, f"{label}: worst step {got} cycles > {bound:.0f} (measured " \
                         f"{MEASURED_WORST_HI[label]} x {CYCLE_TOLERANCE})"


def test_model3_bank_within_its_budget_of_model2(cycle_model) -> None:
    """Model III's bank, every filter every sample, costs at most 1.5 x Model II's (worst
    steps' upper bounds, the same image and scenario: a ratio no machine changes)."""
    m3 = cycle_model["Model III bank, all"]["worst_hi"]
    m2 = cycle_model["Model II bank, all"]["worst_hi"]
    assert m3 <= MODEL3_OVER_MODEL2_MAX * m2, \
        f"Model III {m3} cycles = {m3 / m2:.3f} x Model II's {m2} (budget {MODEL3_OVER_MODEL2_MAX})"


def test_refinement_within_cpu_budget(cycle_model) -> None:
    """The robust estimator's refinement of one insertion costs at most 50 ms of CPU on a
    168 MHz Cortex-M4F: upper-bound cycles of every step that ran a slice, less a normal
    sample's step each (the normal samples' median: the bank's work, done anyway)."""
    s = cycle_model["Model II robust, refinement"]
    normal = cycle_model["Model II robust, normal sample"]["median_hi"]
    own = s["total_hi"] - s["steps"] * normal
    assert 0 < own < s["total_hi"]
    seconds = own / _cycles().CPU_HZ
    assert seconds <= REFINEMENT_BUDGET_S, f"refinement {seconds * 1e3:.1f} ms > " \
                                            f"{REFINEMENT_BUDGET_S * 1e3:.0f} ms"


#: issue 24's real-time targets (upper-bound cycles of the cycle model): no nte_step above
#: this, in any configuration ...
STEP_CYCLES_MAX = 20_000
#: ... and Model II's bank, every filter every sample, at most this per step
MODEL2_BANK_CYCLES_MAX = 5_000


#: one sample period at 200 Hz on a 168 MHz part, cycles
SAMPLE_PERIOD_CYCLES = 840_000


def test_no_step_blocks_a_sample_period(cycle_model) -> None:
    """Every configuration's worst step (upper bound) within one sample period at 200 Hz: the
    refinement is sliced across samples (it took 6.97 M cycles, 8.3 periods, in one step)."""
    worst = {label: s["worst_hi"] for label, s in cycle_model.items()}
    assert max(worst.values()) <= SAMPLE_PERIOD_CYCLES, worst
    assert cycle_model["Model II robust, refinement"]["steps"] > 1


def test_every_bank_step_within_the_real_time_budget(cycle_model) -> None:
    """The banks (every model and schedule, without the robust estimator) hold STEP_CYCLES_MAX
    already: Model III's worst step 11 581 upper-bound cycles (24 394 before the covariance
    prediction used the transition's shape and the Joseph update's sums were written out)."""
    banks = {label: s["worst_hi"] for label, s in cycle_model.items() if "bank" in label}
    assert len(banks) == 4, sorted(banks)
    assert max(banks.values()) <= STEP_CYCLES_MAX, banks


def test_cycles_by_function_add_up(cycle_model) -> None:
    """cycles.py --functions charges every counted instruction to one function: the shares add
    up to the step's cycles exactly, and the kernels the README names are among them."""
    for label, s in cycle_model.items():
        assert sum(s["worst_by_function"].values()) == s["worst_hi"], label
        assert sum(s["worst_by_class"].values()) == s["worst_hi"], label
        top = sorted(s["worst_by_function"], key=s["worst_by_function"].get, reverse=True)[:6]
        assert "nte_model_rk3" in top and "nte_exp" in top, (label, top)
        if "bank" in label:
            assert "nte_ekf_joseph_update" in top, (label, top)


def test_no_step_above_its_real_time_budget(cycle_model) -> None:
    """Every configuration's worst step (upper bound) within STEP_CYCLES_MAX, the refinement's
    slices included (one buffer entry a sample by default: 17 533 cycles; a slice of 96
    entries took 0.39 M): a 1 kHz loop on a 168 MHz part keeps 88 % of its period."""
    worst = {label: s["worst_hi"] for label, s in cycle_model.items()}
    assert max(worst.values()) <= STEP_CYCLES_MAX, worst


@pytest.mark.xfail(strict=True, reason="measured: Model II bank, all filters, 8 446 cycles "
                   "(worst step, upper bound; 14 161 before the Joseph update was written out "
                   "per state count): loads/stores and branches still dominate (issue 24)")
def test_model2_bank_within_its_arithmetic_budget(cycle_model) -> None:
    """Model II's bank, every filter every sample, within MODEL2_BANK_CYCLES_MAX per step."""
    assert cycle_model["Model II bank, all"]["worst_hi"] <= MODEL2_BANK_CYCLES_MAX


@pytest.mark.parametrize("mnemonic,operands,lo,hi", [
    ("vmla.f32", "s0, s1, s2", 3, 3),
    ("vdiv.f32", "s0, s1, s2", 14, 14),
    ("vadd.f32", "s0, s1, s2", 1, 1),
    ("bls.n", "1f0 <x>", 2, 4),           # b + ls, not bl + s
    ("pop", "{r4, r5, r6, pc}", 1 + 4 + 1, 1 + 4 + 3),
    ("vpush", "{d8-d9}", 5, 5),           # two d registers = four words
    ("ldr.w", "pc, [sp], #4", 3, 5),
    ("mvnsne", "r0, r1", 1, 1),
    ("itte", "eq", 0, 1),
    ("udiv", "r0, r1, r2", 2, 12),
])
def test_cycle_table_entries(mnemonic: str, operands: str, lo: int, hi: int) -> None:
    ins = _cycles().Insn(0, 4, mnemonic, operands)
    assert (ins.lo, ins.hi) == (lo, hi)
