"""The structure of the code, floor by floor.

- ``reference_py/`` top level is the twin of the C library: every module there (``__main__`` aside,
  the ``python -m reference_py`` entry point) imports only numpy, the standard library and other
  twin modules -- never the tools (``reference_py/tools``), the discrepancy workflow, scipy or
  matplotlib.
- No import cycle anywhere inside ``reference_py`` or ``host_bench`` (imports inside functions count too: a lazy
  import hides a cycle, it does not remove it).
- No ``#include "..."`` cycle in ``firmware/src`` (file by file, and module by module with a
  ``.c`` and its ``.h`` taken as one module).

The checks read the source (``ast`` for Python, the quoted includes for C); they import nothing.
"""
from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PKG = ROOT / "reference_py"
FIRMWARE_SRC = ROOT / "firmware" / "src"
FIRMWARE_INCLUDE = ROOT / "firmware" / "include"

ENTRY_POINTS = {"reference_py.__main__"}


def module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def python_modules(pkg: Path = PKG) -> dict[str, Path]:
    return {module_name(p): p for p in sorted(pkg.rglob("*.py"))}


def resolve(importer: str, is_package: bool, node: ast.ImportFrom | ast.Import,
            modules: dict[str, Path]) -> list[str]:
    """Absolute names imported by one statement (modules where they exist, else the package)."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    if node.level == 0:
        base = node.module or ""
    else:
        package = importer.split(".") if is_package else importer.split(".")[:-1]
        package = package[:len(package) - (node.level - 1)]
        base = ".".join(package + ([node.module] if node.module else []))
    out = []
    for alias in node.names:
        candidate = f"{base}.{alias.name}"
        out.append(candidate if candidate in modules else base)
    return out


def import_graph(pkg: Path = PKG) -> dict[str, set[str]]:
    """Every import of every module in the package, as absolute dotted names."""
    modules = python_modules(pkg)
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        targets: set[str] = set()
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                targets.update(resolve(name, path.name == "__init__.py", node, modules))
        graph[name] = targets
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of the directed graph (nodes outside the graph's keys are leaves), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if nxt not in graph or nxt == node:
                continue
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        stack.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state:
            found = visit(start)
            if found:
                return found
    return None


def internal_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """Edges between modules of the package only; a package importing its own submodule
    (``from . import x`` in ``__init__``) is not a cycle with that submodule's import of it."""
    return {m: {t for t in targets if t in graph and t != m} for m, targets in graph.items()}


def twin_modules(graph: dict[str, set[str]]) -> list[str]:
    """The package itself and every module file at its top level, the entry point aside."""
    top = {module_name(p) for p in PKG.glob("*.py")}
    return sorted(m for m in graph if m in top and m not in ENTRY_POINTS)


def twin_violations(graph: dict[str, set[str]]) -> list[str]:
    twin = set(twin_modules(graph))
    bad = []
    for module in sorted(twin):
        for target in sorted(graph[module]):
            top = target.split(".")[0]
            if target in twin or top == "numpy" or top in sys.stdlib_module_names:
                continue
            bad.append(f"{module} imports {target}")
    return bad


INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.MULTILINE)


def include_graph() -> dict[str, set[str]]:
    """File -> files it includes with quotes (resolved beside it, then in firmware/src, then
    firmware/include); files are named 'src/x.c', 'include/nte.h' (the public header is its own
    module, not part of nte.c's)."""
    files = sorted(FIRMWARE_SRC.glob("*.[ch]")) + sorted(FIRMWARE_INCLUDE.glob("*.h"))
    graph: dict[str, set[str]] = {}
    for f in files:
        targets = set()
        for inc in INCLUDE.findall(f.read_text(encoding="utf-8")):
            for d in (f.parent, FIRMWARE_SRC, FIRMWARE_INCLUDE):
                if (d / inc).exists():
                    targets.add(f"{d.name}/{inc}")
                    break
            else:
                targets.add(inc)
        graph[f"{f.parent.name}/{f.name}"] = targets
    return graph


def module_include_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """A .c and its .h in the same folder as one module: src/nte_bank.c and src/nte_bank.h are
    'src/nte_bank'."""
    out: dict[str, set[str]] = {}
    for f, targets in graph.items():
        m = f.rsplit(".", 1)[0]
        out.setdefault(m, set()).update(t.rsplit(".", 1)[0] for t in targets)
    return {m: {t for t in ts if t != m} for m, ts in out.items()}


# -- the checks -------------------------------------------------------------------------------

def test_the_twin_is_the_top_level_and_the_tools_are_below():
    graph = import_graph()
    twin = twin_modules(graph)
    for name in ("fmath", "params", "model", "rk3", "ekf", "bank", "robust", "config", "starts"):
        assert f"reference_py.{name}" in twin
    assert "reference_py.tools.cli" in graph and "reference_py.tools.cli" not in twin
    assert "reference_py.__main__" not in twin


def test_twin_imports_only_numpy_stdlib_and_itself():
    assert twin_violations(import_graph()) == []


def test_no_import_cycle_in_reference_py():
    assert find_cycle(internal_graph(import_graph())) is None


def test_no_import_cycle_in_host_bench():
    """The bench: the CLI uses the engines (replay, node mirror, faults), never the reverse."""
    assert find_cycle(internal_graph(import_graph(ROOT / "host_bench"))) is None


def test_no_include_cycle_in_firmware_src():
    graph = include_graph()
    assert "include/nte.h" in graph and "src/nte_real.h" in graph
    assert "include/nte.h" in graph["src/nte_real.h"]  # resolved across the two folders
    assert find_cycle(graph) is None
    assert find_cycle(module_include_graph(graph)) is None


# -- the checks can fail ----------------------------------------------------------------------

def test_cycle_finder_finds_cycles():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None
    assert find_cycle({"a": {"x"}, "b": {"a"}}) is None  # x is outside: a leaf


def test_twin_rule_flags_a_tool_or_library_import():
    graph = import_graph()
    graph["reference_py.model"] = graph["reference_py.model"] | {"reference_py.tools.simulate",
                                                                 "scipy.optimize"}
    bad = twin_violations(graph)
    assert "reference_py.model imports reference_py.tools.simulate" in bad
    assert "reference_py.model imports scipy.optimize" in bad


def test_import_resolution_sees_relative_and_lazy_imports():
    graph = import_graph()
    assert "reference_py.tools.simulate" in graph["reference_py.tools.cli"]  # inside a function
    assert "reference_py.params" in graph["reference_py.tools.cli"]          # from ..params
    assert "reference_py.starts" in graph["reference_py.tools.evaluation"]   # from .. import starts


def test_include_cycle_is_seen_by_module(tmp_path, monkeypatch):
    (tmp_path / "a.c").write_text('#include "b.h"\n')
    (tmp_path / "a.h").write_text("\n")
    (tmp_path / "b.c").write_text('#include "a.h"\n')
    (tmp_path / "b.h").write_text("\n")
    monkeypatch.setattr(sys.modules[__name__], "FIRMWARE_SRC", tmp_path)
    monkeypatch.setattr(sys.modules[__name__], "FIRMWARE_INCLUDE", tmp_path / "none")
    graph = include_graph()
    assert find_cycle(graph) is None  # no file includes itself back...
    cycle = find_cycle(module_include_graph(graph))                     # ...modules do
    assert cycle is not None and sorted(set(cycle)) == [f"{tmp_path.name}/a", f"{tmp_path.name}/b"]


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q"]))
