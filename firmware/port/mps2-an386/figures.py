#!/usr/bin/env python3
"""Figures of the board image (MPS2 AN386, Cortex-M4F): flash and RAM, sizeof(nte_t), the
worst-case stack from the compiler's call graph (-fstack-usage + -fcallgraph-info=su) and the
measured high-water mark of the painted stack after the self-test under QEMU.  Instructions and
cycles per nte_step: cycles.py beside this file.

    python3 firmware/port/mps2-an386/figures.py [--build build/m4]

Needs the cross build (`make board`, i.e. cmake -S . -B build/m4
-DCMAKE_TOOLCHAIN_FILE=cmake/arm-none-eabi.cmake && cmake --build build/m4) and
qemu-system-arm.
"""
from __future__ import annotations

import argparse
import pathlib
import re
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[3]
QEMU = ["qemu-system-arm", "-M", "mps2-an386", "-cpu", "cortex-m4", "-display", "none",
        "-monitor", "none", "-serial", "null", "-semihosting-config", "enable=on,target=native"]


def size(elf: pathlib.Path) -> dict[str, int]:
    out = subprocess.run(["arm-none-eabi-size", "-A", str(elf)], capture_output=True,
                         text=True, check=True).stdout
    sec = {}
    for ln in out.splitlines():
        f = ln.split()
        if len(f) == 3 and f[1].isdigit():
            sec[f[0]] = int(f[1])
    return sec


def size_berkeley(elf: pathlib.Path) -> tuple[int, int, int]:
    """(text, data, bss) as `arm-none-eabi-size` prints them (bss includes the stack region)."""
    out = subprocess.run(["arm-none-eabi-size", str(elf)], capture_output=True, text=True,
                         check=True).stdout.splitlines()
    text, data, bss = (int(x) for x in out[1].split()[:3])
    return text, data, bss


def symbols(elf: pathlib.Path) -> dict[str, int]:
    out = subprocess.run(["arm-none-eabi-nm", str(elf)], capture_output=True, text=True,
                         check=True).stdout
    return {f[2]: int(f[0], 16) for f in (ln.split() for ln in out.splitlines()) if len(f) == 3}


# object directories of each image, and the targets of its calls through pointers
IMAGES = {
    "nte-selftest": (["nte-selftest.elf.dir", "nte_selftest.dir", "nte_board.dir", "nte_f32.dir"],
                     ["emit_semihost", "mark"]),
    "nte-board": (["nte-board.elf.dir", "nte_board.dir", "nte_node.dir", "nte_can.dir",
                   "nte_f32.dir"], ["nte_slcan_receive", "nte_slcan_send", "port_now_us"]),
}


def graph_files(build: pathlib.Path, name: str, dirs: list[str]) -> list[pathlib.Path]:
    """The call graphs of one image: the link's, bin/<name>.elf.ltrans*.ci (the code
    link-time optimisation generated), and those of its objects compiled without -flto.  An
    object that holds link-time bytecode (.gnu.lto_ sections) generated no code of its own,
    so a .ci beside it is left from an earlier build (the link's graph covers it)."""
    files = sorted((build / "bin").glob(f"{name}.elf.ltrans*.ci"))
    for ci in sorted(build.rglob("*.ci")):
        if not any(part in dirs for part in ci.relative_to(build).parts):
            continue
        obj = ci.with_suffix(".obj")
        if obj.exists() and b".gnu.lto_" in obj.read_bytes():
            continue
        files.append(ci)
    return files


def call_graph(build: pathlib.Path, name: str, dirs: list[str], indirect: list[str]
               ) -> tuple[dict[str, int], dict[str, set[str]]]:
    frame: dict[str, int] = {}
    calls: dict[str, set[str]] = {}
    node_re = re.compile(r'node: \{ title: "([^"]+)" label: "[^"]*?\\n[^"]*?\\n(\d+) bytes')
    edge_re = re.compile(r'edge: \{ sourcename: "([^"]+)" targetname: "([^"]+)"')
    for ci in graph_files(build, name, dirs):
        text = ci.read_text()
        for fn, nbytes in node_re.findall(text):
            frame[fn] = max(frame.get(fn, 0), int(nbytes))
        for src, dst in edge_re.findall(text):
            calls.setdefault(src, set()).add(dst)
    # calls through pointers: every known target (static functions carry "file:" prefixes,
    # those link-time optimisation made local "<image>.elf.ltrans0.o:")
    calls["__indirect_call"] = {f for f in frame if f.split(":")[-1] in indirect}
    return frame, calls


