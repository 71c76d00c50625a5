#!/usr/bin/env python3
"""Static analysis gate for firmware/ (driven by tests/static/run.sh; see there)."""
from __future__ import annotations

import argparse
import concurrent.futures
import fnmatch
import json
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

TIDY_CHECKS = "-*,bugprone-*,cert-*,clang-analyzer-*"
CPPCHECK_ENABLE = "warning,style,performance,portability"
# clang-tidy prints warnings from headers matching this (the generated header is excluded).
HEADER_FILTER = r".*/firmware/(include|src|host|node|port|can/nte_)"
TIDY_LINE = re.compile(r"^(/[^:]+):(\d+):(\d+): (warning|error): (.*) \[([^\]]+)\]$")
CPPCHECK_LINE = re.compile(r"^([^:]+):(\d+):([a-z]+):([A-Za-z0-9_]+):(.*)$")


@dataclass(frozen=True)
class Finding:
    tool: str
    checks: tuple[str, ...]
    path: str  # relative to the repository
    line: int
    message: str


@dataclass
class Suppression:
    tool: str
    check: str
    glob: str
    why: str
    used: int = 0


@dataclass
class Report:
    findings: set[Finding] = field(default_factory=set)
    info: list[str] = field(default_factory=list)


def load_suppressions(path: Path) -> list[Suppression]:
    out = []
    for raw in path.read_text().splitlines():
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        head, _, why = line.partition("|")
        parts = head.split()
        if len(parts) != 3 or not why.strip():
            sys.exit(f"{path}: malformed entry (TOOL CHECK GLOB | WHY): {raw}")
        out.append(Suppression(parts[0], parts[1], parts[2], why.strip()))
    return out


def sources(root: Path) -> list[Path]:
    files = sorted((root / "firmware").rglob("*.c"))
    return [f for f in files if "generated" not in f.relative_to(root).parts]


def run_cppcheck(root: Path, files: list[Path], report: Report) -> None:
    inc = ["include", "src", "host", "can", "node", "port/linux"]
    for double in ("0", "1"):
        cmd = ["cppcheck", "--std=c99", f"--enable={CPPCHECK_ENABLE}", "--inline-suppr", "-q",
               f"-DNTE_DOUBLE={double}", "-D_POSIX_C_SOURCE=200809L", "-D__linux__",
               "--suppress=missingIncludeSystem",
               "--template={file}:{line}:{severity}:{id}:{message}"]
        cmd += [f"-I{root / 'firmware' / d}" for d in inc]
        cmd += [str(f) for f in files]
        run = subprocess.run(cmd, capture_output=True, text=True, cwd=root)
        for line in run.stderr.splitlines():
            m = CPPCHECK_LINE.match(line)
            if not m:
                continue
            p = Path(m.group(1))
            rel = str((p if p.is_absolute() else root / p).resolve().relative_to(root))
            report.findings.add(Finding("cppcheck", (m.group(4),), rel, int(m.group(2)),
                                        m.group(5).strip()))


def compile_databases(root: Path, build: Path) -> tuple[Path, Path]:
    """Configure the project with clang and split its compile database by precision."""
    cfg = subprocess.run(["cmake", "-S", str(root), "-B", str(build / "cmake"),
                          "-DCMAKE_C_COMPILER=clang", "-DCMAKE_EXPORT_COMPILE_COMMANDS=ON"],
                         capture_output=True, text=True)
    if cfg.returncode != 0:
        sys.exit("cmake configure failed:\n" + cfg.stdout + cfg.stderr)
    entries = json.loads((build / "cmake" / "compile_commands.json").read_text())
    dirs = []
    for name, want_double in (("f32", False), ("f64", True)):
        sel = [e for e in entries
               if ("-DNTE_DOUBLE=1" in e["command"]) == want_double or
               "-DNTE_DOUBLE=" not in e["command"]]
        d = build / name
        d.mkdir(parents=True, exist_ok=True)
        (d / "compile_commands.json").write_text(json.dumps(sel, indent=1))
        dirs.append(d)
    return dirs[0], dirs[1]


