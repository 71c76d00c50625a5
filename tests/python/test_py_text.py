"""The host programs write Python's text: the C twins in firmware/host/name_value.c against it.

nte-run's messages and --export-config's JSON print floats as Python's repr() does
(nte_py_repr), cells and flag values as repr() of a text does (nte_py_repr_bytes), and strip
cells, names and flag items as str.strip() does (nte_py_strip).  A small driver compiled with
name_value.c prints each for values and texts drawn here, and each must be Python's to the
character: floats of every magnitude and random bit patterns, the layout's edges (1e-4, 1e-5,
1e16), signed zeros and non-finite values; texts of ASCII, quotes, backslashes, controls,
every character str.isspace names and the characters nte_units.h lists as unprintable, valid
and invalid UTF-8 (a byte that is not UTF-8 reads as Python's surrogateescape reads an
argument).  The driver is built with the project's warnings (-Werror).
"""
from __future__ import annotations

import shutil
import subprocess
import unicodedata
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
HOST = ROOT / "firmware" / "host"

DRIVER = r"""
#include "name_value.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static size_t unhex(const char* h, char* out)
{
    size_t n = 0U;
    for (; (h[0] != '\0') && (h[0] != '\n') && (h[1] != '\0'); h += 2) {
        char b[3] = {h[0], h[1], '\0'};
        out[n++] = (char)strtoul(b, NULL, 16);
    }
    return n;
}

int main(void)
{
    static char line[1 << 16];
    static char text[1 << 15];
    static char out[1 << 17];
    while (fgets(line, sizeof line, stdin) != NULL) {
        const size_t n = unhex(line + 2, text);
        if (line[0] == 'f') {
            double x;
            memcpy(&x, text, sizeof x);
            nte_py_repr(x, out, sizeof out);
            printf("%s\n", out);
        } else if (line[0] == 'r') {
            nte_py_repr_bytes(text, n, out, sizeof out);
            printf("%s\n", out);
        } else {
            const char* s = text;
            const size_t m = nte_py_strip(&s, n);
            for (size_t i = 0U; i < m; i++) {
                printf("%02x", (unsigned)(unsigned char)s[i]);
            }
            printf(".\n");
        }
    }
    return 0;
}
"""


@pytest.fixture(scope="module")
def driver(tmp_path_factory) -> Path:
    cc = shutil.which("gcc") or shutil.which("cc")
    if cc is None:
        pytest.skip("no C compiler")
    d = tmp_path_factory.mktemp("py_text")
    (d / "driver.c").write_text(DRIVER)
    exe = d / "driver"
    subprocess.run([cc, "-std=c99", "-D_POSIX_C_SOURCE=200809L", "-Wall", "-Wextra", "-Werror",
                    "-pedantic", "-Wconversion", "-Wshadow", "-Wfloat-equal",
                    f"-I{HOST}", f"-I{ROOT / 'firmware' / 'include'}", str(d / "driver.c"),
                    str(HOST / "name_value.c"), "-lm", "-o", str(exe)], check=True)
    return exe


def _run(exe: Path, lines: list[str]) -> list[str]:
    out = subprocess.run([str(exe)], input="".join(lines).encode(), capture_output=True, check=True,
                         timeout=120).stdout.decode("utf-8", "surrogateescape")
    return out.split("\n")[:len(lines)]


def test_float_repr_is_pythons(driver):
    rng = np.random.default_rng(25)
    values = list(rng.normal(0.0, 1.0, 5000) * 10.0 ** rng.integers(-30, 30, 5000))
    values += list(np.frombuffer(rng.bytes(8 * 5000), dtype=np.float64))
    values += [0.0, -0.0, 1e-4, 1e-5, 9.999e-5, 1e15, 1e16, 9999999999999998.0, 1e22, 0.1,
               0.3, 2.0 / 3.0, 100.0, 5e-324, 1.7976931348623157e308, -1.5, 10000.000000000002,
               float("nan"), float("inf"), float("-inf")]
    values += [k / 1000.0 for k in range(-2000, 2000)]
    got = _run(driver, [f"f {np.float64(v).tobytes().hex()}\n" for v in values])
    wrong = [(repr(float(v)), g) for v, g in zip(values, got) if repr(float(v)) != g]
    assert not wrong, wrong[:10]


def _texts() -> list[bytes]:
    rng = np.random.default_rng(26)
    spaces = [chr(c) for c in range(0x110000) if chr(c).isspace()]
    unprintable = [chr(c) for c in range(0x80, 0x10000) if not (0xD800 <= c < 0xE000)
                   and unicodedata.category(chr(c)) != "Cn" and not chr(c).isprintable()]
    alphabet = (list("0123456789.eE+-abc xyz'\"\\,\t\n\r\x00\x01\x1b\x7f") + spaces
                + unprintable[::7] + ["\u00e9", "\u4e2d", "\U0001f600", "\u2019"])
    out = [b"", b" ", b"'", b'"', b"'\"", b"\xff", b"a\xc3", b"\xed\xa0\x80", b"\xc0\xaf",
           b"\xf4\x90\x80\x80", " \u3000x\u2028 ".encode()]
    out += ["".join(rng.choice(alphabet, int(rng.integers(1, 12)))).encode()
            for _ in range(3000)]
    out += [bytes(rng.integers(0, 256, int(rng.integers(1, 8)), dtype=np.uint8))
            for _ in range(1000)]
    return out


def _shown_as_python(t: bytes) -> bool:
    """Within nte_py_repr_bytes's documented limit: no unassigned code point, none beyond
    U+FFFF that repr escapes."""
    s = t.decode("utf-8", "surrogateescape")
    return not any((unicodedata.category(c) == "Cn" and not 0xDC80 <= ord(c) <= 0xDCFF)
                   or (ord(c) > 0xFFFF and not c.isprintable()) for c in s)


def test_text_repr_is_pythons(driver):
    texts = [t for t in _texts() if _shown_as_python(t)]
    assert len(texts) > 3500
    got = _run(driver, [f"r {t.hex()}\n" for t in texts])
    want = [repr(t.decode("utf-8", "surrogateescape")) for t in texts]
    wrong = [(w, g) for w, g in zip(want, got) if w != g]
    assert not wrong, wrong[:10]


def test_strip_is_pythons(driver):
    texts = [t for t in _texts() if _utf8(t)]
    got = _run(driver, [f"s {t.hex()}\n" for t in texts])
    want = [t.decode().strip().encode().hex() + "." for t in texts]
    wrong = [(t, w, g) for t, w, g in zip(texts, want, got) if w != g]
    assert not wrong, wrong[:10]


def _utf8(b: bytes) -> bool:
    try:
        b.decode("utf-8")
    except UnicodeDecodeError:
        return False
    return True
