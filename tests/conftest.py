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
