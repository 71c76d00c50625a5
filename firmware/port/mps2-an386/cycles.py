#!/usr/bin/env python3
"""Cycle model of nte_step on the Cortex-M4F: the self-test image (nte-selftest.elf) runs
under QEMU, which logs every translated block (-d in_asm) and every block it executes
(-d exec,nochain); each step (between the marker functions nte_mark_step_begin/end) becomes an
exact instruction mix, branches taken or not, which the Cortex-M4 timing table below turns into
a lower-upper cycle range.  Prints cycles per step and the CPU load at 200 Hz on a 168 MHz
part for each configuration of the self-test (Model I bank; Model II bank, every filter every
sample and rotating; the robust estimator's normal samples and its refinement; Model III bank).

    python3 firmware/port/mps2-an386/cycles.py [--build build/m4] [--json FILE] [--functions N]

--functions N also prints, for each configuration's worst step, the N functions that take most
of its cycles: each executed instruction is charged to the function whose symbol holds it
(what the step path inlines is charged to the function it was inlined into).

Deterministic: the same image gives the same figures on every run.  Needs the cross build
(`make board`) and qemu-system-arm.  About 15 s.

Timing (Cortex-M4 TRM, instruction set summary and FPU instruction timings; P = pipeline
refill after a taken branch, 1 to 3 cycles; N = registers/words transferred):
  integer data processing, MOV, CMP, shifts, extends, MUL, UMULL/SMULL, CLZ     1
  MLA, MLS                                                                      2
  SDIV, UDIV                                                                    2..12
  LDR/STR (byte, half, word)     2, 1 when it follows another single load/store (pipelined)
  LDRD, STRD                                                                    3
  LDM, STM, PUSH, POP                                                           1+N (+P to PC)
  B, BL, BX, BLX, CBZ/CBNZ/B<cond> taken, TBB/TBH                               1+P (TBB 2+P)
  B<cond>, CBZ, CBNZ not taken                                                  1
  IT                                                                            0..1
  VADD, VSUB, VMUL, VNMUL, VABS, VNEG, VCMP, VCVT, VMOV, VMRS, VMSR             1
  VMLA, VMLS, VNMLA, VNMLS, VFMA, VFMS                                          3
  VDIV, VSQRT                                                                   14
  VLDR, VSTR                                                                    2
  VLDM, VSTM, VPUSH, VPOP                                                       1+N (words)
Not modelled: flash wait states (a 168 MHz part runs its flash with 5 wait states behind a
prefetch/cache accelerator), FPU result-use stalls, write-buffer stalls; instructions that
fail their IT condition are counted as if executed.
"""
from __future__ import annotations

import argparse
import json
import pathlib
import re
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parents[3]
QEMU = ["qemu-system-arm", "-M", "mps2-an386", "-cpu", "cortex-m4", "-display", "none",
        "-monitor", "none", "-serial", "null", "-semihosting-config", "enable=on,target=native"]
CPU_HZ = 168e6
RATE_HZ = 200.0
#: harness functions inside the marked window that are not part of nte_step's cost
HARNESS = ("mark", "one_run", "nte_mark_step_begin", "nte_mark_step_end")
#: the status bit of a step that ran a slice of the refinement (nte.h NTE_STATUS_REFINING)
STATUS_REFINING = 1 << 15

CONDS = ("eq", "ne", "cs", "hs", "cc", "lo", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt",
         "gt", "le", "al")

# class: (lower, upper) cycles, before the operand-dependent rules in cost()
ALU = ("add", "addw", "adc", "sub", "subw", "sbc", "rsb", "neg", "mov", "movw", "movt", "mvn",
       "and", "orr", "orn", "eor", "bic", "lsl", "lsr", "asr", "ror", "rrx", "cmp", "cmn", "tst",
       "teq", "ubfx", "sbfx", "bfi", "bfc", "uxtb", "uxth", "sxtb", "sxth", "rev", "rev16",
       "revsh", "rbit", "clz", "adr", "mul", "umull", "smull", "umlal", "smlal", "smlabb",
       "smulbb", "nop", "dsb", "dmb", "isb", "usat", "ssat")
TABLE: dict[str, tuple[str, int, int]] = {}
for _m in ALU:
    TABLE[_m] = ("int", 1, 1)
