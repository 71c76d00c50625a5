"""The structure of the code, floor by floor.

- ``reference_py/`` top level is the twin of the C library: every module there (``__main__`` aside,
  the ``python -m reference_py`` entry point) imports only numpy, the standard library and other
  twin modules -- never the tools (``reference_py/tools``), the discrepancy workflow, scipy or
  matplotlib.
- No import cycle anywhere inside ``reference_py`` or ``host_bench`` (imports inside functions count too: a lazy
  import hides a cycle, it does not remove it).
- No ``#include "..."`` cycle in ``firmware/src`` (file by file, and module by module with a
  ``.c`` and its ``.h`` taken as one module).

The product's floors (``reference_py`` and ``host_bench``, read together):

- ``reference_py`` never imports ``host_bench``: the bench stands on the reference, and what both
  need of the bus (the DBC, candump logs) lives in ``reference_py/bus``.
- No module imports a command-line module (a console script of ``pyproject.toml``, a module that
  runs as ``__main__``, or a package's ``__main__`` itself), except a package's own ``__main__``
  importing its package's command: code shared by commands lives in a module of its own.
- No product module mentions ``sys.path``: the packages are installed, and what the product needs
  is in the product (the tests' own helpers stay in ``tests/``).
- No import cycle in the product: not between modules, not between the packages that hold them
  (``reference_py``, ``reference_py.tools``, ``host_bench``...), not between the two top-level
  packages.

The checks read the source (``ast`` for Python, the quoted includes for C); they import nothing.
"""
from __future__ import annotations

import ast
import re
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PKG = ROOT / "reference_py"
FIRMWARE_SRC = ROOT / "firmware" / "src"
FIRMWARE_INCLUDE = ROOT / "firmware" / "include"

ENTRY_POINTS = {"reference_py.__main__"}
#: the installed packages (pyproject.toml's packages.find): the product, floor by floor
PRODUCT = (PKG, ROOT / "host_bench")
PYPROJECT = ROOT / "pyproject.toml"


def module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def python_modules(*pkgs: Path) -> dict[str, Path]:
    """Every module of the packages (``reference_py`` when none is named), by dotted name."""
    return {module_name(p): p for pkg in (pkgs or (PKG,)) for p in sorted(pkg.rglob("*.py"))}


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


def import_graph(*pkgs: Path) -> dict[str, set[str]]:
    """Every import of every module in the packages (``reference_py`` when none is named), as
    absolute dotted names; read together, an import of one package's module from the other
    resolves to that module."""
    modules = python_modules(*pkgs)
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


def host_bench_imports(graph: dict[str, set[str]]) -> list[str]:
    """Every import of ``host_bench`` by a module of ``reference_py``."""
    return [f"{module} imports {target}" for module in sorted(graph)
            if module.split(".")[0] == "reference_py"
            for target in sorted(graph[module]) if target.split(".")[0] == "host_bench"]


def console_script_modules() -> set[str]:
    """The modules pyproject.toml's [project.scripts] install as commands."""
    scripts = tomllib.loads(PYPROJECT.read_text(encoding="utf-8"))["project"]["scripts"]
    return {target.split(":")[0] for target in scripts.values()}


def runs_as_main(path: Path) -> bool:
    """Whether the module compares ``__name__`` with ``"__main__"`` (it runs as a command)."""
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Compare):
            sides = [node.left, *node.comparators]
            if (any(isinstance(x, ast.Name) and x.id == "__name__" for x in sides)
                    and any(isinstance(x, ast.Constant) and x.value == "__main__" for x in sides)):
                return True
    return False


def cli_modules(modules: dict[str, Path]) -> set[str]:
    """The command-line modules: the console scripts, every module that runs as ``__main__``
    (``python -m``) and every package's ``__main__``."""
    return (console_script_modules() & set(modules)) | {
        name for name, path in modules.items()
        if name.split(".")[-1] == "__main__" or runs_as_main(path)}


def cli_import_violations(graph: dict[str, set[str]], clis: set[str]) -> list[str]:
    """Every import of a command-line module, but a package's ``__main__`` importing a command of
    its own package (``python -m reference_py`` is ``nte-ref``)."""
    bad = []
    for module in sorted(graph):
        own = module.rpartition(".")[0] + "." if module.endswith(".__main__") else None
        for target in sorted(graph[module] & clis):
            if target != module and not (own and target.startswith(own)):
                bad.append(f"{module} imports the command {target}")
    return bad


def sys_path_uses(modules: dict[str, Path]) -> list[str]:
    """Every ``sys.path`` (and ``from sys import path``) in the modules, as ``module:line``."""
    found = []
    for name, path in sorted(modules.items()):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            if (isinstance(node, ast.Attribute) and node.attr == "path"
                    and isinstance(node.value, ast.Name) and node.value.id == "sys") or (
                    isinstance(node, ast.ImportFrom) and node.module == "sys"
                    and any(alias.name == "path" for alias in node.names)):
                found.append(f"{name}:{node.lineno} uses sys.path")
    return found


def folded(graph: dict[str, set[str]], home) -> dict[str, set[str]]:  # type: ignore[no-untyped-def]
    """The graph of the modules' homes (``home(module)``: the package holding it, say): an
    import between modules of two homes is an arrow between the homes; imports outside the
    graph are dropped."""
    out: dict[str, set[str]] = {}
    for module, targets in graph.items():
        out.setdefault(home(module), set()).update(home(t) for t in targets if t in graph)
    return {h: {t for t in ts if t != h} for h, ts in out.items()}


