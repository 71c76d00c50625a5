"""``nte-ref estimate --engine c``: the same estimate through the C library's host program.

The program is ``nte-run-double`` (``--precision float64``) or ``nte-run`` (float32) in
``--c-bin DIR`` (default: build/host/bin of this repository; ``make build`` builds them).  A
program that is missing there is refused (exit 2) before anything runs: point ``--c-bin`` at
another directory to use another build.

Every estimate flag given (a value other than its default) is handed to the program under its
own name, with the value as nte-ref parsed it (numbers with ``repr``: the program reads the
same double).  The program's ``--help`` is read first, and a flag it does not list is

* an input flag (``--columns``, the units and signs, ``--no-units-check``): then nte-ref's own
  reader (csvio) maps, converts and checks the file, and the program is given a temporary CSV
  of t_s, depth_mm, force_n (and velocity_mm_s when the file gives one) printed with ``%.17g``
  (every value round-trips: the program reads the doubles the reference estimates from), with
  none of the input flags but ``--no-units-check`` when it has that one;
* any other flag (``--plot``, ...): refused, exit 2, one line naming it.

So a C build that has the input flags reads the file itself, and one that lacks some still
gives the estimate file the reference writes, byte for byte.  The program's stdout, stderr and
exit status are nte-ref's (its refusals are its own one line).
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:
    from .csvio import Trial

#: the reference's reader of an estimate's input: the flags -> the trial it estimates from
ReadInput = Callable[[argparse.Namespace], "Trial"]

#: where the host programs are built (make build), and which one runs which precision
C_BIN = Path(__file__).resolve().parents[2] / "build" / "host" / "bin"
C_EXE = {"float32": "nte-run", "float64": "nte-run-double"}
#: nte-ref's own flags, not the program's
OWN_DESTS = ("engine", "c_bin", "help")
#: the input flags nte-ref's reader can apply for the program (csvio.Units)
INPUT_FLAGS = ("--columns", "--force-unit", "--time-unit", "--depth-unit", "--force-sign",
               "--depth-sign", "--depth-offset", "--no-units-check")


def program(a: argparse.Namespace) -> Path:
    """The host program for ``a.precision``, or ValueError saying how to build it."""
    exe = (Path(a.c_bin) if a.c_bin else C_BIN) / C_EXE[a.precision]
    if not (exe.is_file() and os.access(exe, os.X_OK)):
        raise ValueError(f"--engine c: {exe} is missing (make build builds it; --c-bin DIR "
                         f"points at another build)")
    return exe


def program_flags(exe: Path) -> set[str]:
    """The flags the program's --help lists."""
    r = subprocess.run([str(exe), "--help"], capture_output=True, text=True,
                       stdin=subprocess.DEVNULL, timeout=60)
    return set(re.findall(r"--[a-z][a-z0-9-]*", r.stdout))


def _text(value: object) -> str:
    if isinstance(value, dict):
        return ",".join(f"{k}={v!r}" for k, v in value.items())
    return repr(value) if isinstance(value, float) else str(value)


def given_flags(a: argparse.Namespace, actions: list[argparse.Action]
                ) -> list[tuple[str, list[str]]]:
    """(flag, its command-line tokens) of every estimate option ``a`` holds a value other than
    the default of, nte-ref's own ones excepted."""
    out = []
    for act in actions:
        if not act.option_strings or act.dest in OWN_DESTS:
            continue
        v = getattr(a, act.dest)
        if v is None or v is False or v == act.default:
            continue
        flag = act.option_strings[-1]
        out.append((flag, [flag] if v is True else [flag, _text(v)]))
    return out


def converted_input(a: argparse.Namespace, folder: Path, read_input: ReadInput) -> Path:
    """The input as the reference reads it (``read_input(a)``: mapped, converted, checked),
    written to ``folder`` under the file's own name in t_s, depth_mm, force_n[, velocity_mm_s]
    with %.17g."""
    tr = read_input(a)
    cols = [tr.t_s, tr.depth_mm, tr.force_n] + ([tr.velocity_mm_s] if tr.velocity_given else [])
    head = "t_s,depth_mm,force_n" + (",velocity_mm_s" if tr.velocity_given else "")
    path = folder / Path(a.csv).name
    with open(path, "w", encoding="utf-8", newline="") as fh:
        fh.write(head + "\n")
        for row in zip(*cols):
            fh.write(",".join("%.17g" % float(x) for x in row) + "\n")
    return path


def run_c_estimate(a: argparse.Namespace, actions: list[argparse.Action],
                   read_input: ReadInput) -> int:
    """Run the estimate ``a`` asks for through the host program (the module's docstring);
    ``read_input`` is the reference's reader of that input (the CLI's: this module imports no
    CLI module), used when the program lacks one of the input flags given."""
    given = given_flags(a, actions)
    exe = program(a)
    known = program_flags(exe)
    lacking = [flag for flag, _ in given if flag not in known]
    if "--plot" in lacking:
        raise ValueError(f"--engine c: --plot: {exe.name} draws nothing (draw its estimate "
                         f"file with nte-ref plot)")
    other = [flag for flag in lacking if flag not in INPUT_FLAGS]
    if other:
        raise ValueError(f"--engine c: {exe.name} has no {other[0]} (this build; run with "
                         f"--engine reference, or rebuild it with make build)")
    convert = any(flag in INPUT_FLAGS for flag in lacking)
    with tempfile.TemporaryDirectory(prefix="nte-engine-") as tmp:
        src = str(a.csv)
        args = [tok for _, toks in given for tok in toks]
        if convert:
            src = str(converted_input(a, Path(tmp), read_input))
            args = [tok for flag, toks in given if flag not in INPUT_FLAGS for tok in toks]
            if a.no_units_check and "--no-units-check" in known:
                args.append("--no-units-check")
        r = subprocess.run([str(exe), src, *args], capture_output=True, text=True,
                           stdin=subprocess.DEVNULL)
    sys.stdout.write(r.stdout)
    sys.stderr.write(r.stderr)
    return r.returncode if r.returncode >= 0 else 1


__all__ = ["C_BIN", "C_EXE", "INPUT_FLAGS", "converted_input", "given_flags", "program",
           "program_flags", "run_c_estimate"]