TABLE.update({
    "mla": ("int", 2, 2), "mls": ("int", 2, 2),
    "sdiv": ("div", 2, 12), "udiv": ("div", 2, 12),
    "ldr": ("mem", 2, 2), "ldrb": ("mem", 2, 2), "ldrh": ("mem", 2, 2), "ldrsb": ("mem", 2, 2),
    "ldrsh": ("mem", 2, 2), "str": ("mem", 2, 2), "strb": ("mem", 2, 2), "strh": ("mem", 2, 2),
    "ldrd": ("mem", 3, 3), "strd": ("mem", 3, 3),
    "ldm": ("mem", 1, 1), "ldmia": ("mem", 1, 1), "ldmdb": ("mem", 1, 1), "stm": ("mem", 1, 1),
    "stmia": ("mem", 1, 1), "stmdb": ("mem", 1, 1), "push": ("mem", 1, 1), "pop": ("mem", 1, 1),
    "b": ("branch", 2, 4), "bl": ("branch", 2, 4), "bx": ("branch", 2, 4),
    "blx": ("branch", 2, 4), "cbz": ("branch", 2, 4), "cbnz": ("branch", 2, 4),
    "tbb": ("branch", 3, 5), "tbh": ("branch", 3, 5),
    "it": ("int", 0, 1),
    "vadd": ("fpu", 1, 1), "vsub": ("fpu", 1, 1), "vmul": ("fpu", 1, 1), "vnmul": ("fpu", 1, 1),
    "vabs": ("fpu", 1, 1), "vneg": ("fpu", 1, 1), "vcmp": ("fpu", 1, 1), "vcmpe": ("fpu", 1, 1),
    "vcvt": ("fpu", 1, 1), "vcvtr": ("fpu", 1, 1), "vmov": ("fpmove", 1, 1),
    "vmrs": ("fpmove", 1, 1), "vmsr": ("fpmove", 1, 1),
    "vmla": ("fpu", 3, 3), "vmls": ("fpu", 3, 3), "vnmla": ("fpu", 3, 3), "vnmls": ("fpu", 3, 3),
    "vfma": ("fpu", 3, 3), "vfms": ("fpu", 3, 3), "vfnma": ("fpu", 3, 3), "vfnms": ("fpu", 3, 3),
    "vdiv": ("fdiv", 14, 14), "vsqrt": ("fdiv", 14, 14),
    "vldr": ("fpmem", 2, 2), "vstr": ("fpmem", 2, 2),
    "vldmia": ("fpmem", 1, 1), "vldmdb": ("fpmem", 1, 1), "vstmia": ("fpmem", 1, 1),
    "vstmdb": ("fpmem", 1, 1), "vpush": ("fpmem", 1, 1), "vpop": ("fpmem", 1, 1),
})
BASES = sorted(TABLE, key=len, reverse=True)
SINGLE_MEM = ("ldr", "ldrb", "ldrh", "ldrsb", "ldrsh", "str", "strb", "strh")
MULTI = ("ldm", "ldmia", "ldmdb", "stm", "stmia", "stmdb", "push", "pop", "vldmia", "vldmdb",
         "vstmia", "vstmdb", "vpush", "vpop")
CONDITIONAL_BRANCH = ("cbz", "cbnz")


def parse_mnemonic(raw: str) -> tuple[str, bool]:
    """Base mnemonic (condition, flag-setting 's' and width/type suffixes removed) and whether
    the instruction is conditional (a B<cond>, or an instruction inside an IT block)."""
    m = raw.split(".")[0]
    if re.fullmatch(r"it[te]{0,3}", m):
        return "it", False
    for base in BASES:
        if not m.startswith(base):
            continue
        rest = m[len(base):]
        branch = TABLE[base][0] == "branch"
        if rest == "":
            return base, False
        if rest in CONDS:
            return base, True
        if not branch and rest == "s":
            return base, False
        if not branch and rest[:1] == "s" and rest[1:] in CONDS:
            return base, True
    raise KeyError(raw)


def reg_words(operands: str) -> int:
    """Words a register list {…} transfers (a d register is two)."""
    body = operands[operands.index("{") + 1:operands.index("}")]
    words = 0
    for item in body.split(","):
        item = item.strip()
        lo, _, hi = item.partition("-")
        n = int(hi[1:]) - int(lo[1:]) + 1 if hi else 1
        words += 2 * n if lo.startswith("d") else n
    return words


