"""Session hooks for the whole suite.  They live here, not in tests/python/conftest.py, because
pytest loads this file before xdist starts its workers (`pytest tests`): the controlling process
must create the bus session's shared directory before the workers start (they inherit it through
the environment) and must stop the session's kernel after they have all finished."""
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "python"))
import vcan_session  # noqa: E402


def pytest_configure(config: pytest.Config) -> None:
    if not hasattr(config, "workerinput"):       # the controller, or pytest without xdist
        vcan_session.configure()


def pytest_unconfigure(config: pytest.Config) -> None:
    if not hasattr(config, "workerinput"):
        vcan_session.shutdown()


#: The files that take longest, longest first, with their seconds (setup included) in the CI
#: run of 36cde50 on a 2-core AMD EPYC (`--junitxml`).  `make test` runs the files two at a time
#: (`--dist loadfile`), each file whole on one worker; xdist's default order puts the files
#: with most tests first, which started test_export_twins.py (5 tests, 18.5 min) last, and the
#: other worker stood idle for most of those minutes (pytest 3 026 s on 10a4567).  Started
#: first, a long file runs beside all the short ones: 2 758 s for 5 485 s of tests on two
#: workers.  A file missing here only starts later; nothing depends on the order.
LONGEST_FIRST = (
    "test_export_twins.py",      # 1 110 s
    "test_run_units.py",         # 404 s
    "test_robust.py",            # 368 s
    "test_config_loop.py",       # 357 s
    "test_node_vcan.py",         # 282 s
    "test_cli.py",               # 211 s
    "test_c_bitidentity.py",     # 153 s
)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The files of LONGEST_FIRST first, in its order, then the others with most tests first
    (the order xdist would choose; the Makefile passes --no-loadscope-reorder so that it keeps
    this one).  A stable sort: the tests of a file keep their order."""
    def file_name(item: pytest.Item) -> str:
        return item.nodeid.split("::", 1)[0].rsplit("/", 1)[-1]
    count: dict[str, int] = {}
    for item in items:
        count[file_name(item)] = count.get(file_name(item), 0) + 1

    def rank(item: pytest.Item) -> tuple[int, int, str]:
        name = file_name(item)
        first = LONGEST_FIRST.index(name) if name in LONGEST_FIRST else len(LONGEST_FIRST)
        return first, -count[name], item.nodeid.split("::", 1)[0]
    items.sort(key=rank)
