"""Sanitizer build of every C target and test, and the libFuzzer harnesses.

* The whole CMake project (library float/double, CAN layer, node, Linux port, host programs, all
  cmocka tests) built with -fsanitize=address,undefined,float-cast-overflow
  -fno-sanitize-recover=all through cmake/sanitize.cmake, then ctest: every test passes and no
  sanitizer reports anything.
* tests/fuzz/run.sh 20 HARNESS for each harness: 0 crashes (property aborts, sanitizer findings,
  timeouts, out-of-memory).  Skipped only when clang is not installed.
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
FUZZ_SECONDS = int(os.environ.get("NTE_FUZZ_SECONDS", "20"))
SAN_REPORT = re.compile(r"runtime error:|ERROR: (Address|Leak|UndefinedBehavior)Sanitizer|"
                        r"SUMMARY: (Address|UndefinedBehavior)Sanitizer")
SAN_ENV = {"ASAN_OPTIONS": "detect_leaks=1:abort_on_error=1:halt_on_error=1",
           "UBSAN_OPTIONS": "print_stacktrace=1:halt_on_error=1"}
# The estimator's divergence on finite in-range samples (reported under issue 9; reproducers in
# tests/fuzz/regressions/).  Remove from here once the library rejects or repairs it.
KNOWN_DIVERGENCE = "nte_step output non-finite on finite in-range input (issue 9 report)"


def _clang_or_skip() -> str:
    cc = shutil.which("clang")
    if cc is None:
        pytest.skip("clang not installed (the Makefile installs clang libclang-rt-14-dev)")
    return cc


def test_sanitizer_build_ctest() -> None:
    if shutil.which("cmake") is None or shutil.which("ctest") is None:
        pytest.skip("cmake not installed")
    build = ROOT / "build" / "asan"
    env = dict(os.environ, **SAN_ENV)
    subprocess.run(["cmake", "-S", str(ROOT), "-B", str(build), "-DCMAKE_BUILD_TYPE=RelWithDebInfo",
                    "-DNTE_SANITIZE=ON",
                    f"-DCMAKE_PROJECT_INCLUDE={ROOT / 'cmake' / 'sanitize.cmake'}"],
                   check=True, capture_output=True, env=env)
    b = subprocess.run(["cmake", "--build", str(build), "-j2"], capture_output=True, text=True,
                       env=env)
    assert b.returncode == 0, b.stdout[-4000:] + b.stderr[-4000:]
    flags = (build / "tests" / "c_can" / "CMakeFiles" / "test_nte_e2e.dir" / "flags.make")
    assert "-fsanitize=address,undefined,float-cast-overflow" in flags.read_text()
    t = subprocess.run(["ctest", "--test-dir", str(build), "-j2", "--output-on-failure"],
                       capture_output=True, text=True, env=env, timeout=600)
    print(t.stdout[-3000:])
    assert t.returncode == 0, t.stdout[-6000:] + t.stderr[-2000:]
    assert "100% tests passed" in t.stdout
    assert not SAN_REPORT.search(t.stdout + t.stderr)


def _run_harness(name: str) -> dict[str, int]:
    _clang_or_skip()
    run = subprocess.run([str(ROOT / "tests" / "fuzz" / "run.sh"), str(FUZZ_SECONDS), name],
                         capture_output=True, text=True, timeout=FUZZ_SECONDS * 4 + 300,
                         env=dict(os.environ, NTE_FUZZ_BUILD=str(ROOT / "build" / "fuzz")))
    print(run.stdout, run.stderr[-3000:])
    assert run.returncode in (0, 1), run.stdout + run.stderr  # 2 = build error
    m = re.search(rf"^fuzz {name}: executions=(\d+) crashes=(\d+) sanitizer_reports=(\d+)",
                  run.stdout, re.M)
    assert m, run.stdout
    return {"executions": int(m.group(1)), "crashes": int(m.group(2)),
            "sanitizer_reports": int(m.group(3)), "rc": run.returncode}


@pytest.mark.parametrize("name", [
    "node",
    "csv",
    pytest.param("config_f32", marks=pytest.mark.xfail(reason=KNOWN_DIVERGENCE, strict=False)),
    pytest.param("config_f64", marks=pytest.mark.xfail(reason=KNOWN_DIVERGENCE, strict=False)),
])
def test_fuzz_harness(name: str) -> None:
    r = _run_harness(name)
    assert r["executions"] > 1000, r
    assert r["crashes"] == 0 and r["sanitizer_reports"] == 0 and r["rc"] == 0, r


@pytest.mark.xfail(reason=KNOWN_DIVERGENCE, strict=True)
@pytest.mark.parametrize("prec", ["f32", "f64"])
def test_known_divergence_reproducer(prec: str) -> None:
    """Strict xfail: when the library is fixed this XPASSes and fails, so the marks above get
    removed and the config harnesses become a hard gate."""
    _clang_or_skip()
    exe = ROOT / "build" / "fuzz" / "bin" / f"fuzz_config_{prec}"
    if not exe.exists():
        subprocess.run([str(ROOT / "tests" / "fuzz" / "run.sh"), "0"], capture_output=True,
                       check=True, env=dict(os.environ, NTE_FUZZ_BUILD=str(exe.parents[1])))
    run = subprocess.run([str(exe), str(ROOT / "tests" / "fuzz" / "regressions" /
                                        f"config_divergence_{prec}.bin")],
                         capture_output=True, text=True, env=dict(os.environ, **SAN_ENV))
    assert run.returncode == 0, run.stderr[-2000:]
