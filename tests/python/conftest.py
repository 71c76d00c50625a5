import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
os.environ.setdefault("MPLBACKEND", "Agg")

import vcan_session  # noqa: E402  (tests/python is on sys.path under pytest's rootdir rules)


def pytest_configure(config: pytest.Config) -> None:
    # the controller (or a run without xdist) owns the session's kernel; workers inherit the
    # shared directory through the environment
    if not hasattr(config, "workerinput"):
        vcan_session.configure()


def pytest_unconfigure(config: pytest.Config) -> None:
    if not hasattr(config, "workerinput"):
        vcan_session.shutdown()


@pytest.fixture(scope="session")
def vcan_env():
    """Environment for host_bench/with-vcan commands that run in the session's one kernel."""
    try:
        return vcan_session.env()
    except vcan_session.BusUnavailable as e:
        pytest.fail(str(e))
