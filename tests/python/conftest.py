import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
os.environ.setdefault("MPLBACKEND", "Agg")
# one BLAS thread per process, as `make test` and nte-discrepancy have it: the discrepancy
# fits are many small solves, and a threaded BLAS on a loaded 2-core machine spins instead
# (stick-slip case 10 with its 40 layers: 15 s, and over 15 min with the threads)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import vcan_session  # noqa: E402  (its session hooks: tests/conftest.py)


@pytest.fixture(scope="session")
def vcan_env():
    """Environment for host_bench/with-vcan commands that run in the session's one kernel."""
    try:
        return vcan_session.env()
    except vcan_session.BusUnavailable as e:
        pytest.fail(str(e))
