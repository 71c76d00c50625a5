"""One C style: every hand-written C file is formatted by .clang-format (clang-format 14, Debian
12's; `make test` installs it).  Fix a file with `clang-format -i FILE`.  Generated files keep
their generator's output and are listed in EXCLUDED, the one place that says what is not checked.
"""
from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
STYLE = ROOT / ".clang-format"
VERSION = 14  # the style's options and output are those of this major version

# Generated: each is rewritten by its generator (and compared with its output by other tests),
# so reformatting it by hand would only make the next regeneration differ.
EXCLUDED = {
    "firmware/can/generated/nte_can.c": "cantools, firmware/can/regenerate.sh",
    "firmware/can/generated/nte_can.h": "cantools, firmware/can/regenerate.sh",
    "firmware/src/nte_constants.h": "firmware/tools/gen_constants.py",
    "firmware/presets/nte_presets.h": "firmware/tools/gen_constants.py",
    "firmware/host/nte_units.h": "firmware/tools/gen_constants.py",
    "firmware/host/nte_verdict_rules.h": "firmware/tools/gen_constants.py",
    "firmware/port/mps2-an386/scenario.h": "firmware/port/mps2-an386/gen_scenario.py",
    "tests/c/model_vectors.h": "tests/c/gen_vectors.py",
}

_FINDING = re.compile(r"^(?P<path>.+?):\d+:\d+: (?:error|warning): code should be clang-formatted")


def clang_format() -> str:
    exe = shutil.which("clang-format")
    if exe is None:
        pytest.fail("clang-format is not installed: `make test` installs it (APT_PACKAGES in the "
                    "Makefile), or apt-get install -y clang-format")
    out = subprocess.run([exe, "--version"], capture_output=True, text=True, check=True).stdout
    m = re.search(r"version (\d+)\.", out)
    if m is None or int(m.group(1)) != VERSION:
        pytest.fail(f"clang-format {VERSION} is the style's version (Debian 12's), found: "
                    f"{out.strip()}")
    return exe


def tracked_c_files() -> list[str]:
    out = subprocess.run(["git", "ls-files", "*.c", "*.h"], cwd=ROOT, capture_output=True,
                         text=True, check=True).stdout
    return sorted(out.split())


def unformatted(paths: list[Path]) -> list[str]:
    """The files among `paths` that clang-format would change (the repository's .clang-format)."""
    run = subprocess.run([clang_format(), f"--style=file:{STYLE}", "--dry-run", "--Werror",
                          *map(str, paths)], capture_output=True, text=True, timeout=300)
    found = sorted({m.group("path") for line in run.stderr.splitlines()
                    if (m := _FINDING.match(line))})
    if run.returncode != 0 and not found:
        raise AssertionError(f"clang-format failed (exit {run.returncode}):\n{run.stderr}")
    return found


def test_every_hand_written_c_file_is_formatted() -> None:
    files = [f for f in tracked_c_files() if f not in EXCLUDED]
    assert len(files) > 50, files
    bad = unformatted([ROOT / f for f in files])
    assert not bad, ("not formatted as .clang-format says (run `clang-format -i FILE`):\n  "
                     + "\n  ".join(str(Path(p).relative_to(ROOT)) for p in bad))


def test_excluded_files_are_tracked_and_generated() -> None:
    """No stale entry, and none that a person writes: each says it is generated."""
    tracked = set(tracked_c_files())
    for path, generator in EXCLUDED.items():
        assert path in tracked, f"{path} (EXCLUDED) is not in the repository any more"
        head = "\n".join((ROOT / path).read_text().splitlines()[:6])
        assert "generated" in head.lower(), f"{path}: no 'generated' header ({generator})"


def test_the_check_finds_a_broken_file(tmp_path: Path) -> None:
    """The same function reports a real file once its indentation is broken, and not before."""
    source = (ROOT / "firmware" / "src" / "nte_model.c").read_text()
    intact = tmp_path / "intact.c"
    intact.write_text(source)
    broken = tmp_path / "broken.c"
    broken.write_text(re.sub(r"(?m)^    (?=\S)", "  ", source))
    assert broken.read_text() != source
    assert unformatted([intact, broken]) == [str(broken)]