class Insn:
    __slots__ = ("pc", "size", "base", "cls", "lo", "hi", "branch", "cond", "to_pc")

    def __init__(self, pc: int, size: int, raw: str, operands: str) -> None:
        self.pc, self.size = pc, size
        self.base, self.cond = parse_mnemonic(raw)
        self.cls, self.lo, self.hi = TABLE[self.base]
        ops = operands.replace(" ", "")
        self.to_pc = False
        if self.base in MULTI:
            n = reg_words(operands)
            self.lo, self.hi = 1 + n, 1 + n
            self.to_pc = "pc" in ops[ops.index("{"):ops.index("}")]
        elif self.base in ("ldr",) and ops.startswith("pc,"):
            self.to_pc = True
        elif self.base == "mov" and ops.startswith("pc,"):
            self.to_pc = True
        elif self.base in ("vldr", "vstr") and ops.startswith("d"):
            self.lo, self.hi = 3, 3
        elif self.base == "vmov" and ops.count(",") >= 2:
            self.lo, self.hi = 1, 2  # two core registers to/from the FPU
        if self.to_pc:  # a load to PC is a branch: + P
            self.cls = "branch"
            self.lo, self.hi = self.lo + 1, self.hi + 3
        self.branch = TABLE[self.base][0] == "branch" or self.to_pc


def disassemble(elf: pathlib.Path) -> tuple[dict[int, Insn], dict[str, tuple[int, int]]]:
    out = subprocess.run(["arm-none-eabi-objdump", "-d", "--no-show-raw-insn", str(elf)],
                         capture_output=True, text=True, check=True).stdout
    raw = subprocess.run(["arm-none-eabi-objdump", "-d", str(elf)], capture_output=True,
                         text=True, check=True).stdout
    sizes: dict[int, int] = {}
    for ln in raw.splitlines():
        m = re.match(r"^\s+([0-9a-f]+):\t([0-9a-f]{4})( [0-9a-f]{4})?\s*\t", ln)
        if m:
            sizes[int(m.group(1), 16)] = 4 if m.group(3) else 2
    insns: dict[int, Insn] = {}
    funcs: dict[str, tuple[int, int]] = {}
    current = None
    for ln in out.splitlines():
        h = re.match(r"^([0-9a-f]{8}) <(.+)>:$", ln)
        if h:
            current = h.group(2)
            funcs[current] = (int(h.group(1), 16), int(h.group(1), 16))
            continue
        m = re.match(r"^\s+([0-9a-f]+):\t(\S+)\s*(.*)$", ln)
        if not m or current is None:
            continue
        pc = int(m.group(1), 16)
        if pc not in sizes or m.group(2).startswith("."):
            continue  # literal pool data
        ops = m.group(3).split(";")[0].strip()
        try:
            insns[pc] = Insn(pc, sizes[pc], m.group(2), ops)
        except KeyError:
            insns[pc] = None  # type: ignore[assignment]  # unknown: an error if executed
        funcs[current] = (funcs[current][0], pc + sizes[pc])
    return insns, funcs


def symbol(elf: pathlib.Path, name: str) -> int:
    out = subprocess.run(["arm-none-eabi-nm", str(elf)], capture_output=True, text=True,
                         check=True).stdout
    for ln in out.splitlines():
        f = ln.split()
        if len(f) == 3 and f[2] == name:
            return int(f[0], 16) & ~1
    raise KeyError(name)


def trace_steps(elf: pathlib.Path) -> tuple[list[dict[tuple[int, int], int]], dict[int, tuple],
                                            str]:
    """Runs the self-test under QEMU; returns per step the executed blocks as
    {(block start pc, exit kind): count} (exit kind 1: the block's last instruction branched,
    0: it fell through), the blocks' instruction addresses, and the self-test's output."""
    begin, end = symbol(elf, "nte_mark_step_begin"), symbol(elf, "nte_mark_step_end")
    with tempfile.TemporaryFile() as err:
        p = subprocess.Popen(QEMU + ["-d", "in_asm,exec,nochain", "-D", "/dev/stdout",
                                     "-kernel", str(elf)], stdout=subprocess.PIPE, stderr=err,
                             stdin=subprocess.DEVNULL)
        blocks: dict[int, tuple] = {}
        steps: list[dict[tuple[int, int], int]] = []
        cur: dict[tuple[int, int], int] | None = None
        prev = -1  # the block executed before, whose exit the next block tells
        collecting: list[int] | None = None
        trace_re = re.compile(rb"^Trace \d+: 0x[0-9a-f]+ \[[0-9a-f]+/([0-9a-f]+)/")
        addr_re = re.compile(rb"^0x([0-9a-f]{8}):")
        assert p.stdout is not None
        try:
            for ln in p.stdout:
                if collecting is not None:
                    m = addr_re.match(ln)
                    if m:
                        collecting.append(int(m.group(1), 16))
                        continue
                    if collecting:
                        blocks[collecting[0]] = tuple(collecting)
                    collecting = None
                if ln.startswith(b"IN:"):
                    collecting = []
                    continue
                m = trace_re.match(ln)
                if m is None:
                    continue
                pc = int(m.group(1), 16)
                if cur is not None and prev >= 0:
                    last = blocks[prev][-1]
                    taken = 0 if pc == last + SIZE.get(last, 0) else 1
                    key = (prev, taken)
                    cur[key] = cur.get(key, 0) + 1
                prev = -1
                if pc == begin:
                    cur = {}
                elif pc == end:
                    if cur is not None:
                        steps.append(cur)
                    cur = None
                elif cur is not None:
                    prev = pc
        finally:
            if p.poll() is None:
                p.kill()
            p.wait()
        err.seek(0)
        output = err.read().decode()
    if p.returncode != 0:
        sys.exit(f"cycles: the self-test failed under QEMU (status {p.returncode})")
    return steps, blocks, output


