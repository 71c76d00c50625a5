"""Fail if the float build of the library uses double, malloc, free or printf.

    check_float_build.py --lib libnte_f32.a --src firmware/src --src firmware/include

Three checks:
1. the archive's undefined symbols (nm -u) name no allocator, no printf family, no double libm
   function (exp, sqrt, ...) and no soft-float double helper (__aeabi_d*, __extendsfdf2, ...);
2. its disassembly (objdump -d, x86-64) holds no scalar-double SSE instruction (…sd);
3. the sources contain the word `double` only inside `#if NTE_DOUBLE` branches.
Exit status 0 when clean, 1 with a list of findings otherwise.
"""
from __future__ import annotations

import argparse
import re
import subprocess
import sys
from pathlib import Path

FORBIDDEN_CALLS = re.compile(
    r"^(malloc|calloc|realloc|free|printf|fprintf|sprintf|snprintf|vprintf|vfprintf|puts|"
    r"exp|log|pow|sqrt|tanh|sin|cos|fabs|floor|ceil|__extendsfdf2|__truncdfsf2|__adddf3|"
    r"__muldf3|__divdf3|__subdf3|__aeabi_d\w*|__aeabi_f2d|__aeabi_d2f)$")
DOUBLE_INSN = re.compile(r"\s(cvtss2sd|cvtsd2ss|cvtsi2sdl?q?|cvttsd2si\w*|addsd|subsd|mulsd|"
                         r"divsd|sqrtsd|ucomisd|comisd|maxsd|minsd|vcvtss2sd|vaddsd|vmulsd|"
                         r"vdivsd|vsubsd)\b")


def undefined_symbols(lib: str) -> list[str]:
    out = subprocess.run(["nm", "-u", lib], check=True, capture_output=True, text=True).stdout
    return [ln.split()[-1] for ln in out.splitlines() if ln.strip() and not ln.endswith(":")]


def double_instructions(lib: str) -> list[str]:
    out = subprocess.run(["objdump", "-d", lib], check=True, capture_output=True, text=True).stdout
    return [ln.strip() for ln in out.splitlines() if DOUBLE_INSN.search(ln)]


def double_outside_guard(path: Path) -> list[str]:
    """Lines using `double` that the float build compiles (outside #if NTE_DOUBLE)."""
    findings = []
    stack: list[str] = []  # per #if: "dbl" (double branch), "flt" (float branch) or "other"
    in_comment = False
    for no, line in enumerate(path.read_text().splitlines(), start=1):
        s = line.strip()
        if s.startswith("#if"):
            cond = s[3:].strip()
            stack.append("dbl" if re.fullmatch(r"(def\s+)?\(?NTE_DOUBLE\)?", cond) else
                         ("flt" if re.fullmatch(r"(ndef\s+NTE_DOUBLE|\s*!\s*NTE_DOUBLE)", cond)
                          else "other"))
            continue
        if s.startswith("#else") and stack:
            stack[-1] = {"dbl": "flt", "flt": "dbl"}.get(stack[-1], "other")
            continue
        if s.startswith("#endif") and stack:
            stack.pop()
            continue
        code = line
        if in_comment:
            if "*/" not in code:
                continue
            code = code.split("*/", 1)[1]
            in_comment = False
        code = re.sub(r"/\*.*?\*/", "", code)
        if "/*" in code:
            code = code.split("/*", 1)[0]
            in_comment = True
        code = code.split("//", 1)[0]
        code = re.sub(r'"[^"]*"', "", code)
        if re.search(r"\bdouble\b", code) and "dbl" not in stack:
            findings.append(f"{path}:{no}: {s}")
    return findings


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--lib", required=True)
    ap.add_argument("--src", action="append", default=[])
    a = ap.parse_args()
    bad = [f"undefined symbol {s}" for s in undefined_symbols(a.lib) if FORBIDDEN_CALLS.match(s)]
    bad += [f"double instruction: {i}" for i in double_instructions(a.lib)]
    for d in a.src:
        for p in sorted(Path(d).glob("*.[ch]")):
            bad += double_outside_guard(p)
    for b in bad:
        print(b)
    print("float build: clean" if not bad else f"float build: {len(bad)} finding(s)")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