def package_graph(graph: dict[str, set[str]], modules: dict[str, Path]) -> dict[str, set[str]]:
    """Modules folded into the package whose folder holds them (a package's ``__init__`` is the
    package itself); a package's ``__main__`` stays its own node: the door on the top floor
    (``python -m reference_py`` runs the tools' command), not part of the package's floor."""
    packages = {name for name, path in modules.items() if path.name == "__init__.py"}
    return folded(graph, lambda m: m if m in packages or m.endswith(".__main__")
                  else m.rpartition(".")[0])


def top_level_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """Modules folded into their top-level package (``reference_py``, ``host_bench``)."""
    return folded(graph, lambda m: m.split(".")[0])


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


def test_reference_py_never_imports_host_bench():
    assert host_bench_imports(import_graph(*PRODUCT)) == []


def test_no_module_imports_a_command():
    modules = python_modules(*PRODUCT)
    clis = cli_modules(modules)
    assert {"reference_py.tools.cli", "host_bench.cli", "reference_py.discrepancy.cli",
            "reference_py.__main__"} <= clis
    assert cli_import_violations(import_graph(*PRODUCT), clis) == []


def test_no_product_module_mentions_sys_path():
    assert sys_path_uses(python_modules(*PRODUCT)) == []


def test_no_import_cycle_in_the_product():
    """Modules, the packages that hold them and the two top-level packages: each a floor above
    what it imports."""
    graph = import_graph(*PRODUCT)
    assert find_cycle(internal_graph(graph)) is None
    assert find_cycle(package_graph(graph, python_modules(*PRODUCT))) is None
    assert find_cycle(top_level_graph(graph)) is None


#: the longest a product module may be (issue 25): one job per file; a module that grows past it
#: is doing two
MODULE_LINES_MAX = 700


def _long_modules(roots: list[Path], base: Path = ROOT) -> list[tuple[str, int]]:
    out = []
    for root in roots:
        for f in sorted(root.rglob("*.py")):
            n = len(f.read_text().splitlines())
            if n > MODULE_LINES_MAX:
                out.append((str(f.relative_to(base)), n))
    return out


def test_no_product_module_longer_than_the_limit():
    assert _long_modules([ROOT / "reference_py", ROOT / "host_bench"]) == []


def test_the_length_rule_flags_a_long_module(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "long.py").write_text("x = 1\n" * (MODULE_LINES_MAX + 1))
    (pkg / "short.py").write_text("x = 1\n" * MODULE_LINES_MAX)
    assert _long_modules([pkg], tmp_path) == [("pkg/long.py", MODULE_LINES_MAX + 1)]


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
    graph["reference_py.model"] = graph["reference_py.model"] | {"reference_py.sim.simulate",
                                                                 "scipy.optimize"}
    bad = twin_violations(graph)
    assert "reference_py.model imports reference_py.sim.simulate" in bad
    assert "reference_py.model imports scipy.optimize" in bad


def test_import_resolution_sees_relative_and_lazy_imports():
    graph = import_graph()
    assert "reference_py.sim.simulate" in graph["reference_py.tools.cli"]  # inside a function
    assert "reference_py.params" in graph["reference_py.tools.cli"]          # from ..params
    assert "reference_py.starts" in graph["reference_py.tools.evaluation"]   # from .. import starts


def test_product_rules_flag_what_they_forbid():
    graph = import_graph(*PRODUCT)
    graph["reference_py.tools.csvio"] = graph["reference_py.tools.csvio"] | {"host_bench.replay",
                                                                           "reference_py.tools.cli"}
    assert "reference_py.tools.csvio imports host_bench.replay" in host_bench_imports(graph)
    clis = cli_modules(python_modules(*PRODUCT))
    bad = cli_import_violations(graph, clis)
    assert "reference_py.tools.csvio imports the command reference_py.tools.cli" in bad
    assert not any(b.startswith("reference_py.__main__ ") for b in bad)  # its own command
    graph["host_bench.__main__"] = {"reference_py.tools.cli"}            # not its package's
    assert ("host_bench.__main__ imports the command reference_py.tools.cli"
            in cli_import_violations(graph, clis))
    assert find_cycle(top_level_graph(graph)) is not None                # csvio -> replay -> ...


def test_cli_and_sys_path_finders_read_the_source(tmp_path):
    (tmp_path / "tool.py").write_text('import sys\nif "__main__" == __name__:\n    pass\n')
    (tmp_path / "lib.py").write_text("from sys import path\n")
    (tmp_path / "plain.py").write_text("import sys\nsys.exit(0)\n")
    modules = {p.stem: p for p in tmp_path.glob("*.py")}
    assert runs_as_main(modules["tool"]) and not runs_as_main(modules["lib"])
    assert cli_modules(modules) == {"tool"}
    assert sys_path_uses(modules) == ["lib:1 uses sys.path"]
    (tmp_path / "plain.py").write_text("import sys\nsys.path.insert(0, '.')\n")
    assert sys_path_uses(modules) == ["lib:1 uses sys.path", "plain:2 uses sys.path"]


def test_package_graph_sees_a_cycle_between_packages():
    graph = {"p.a": {"q.b"}, "q.b": set(), "q.c": {"p.d"}, "p.d": set()}
    assert find_cycle(internal_graph(graph)) is None                     # no module cycle...
    modules = {m: Path(m.replace(".", "/") + ".py") for m in graph}
    assert find_cycle(package_graph(graph, modules)) == ["p", "q", "p"]  # ...a package cycle


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