SIZE: dict[int, int] = {}


def block_cost(pcs: tuple, taken: int, insns: dict[int, Insn], harness: set[int],
               owner: dict[int, str]) -> tuple[int, int, int, dict[str, int], dict[str, int]]:
    """(instructions, lower, upper cycles, upper cycles per class, upper cycles per function)
    of one execution."""
    n = lo = hi = 0
    by: dict[str, int] = {}
    fn: dict[str, int] = {}
    prev_single = False
    for i, pc in enumerate(pcs):
        if pc in harness:
            return 0, 0, 0, {}, {}
        ins = insns.get(pc)
        if ins is None:
            raise KeyError(f"no timing for the instruction at {pc:#x}")
        a, b = ins.lo, ins.hi
        if ins.base in SINGLE_MEM and not ins.to_pc and prev_single:
            a = 1
        prev_single = ins.base in SINGLE_MEM and not ins.to_pc
        if i == len(pcs) - 1 and ins.branch and not taken:
            a, b = 1, 1  # a conditional branch that fell through
        n += 1
        lo += a
        hi += b
        by[ins.cls] = by.get(ins.cls, 0) + b
        fn[owner[pc]] = fn.get(owner[pc], 0) + b
    return n, lo, hi, by, fn


def model(elf: pathlib.Path) -> dict:
    insns, funcs = disassemble(elf)
    SIZE.clear()
    SIZE.update({pc: i.size for pc, i in insns.items() if i is not None})
    harness = {pc for name in HARNESS if name in funcs
               for pc in range(funcs[name][0], funcs[name][1])}
    # the function each instruction belongs to (objdump's symbol; GCC's clones such as
    # nte_ekf_predict.constprop.0 are their own rows)
    owner = {pc: name for name, (a, b) in funcs.items() for pc in range(a, b)}
    steps, blocks, output = trace_steps(elf)
    cache: dict[tuple[int, int], tuple] = {}
    per_step = []
    for st in steps:
        n = lo = hi = 0
        by: dict[str, int] = {}
        fn: dict[str, int] = {}
        for key, count in st.items():
            if key not in cache:
                cache[key] = block_cost(blocks[key[0]], key[1], insns, harness, owner)
            bn, blo, bhi, bby, bfn = cache[key]
            n += count * bn
            lo += count * blo
            hi += count * bhi
            for c, v in bby.items():
                by[c] = by.get(c, 0) + count * v
            for c, v in bfn.items():
                fn[c] = fn.get(c, 0) + count * v
        per_step.append({"insns": n, "lo": lo, "hi": hi, "by": by, "fn": fn})
    runs = [ln for ln in output.splitlines() if ln.startswith("R ")]
    # each step printed one S line: "S <run> <k> <force> <z> <innovation> <nis> <status> ..."
    lines = [ln.split() for ln in output.splitlines() if ln.startswith("S ")]
    if len(lines) != len(per_step):
        sys.exit(f"cycles: {len(per_step)} steps for {len(lines)} output lines")
    res = {}
    for r, header in enumerate(runs):
        f = dict(kv.split("=") for kv in header.split()[2:])
        mine = [i for i, ln in enumerate(lines) if int(ln[1]) == r]
        sl = [per_step[i] for i in mine]
        label = (f"Model {'I' * int(f['model'])} "
                 f"{f['estimator']}" + ("" if f["estimator"] == "robust"
                                        else f", {f['schedule']}"))
        if f["estimator"] == "robust":
            slicing = [int(lines[i][7], 16) & STATUS_REFINING != 0 for i in mine]
            normal = [s for s, sliced in zip(sl, slicing) if not sliced]
            refine = [s for s, sliced in zip(sl, slicing) if sliced]
            res[label + ", normal sample"] = summary(normal)
            if refine:
                res[label + ", refinement"] = summary(refine)
        else:
            res[label] = summary(sl)
    return res


