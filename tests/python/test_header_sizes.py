"""The sizes the public headers quote are the sizes the compiler lays out.

nte.h's MEMORY MODEL and nte_node.h's quote sizeof(nte_t), the contact front end's share and
sizeof(nte_node_t) on x86-64 with gcc: a user sizes a static pool or a task stack from them, so
a struct that grows without its header saying so is a defect.  The test reads the numbers from
the header text and compiles a one-line program per precision and robust buffer length.
"""
from __future__ import annotations

import platform
import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
INCLUDES = [ROOT / "firmware" / d for d in ("include", "node", "can", "can/generated")]

pytestmark = pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"),
                                reason="the headers quote x86-64 sizes")


def _prose(header: str) -> str:
    """The header's comment text as one line (the ' * ' margins and line breaks removed)."""
    text = (ROOT / "firmware" / header).read_text()
    lines = (re.sub(r"^\s*/?\*+/?", "", line) for line in text.splitlines())
    return re.sub(r"\s+", " ", " ".join(lines))


def _sizes(tmp: Path, double: int, buffer_len: int) -> dict[str, int]:
    cc = shutil.which("gcc") or shutil.which("cc")
    if cc is None:
        pytest.skip("no C compiler")
    src = tmp / "sizes.c"
    src.write_text('#include <stdio.h>\n#include "nte.h"\n#include "nte_node.h"\n'
                   "int main(void) {\n"
                   '    printf("%zu %zu %zu %zu %zu\\n", sizeof(nte_t), sizeof(nte_node_t),\n'
                   "           sizeof(nte_config_t), sizeof(nte_contact_t),\n"
                   "           sizeof(nte_contact_config_t));\n"
                   "    return 0;\n}\n")
    exe = tmp / f"sizes_{double}_{buffer_len}"
    subprocess.run([cc, "-std=c99", f"-DNTE_DOUBLE={double}",
                    f"-DNTE_ROBUST_BUFFER_LEN={buffer_len}",
                    *(f"-I{d}" for d in INCLUDES), str(src), "-o", str(exe)], check=True)
    values = [int(v) for v in subprocess.run([str(exe)], capture_output=True, text=True,
                                             check=True).stdout.split()]
    return dict(zip(("nte_t", "nte_node_t", "nte_config_t", "contact", "contact_config"),
                    values))


def test_nte_h_quotes_the_instance_sizes(tmp_path: Path) -> None:
    text = _prose("include/nte.h")
    m = re.search(r"sizeof\(nte_t\) on x86-64 \(gcc\): (\d+) bytes \(float\) / (\d+) \(double\) "
                  r"with NTE_ROBUST_BUFFER_LEN = 0 \(the bank and the contact front end: its "
                  r"state (\d+) / (\d+) bytes, its configuration (\d+) / (\d+)\); with the "
                  r"default 96: (\d+) \(float, \+(\d+)\) / (\d+) \(double, \+(\d+)\)", text)
    assert m, "nte.h's MEMORY MODEL no longer states the sizes in the form this test reads"
    (f0, d0, state_f, state_d, cfg_f, cfg_d, f96, df, d96, dd) = map(int, m.groups())
    got = {(dbl, n): _sizes(tmp_path, dbl, n) for dbl in (0, 1) for n in (0, 96)}
    assert (f0, d0) == (got[0, 0]["nte_t"], got[1, 0]["nte_t"])
    assert (f96, d96) == (got[0, 96]["nte_t"], got[1, 96]["nte_t"])
    assert (df, dd) == (f96 - f0, d96 - d0)
    assert (state_f, state_d) == (got[0, 0]["contact"], got[1, 0]["contact"])
    assert (cfg_f, cfg_d) == (got[0, 0]["contact_config"], got[1, 0]["contact_config"])


def test_nte_node_h_quotes_the_node_size(tmp_path: Path) -> None:
    text = _prose("node/nte_node.h")
    m = re.search(r"sizeof\(nte_node_t\) is (\d+) bytes on x86-64 with the default sizes: the "
                  r"estimator nte_t (\d+), three estimator configurations 3 x (\d+)", text)
    assert m, "nte_node.h's MEMORY MODEL no longer states the sizes in the form this test reads"
    node, est, cfg = map(int, m.groups())
    got = _sizes(tmp_path, 0, 96)
    assert (node, est, cfg) == (got["nte_node_t"], got["nte_t"], got["nte_config_t"])
