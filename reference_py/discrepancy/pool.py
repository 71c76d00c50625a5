"""The independent fits of one condition on worker processes (``nte-discrepancy --jobs``).

The workflow fits the base model from several starts, screens every candidate effect from each
of its starts and refines the best two of a round: fits that read the same grids and rows and do
not depend on each other.  One process does the rest (naming, judging, the report) in order.
On a 2-core machine two workers take a six-trial condition of measured-like records from 9.4 s
to 7.1 s of wall time (README, "Both cores").

Why the results do not depend on ``jobs``: every fit (fit.fit) keeps its own warm start, and the
state cache (effects.StateCache) only remembers values it would compute again bit for bit, so
a worker with a cache of its own returns the very Fit the parent would.  The results come back
in the order the tasks were given.  Workers are forked (Linux): they start with the parent's
modules and data, and the grids and rows are handed over once, when each worker starts, not
with every task."""
from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from typing import Any, Callable, Iterable

from ..fmath import Array
from .effects import StateCache, TrialGrid

#: a worker's condition (grids, rows y) and its own state cache, set once when it starts: a
#: worker runs one pool's tasks only, so this is the worker's whole context, not shared state
_WORKER: dict[str, Any] = {}


def available_cpus() -> int:
    """The CPUs this process may run on (its affinity mask where the OS has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:              # not Linux
        return os.cpu_count() or 1


def forked(jobs: int, **kw: Any) -> ProcessPoolExecutor:
    """An executor of ``jobs`` forked workers (the one kind the workflow's tools use: a forked
    worker starts with this process's modules and data, nothing is imported again)."""
    return ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("fork"),
                               **kw)


def _start_worker(grids: list[TrialGrid], y: Array, substeps: int) -> None:
    _WORKER.update(grids=grids, y=y, cache=StateCache(substeps))


def _in_worker(fn: Callable[..., Any], args: tuple) -> Any:
    return fn(*args, _WORKER["grids"], _WORKER["y"], _WORKER["cache"])


class FitPool:
    """``map(fn, args)`` calls fn(*a, grids, y, cache) for every a, in worker processes when
    ``jobs`` > 1 and there are at least two tasks, in this process otherwise (with ``cache``);
    results in the order of ``args``.  ``fn`` must be a module-level function (it is sent to
    the workers by name).  Use as a context manager: leaving it stops the workers."""

    def __init__(self, grids: list[TrialGrid], y: Array, cache: StateCache, jobs: int = 1
                 ) -> None:
        self.grids, self.y, self.cache = grids, y, cache
        self._executor: ProcessPoolExecutor | None = None
        if jobs > 1:
            self._executor = forked(jobs, initializer=_start_worker,
                                    initargs=(grids, y, cache.substeps))

    def map(self, fn: Callable[..., Any], args: Iterable[tuple]) -> list[Any]:
        tasks = list(args)
        if self._executor is None or len(tasks) < 2:
            return [fn(*a, self.grids, self.y, self.cache) for a in tasks]
        return list(self._executor.map(_in_worker, [fn] * len(tasks), tasks))

    def close(self) -> None:
        if self._executor is not None:
            self._executor.shutdown(wait=True, cancel_futures=True)
            self._executor = None

    def __enter__(self) -> FitPool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


__all__ = ["FitPool", "available_cpus", "forked"]