def tidy_one(root: Path, db: Path, src: Path) -> tuple[str, str]:
    cmd = ["clang-tidy", "-p", str(db), "--quiet", f"--checks={TIDY_CHECKS}",
           f"--header-filter={HEADER_FILTER}", "--extra-arg=-Wno-error", str(src)]
    run = subprocess.run(cmd, capture_output=True, text=True, cwd=root)
    return run.stdout, run.stderr


def run_clang_tidy(root: Path, build: Path, files: list[Path], jobs: int, report: Report) -> None:
    db32, db64 = compile_databases(root, build)
    known = {Path(e["file"]).resolve()
             for e in json.loads((db32 / "compile_commands.json").read_text())}
    jobs_list = [(db32, f) for f in files if f.resolve() in known]
    missing = [f for f in files if f.resolve() not in known]
    for f in missing:
        # e.g. a board port built only by its cross toolchain: cppcheck still covers it.
        report.info.append(f"{f.relative_to(root)}: not in the host compile database, "
                           "clang-tidy skipped it (cppcheck did not)")
    # The library proper is analysed in its double build too.
    jobs_list += [(db64, f) for f in files if f.parent.name == "src"]
    with concurrent.futures.ThreadPoolExecutor(max_workers=jobs) as pool:
        outs = list(pool.map(lambda job: tidy_one(root, *job), jobs_list))
    for stdout, _ in outs:
        for line in stdout.splitlines():
            m = TIDY_LINE.match(line)
            if not m:
                continue
            checks = tuple(m.group(6).split(","))
            rel = str(Path(m.group(1)).resolve().relative_to(root))
            if all(c.startswith("clang-diagnostic-") for c in checks):
                # Compiler warnings (clang's view of the gcc-tuned -W flags): not a check we
                # gate on here, but listed.
                report.info.append(f"clang compiler warning, not gated: {rel}:{m.group(2)}: "
                                   f"{m.group(5)} [{m.group(6)}]")
                continue
            report.findings.add(Finding("clang-tidy", checks, rel, int(m.group(2)),
                                        m.group(5)))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--root", type=Path, required=True)
    ap.add_argument("--build", type=Path, required=True)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--suppressions", type=Path, required=True)
    ap.add_argument("--only", choices=["cppcheck", "clang-tidy"], default=None)
    a = ap.parse_args()
    root = a.root.resolve()
    need = ["cmake", "clang"] + ([] if a.only == "cppcheck" else ["clang-tidy"]) + \
        ([] if a.only == "clang-tidy" else ["cppcheck"])
    missing = [t for t in need if shutil.which(t) is None]
    if missing:
        print(f"static: missing tools {missing} (apt-get install -y cppcheck clang clang-tidy)")
        return 2
    a.build.mkdir(parents=True, exist_ok=True)
    files = sources(root)
    report = Report()
    if a.only != "clang-tidy":
        run_cppcheck(root, files, report)
    if a.only != "cppcheck":
        run_clang_tidy(root, a.build, files, a.jobs, report)
    sups = load_suppressions(a.suppressions)
    bad = []
    for f in sorted(report.findings, key=lambda f: (f.path, f.line, f.checks)):
        hit = None
        for s in sups:
            if s.tool == f.tool and s.check in f.checks and fnmatch.fnmatch(f.path, s.glob):
                hit = s
                break
        if hit is None:
            bad.append(f)
        else:
            hit.used += 1
    for f in bad:
        print(f"FINDING {f.tool} {f.path}:{f.line}: {f.message} [{','.join(f.checks)}]")
    unused = [s for s in sups if s.used == 0 and (a.only is None or a.only == s.tool)]
    for s in unused:
        print(f"UNUSED SUPPRESSION {s.tool} {s.check} {s.glob} (remove it)")
    for s in sups:
        if s.used:
            print(f"suppressed {s.used:3d} x {s.tool} {s.check} {s.glob}")
    for i in report.info:
        print(f"info: {i}")
    n_tidy = sum(1 for f in report.findings if f.tool == "clang-tidy")
    n_cpp = sum(1 for f in report.findings if f.tool == "cppcheck")
    print(f"static: files={len(files)} cppcheck_findings={n_cpp} clang_tidy_findings={n_tidy} "
          f"suppressed={sum(s.used for s in sups)} unsuppressed={len(bad)} "
          f"unused_suppressions={len(unused)}")
    return 1 if (bad or unused) else 0


if __name__ == "__main__":
    sys.exit(main())
