"""The workflow's independent fits on worker processes (reference_py/discrepancy/pool.py,
``nte-discrepancy --jobs``): the result is the same bit for bit whatever the number of workers,
the work really runs in other processes, and they are gone when the run ends."""
import json
import os
from pathlib import Path

import numpy as np
import pytest

from discrepancy_measured_like import make_case

from reference_py.discrepancy import workflow
from reference_py.discrepancy.cli import main
from reference_py.discrepancy.effects import StateCache
from reference_py.discrepancy.pool import FitPool, available_cpus


def _pid_and_sum(a: float, b: float, grids: list, y: np.ndarray, cache: StateCache
                 ) -> tuple[int, float]:
    return os.getpid(), a + b + float(np.sum(y)) + len(grids) + cache.substeps


def test_pool_runs_tasks_in_other_processes_in_order_and_stops_them():
    y = np.array([1.0, 2.0])
    args = [(float(k), 0.5) for k in range(6)]
    with FitPool(["g"], y, StateCache(4), jobs=2) as pool:
        out = pool.map(_pid_and_sum, args)
        workers = {pid for pid, _ in out}
    # every value in the order given, computed against the pool's own grids and rows
    assert [v for _, v in out] == [k + 0.5 + 3.0 + 1 + 4 for k in range(6)]
    assert os.getpid() not in workers and 1 <= len(workers) <= 2
    for pid in workers:                 # joined on leaving the pool: no process is left
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
    # one job (or one task): everything in this process, with the caller's cache
    serial = FitPool(["g"], y, StateCache(7), jobs=1)
    assert serial.map(_pid_and_sum, args[:2]) == [(os.getpid(), k + 0.5 + 3.0 + 1 + 7)
                                                  for k in range(2)]
    assert available_cpus() >= 1


def _summary(res: workflow.Result) -> list:
    """Everything the fits decide: the named effects, every fit's values, coefficients and SSE,
    and the scores of the last round."""
    fits = [(f.effects, {k: np.asarray(v).tolist() for k, v in f.nl.items()}, f.coef, f.sse,
             f.k) for f in res.fits]
    return [res.named, fits, res.last_round, res.validation]


def test_two_workers_give_the_same_result_bit_for_bit():
    # measured-like seed 31 (three trials: tears, relaxation, pre-sliding, so several rounds
    # with screens and refines); its serial run is the reference
    trials = make_case(31, trials=3).trials
    one = workflow.run(trials, jobs=1)
    two = workflow.run(trials, jobs=2)
    assert len(one.named) >= 2
    assert _summary(two) == _summary(one)


def test_cli_jobs_do_not_change_the_report_or_its_figures(tmp_path: Path):
    from config_loop_figures import write_record
    case = make_case(32, trials=2)
    files = []
    for k, tr in enumerate(case.trials):
        f = tmp_path / f"t{k}.csv"
        write_record(f, tr.t_s, tr.depth_mm, tr.force_n)
        files.append(str(f))
    reports = []
    for jobs in (1, 2):
        out = tmp_path / f"j{jobs}"
        assert main(files + ["--out", str(out), "--jobs", str(jobs)]) == 0
        rep = json.loads((out / "report.json").read_text())
        rep.pop("runtime_s")
        figures = [(out / name).read_bytes() for name in rep["figures"]]
        reports.append((rep, (out / "estimator_config.json").read_bytes(), figures))
    assert len(reports[0][2]) == 2 and all(len(b) > 10_000 for b in reports[0][2])
    assert reports[0] == reports[1]
    # the safe writer's temporary files, written by the figure workers, all renamed
    assert sorted(q.name for q in (tmp_path / "j2").iterdir()) == sorted(
        ["report.json", "report.md", "estimator_config.json", *reports[0][0]["figures"]])