def summary(sl: list[dict]) -> dict:
    worst = max(sl, key=lambda s: s["hi"])
    mid = sorted(sl, key=lambda s: s["hi"])[len(sl) // 2]
    tot_hi = sum(s["hi"] for s in sl)
    return {"steps": len(sl), "median_insns": mid["insns"], "median_lo": mid["lo"],
            "median_hi": mid["hi"], "worst_insns": worst["insns"], "worst_lo": worst["lo"],
            "worst_hi": worst["hi"], "total_lo": sum(s["lo"] for s in sl), "total_hi": tot_hi,
            "worst_by_class": worst["by"], "worst_by_function": worst["fn"]}


def num(x: int) -> str:
    return f"{x:,}".replace(",", "\u202f")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--build", default=str(ROOT / "build" / "m4"))
    ap.add_argument("--json", help="also write the figures to this file")
    ap.add_argument("--functions", type=int, default=0, metavar="N",
                    help="also print the N functions that take most of each worst step")
    a = ap.parse_args()
    if a.functions < 0:
        ap.error(f"argument --functions: {a.functions} is negative (a count of functions, 0: none)")
    elf = pathlib.Path(a.build) / "bin" / "nte-selftest.elf"
    if not elf.exists():
        print(f"cycles: {elf} not found (build it: make board)", file=sys.stderr)
        return 2
    res = model(elf)
    budget = CPU_HZ / RATE_HZ
    print(f"# cycles per nte_step on a Cortex-M4F (QEMU instruction mix x M4 timings; "
          f"load at {RATE_HZ:.0f} Hz on {CPU_HZ / 1e6:.0f} MHz = cycles / {budget:.0f})")
    print("| configuration | steps | median step, cycles | worst step, cycles | "
          "worst step, instructions | load at 200 Hz (worst step) |")
    print("|---|---|---|---|---|---|")
    for label, s in res.items():
        print(f"| {label} | {s['steps']} | {num(s['median_lo'])}–{num(s['median_hi'])} | "
              f"{num(s['worst_lo'])}–{num(s['worst_hi'])} | {num(s['worst_insns'])} | "
              f"{100 * s['worst_lo'] / budget:.2f}–{100 * s['worst_hi'] / budget:.2f} % |")
    for label, s in res.items():
        if "refinement" in label:
            # the refinement's own share: each slice's step less a normal sample's (median)
            normal = res[label.replace("refinement", "normal sample")]
            own_lo = s["total_lo"] - s["steps"] * normal["median_lo"]
            own_hi = s["total_hi"] - s["steps"] * normal["median_hi"]
            print(f"refinement: {s['steps']} step(s), {s['total_lo'] / CPU_HZ * 1e3:.1f}–"
                  f"{s['total_hi'] / CPU_HZ * 1e3:.1f} ms of CPU at {CPU_HZ / 1e6:.0f} MHz in "
                  f"all, {own_lo / CPU_HZ * 1e3:.1f}–{own_hi / CPU_HZ * 1e3:.1f} ms of it the "
                  f"refinement's own (less a normal sample's median step each); the worst "
                  f"step blocks {s['worst_hi'] / budget:.2f} sample periods")
    for label, s in res.items():
        tot = sum(s["worst_by_class"].values())
        shares = ", ".join(f"{c} {100 * v / tot:.0f} %"
                           for c, v in sorted(s["worst_by_class"].items(), key=lambda x: -x[1]))
        print(f"upper-bound cycles of the worst step by class, {label}: {shares}")
    if a.functions > 0:
        for label, s in res.items():
            tot = sum(s["worst_by_function"].values())
            top = sorted(s["worst_by_function"].items(), key=lambda x: -x[1])[:a.functions]
            print(f"worst step by function (upper-bound cycles), {label}: " +
                  ", ".join(f"{f} {num(v)} ({100 * v / tot:.0f} %)" for f, v in top))
    if a.json:
        pathlib.Path(a.json).write_text(json.dumps(res, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