def worst_path(root: str, frame: dict[str, int], calls: dict[str, set[str]]
               ) -> tuple[int, list[str], set[str]]:
    memo: dict[str, tuple[int, list[str]]] = {}
    unknown: set[str] = set()

    def go(fn: str, seen: frozenset[str]) -> tuple[int, list[str]]:
        if fn in memo:
            return memo[fn]
        if fn in seen:
            raise RuntimeError(f"recursion through {fn}")
        if fn not in frame:
            unknown.add(fn)
        best = (0, [])
        for callee in calls.get(fn, ()):
            cand = go(callee, seen | {fn})
            if cand[0] > best[0]:
                best = cand
        res = (frame.get(fn, 0) + best[0], [fn] + best[1])
        memo[fn] = res
        return res

    total, path = go(root, frozenset())
    return total, path, unknown


def run_selftest(elf: pathlib.Path) -> dict[str, int]:
    r = subprocess.run(QEMU + ["-kernel", str(elf)], capture_output=True, text=True,
                       timeout=300, stdin=subprocess.DEVNULL)
    if r.returncode != 0:
        sys.exit(f"self-test failed under QEMU ({r.returncode}):\n{r.stderr[-2000:]}")
    m = re.search(r"^F stack_used=(\d+) stack_size=(\d+) sizeof_nte_t=(\d+)$", r.stderr, re.M)
    if m is None:
        sys.exit("no F line in the self-test output")
    steps = {}
    for ln in r.stderr.splitlines():
        if ln.startswith("R "):
            steps[ln.split()[1]] = ln
    return {"stack_used": int(m.group(1)), "stack_size": int(m.group(2)),
            "sizeof_nte_t": int(m.group(3)), "runs": steps}  # type: ignore[dict-item]


#: an exception entry pushes 26 words with the FPU context (lazy stacking reserves the space)
EXCEPTION_FRAME_B = 104
#: the stack region must exceed the worst case by this factor (mps2.ld states the rule)
STACK_MARGIN = 1.2
HANDLERS = ("nte_systick_handler", "nte_fault_handler")


def image_figures(build: pathlib.Path, name: str) -> dict:
    """Flash and RAM as arm-none-eabi-size counts them (flash = text + data, RAM = data + bss,
    where bss includes the NOLOAD stack region), and the worst-case stack from the call graph:
    the deepest path from main + one exception frame + the deepest handler."""
    elf = build / "bin" / f"{name}.elf"
    sec = size(elf)
    b_text, b_data, b_bss = size_berkeley(elf)
    sym = symbols(elf)
    frame, calls = call_graph(build, name, *IMAGES[name])
    main_b, path, unknown = worst_path("main", frame, calls)
    handler_b = max(worst_path(h, frame, calls)[0] for h in HANDLERS)
    text = sec.get(".text", 0) + sec.get(".ARM.exidx", 0)
    data = sec.get(".data", 0)
    bss = sec.get(".bss", 0)
    stack = sym["__stack_top"] - sym["__stack_bottom"]
    return {"flash": b_text + b_data, "text": text, "data": data, "bss": bss, "stack": stack,
            "ram": b_data + b_bss, "main_stack": main_b, "handler_stack": handler_b,
            "path": [f.split(":")[-1] for f in path],
            "not_counted": sorted(u for u in unknown if u != "__indirect_call")}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--build", default=str(ROOT / "build" / "m4"))
    a = ap.parse_args()
    build = pathlib.Path(a.build)
    bindir = build / "bin"
    print("# Board image figures (mps2-an386, Cortex-M4F, arm-none-eabi-gcc -flto: -O2 on the step "
          "path, -Os for the node, CAN layer, board support and the configuration check; "
          "newlib-nano)")
    for name in ("nte-selftest", "nte-board"):
        f = image_figures(build, name)
        print(f"{name}.elf (arm-none-eabi-size): flash {f['flash']} B (text {f['text']}, "
              f"data {f['data']}); RAM {f['ram']} B (data {f['data']}, bss {f['bss']}, "
              f"stack {f['stack']})")
        worst = f["main_stack"] + EXCEPTION_FRAME_B + f["handler_stack"]
        print(f"  worst-case stack {worst} B = {f['main_stack']} B from main (-fstack-usage "
              f"call graph) + {EXCEPTION_FRAME_B} B exception frame + {f['handler_stack']} B "
              f"deepest handler; stack region {f['stack']} B "
              f"({100.0 * (f['stack'] / worst - 1.0):.0f} % margin)")
        print(f"    path: {' > '.join(f['path'])}")
        print(f"    not counted: library functions without stack data "
              f"({', '.join(f['not_counted'])}); calls through pointers counted as any of "
              f"{', '.join(IMAGES[name][1])}")
    st = run_selftest(bindir / "nte-selftest.elf")
    print(f"sizeof(nte_t) on the M4: {st['sizeof_nte_t']} B (NTE_ROBUST_BUFFER_LEN default)")
    print(f"painted-stack high-water mark after the self-test (5 runs, incl. one robust "
          f"refinement): {st['stack_used']} B of {st['stack_size']} B")
    return 0


if __name__ == "__main__":
    sys.exit(main())
