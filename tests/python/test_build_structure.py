"""The build's structure: one set of strict flags on every C target, one source list for the
library, products independent of the tests.

Configures the project (configure only, no build) into a temporary directory with a compile
database and reads every compile command; also greps the CMake files.
"""
from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
STRICT = ["-Wall", "-Wextra", "-Werror", "-pedantic", "-Wconversion", "-Wdouble-promotion",
          "-Wshadow", "-Wfloat-equal", "-Wundef", "-ffp-contract=off", "-std=c99"]
CMAKE_FILES = sorted([ROOT / "CMakeLists.txt", *(ROOT / "cmake").glob("*.cmake"),
                      *(ROOT / "firmware").rglob("CMakeLists.txt"),
                      *(ROOT / "tests").rglob("CMakeLists.txt")])


def _configure(tmp: Path, *args: str) -> list[dict]:
    if shutil.which("cmake") is None:
        pytest.skip("cmake not installed")
    r = subprocess.run(["cmake", "-S", str(ROOT), "-B", str(tmp),
                        "-DCMAKE_EXPORT_COMPILE_COMMANDS=ON", *args],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    return json.loads((tmp / "compile_commands.json").read_text())


def test_every_compile_command_has_the_strict_flags(tmp_path: Path) -> None:
    entries = _configure(tmp_path / "all")
    files = {Path(e["file"]).relative_to(ROOT).as_posix() for e in entries}
    for f in ("firmware/src/nte_model.c", "firmware/can/nte_frames.c",
              "firmware/node/nte_node.c", "firmware/port/linux/nte_node_main.c",
              "firmware/host/nte_run.c", "firmware/port/mps2-an386/selftest.c",
              "tests/c/test_api.c", "tests/c_can/test_nte_e2e.c"):
        assert f in files, f
    for e in entries:
        flags = e["command"].split()
        if e["file"].endswith("enobufs_shim.c"):
            # the LD_PRELOAD test shim: dlsym(RTLD_NEXT) needs GNU C, documented exception
            want = [f for f in STRICT if f != "-std=c99"] + ["-std=gnu99"]
            assert flags[flags.index("-pedantic") + 1:].count("-Wno-pedantic") == 1
        else:
            want = STRICT
            assert not [f for f in flags if f.startswith("-Wno-")], e["command"]
        missing = [f for f in want if f not in flags]
        assert not missing, f"{e['file']}: missing {missing}"


def test_products_configure_without_the_tests(tmp_path: Path) -> None:
    """NTE_BUILD_TESTS=OFF: nothing under tests/ is compiled, cmocka is never looked for."""
    entries = _configure(tmp_path / "products", "-DNTE_BUILD_TESTS=OFF")
    assert not [e["file"] for e in entries if "/tests/" in e["file"]]
    cache = (tmp_path / "products" / "CMakeCache.txt").read_text()
    assert "CMOCKA_INCLUDE_DIR" not in cache and "CMOCKA_LIBRARY" not in cache
    for f in ("firmware/port/linux/nte_port_socketcan.c", "firmware/host/nte_bench.c"):
        assert str(ROOT / f) in {e["file"] for e in entries}, f


def test_strict_flags_and_library_sources_are_written_once() -> None:
    spelled = [p.relative_to(ROOT).as_posix() for p in CMAKE_FILES
               if "-Wconversion" in p.read_text() or "-Wfloat-equal" in p.read_text()]
    assert spelled == ["cmake/nte_strict.cmake"], spelled
    lists = [p.relative_to(ROOT).as_posix() for p in CMAKE_FILES
             if "nte_config.c" in p.read_text()]
    assert lists == ["firmware/CMakeLists.txt"], lists


def test_ports_do_not_reach_into_the_host_programs() -> None:
    """The presets are generated where ports and host programs both find them."""
    for src in (ROOT / "firmware" / "port").rglob("*"):
        if src.suffix in (".c", ".h") or src.name == "CMakeLists.txt":
            text = src.read_text()
            assert "firmware/host" not in text and "../host" not in text, src
    assert (ROOT / "firmware" / "presets" / "nte_presets.h").is_file()
    assert not (ROOT / "firmware" / "host" / "nte_presets.h").exists()
