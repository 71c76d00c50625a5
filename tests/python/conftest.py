import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
os.environ.setdefault("MPLBACKEND", "Agg")

import vcan_session  # noqa: E402  (its session hooks: tests/conftest.py)


@pytest.fixture(scope="session")
def vcan_env():
    """Environment for host_bench/with-vcan commands that run in the session's one kernel."""
    try:
        return vcan_session.env()
    except vcan_session.BusUnavailable as e:
        pytest.fail(str(e))
