"""dynsens.executor: one interface, three places to run (this process, spawned processes, Dask).

Contract: every executor returns the same results for the same tasks (``map`` in task
order, ``run`` in completion order with the task's index); messages a task publishes reach
the caller in the order sent; a task that raises stops the run with its exception;
``make_executor`` runs in this process for one worker or one task; an unreachable
scheduler is one clean error.
"""
from __future__ import annotations

import os

import pytest

from dynsens.errors import DynsensError
from dynsens.executor import (DaskExecutor, ExecutorError, ProcessExecutor, SerialExecutor, make_executor,
                              publish)


def _square_and_tell(k: int) -> tuple[int, int]:
    for i in range(3):
        publish({"task": k, "seq": i})
    return k * k, os.getpid()


def _fail_on_three(k: int) -> int:
    if k == 3:
        raise ValueError("task 3 cannot")
    return k


@pytest.fixture(scope="module")
def dask_address():
    pytest.importorskip("distributed", reason="dask.distributed is in the test extra")
    from distributed import LocalCluster
    # threads in this process (processes=False) keep the test fast; the executor serializes
    # simulations per process, so this is also safe for real simulations
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0") as cluster:
        yield cluster.scheduler_address


def _executors(dask_address: str) -> list:
    return [SerialExecutor(), ProcessExecutor(2), DaskExecutor(dask_address)]


def test_every_executor_gives_the_same_results_and_messages(dask_address) -> None:
    tasks = list(range(6))
    for ex in _executors(dask_address):
        with ex:
            got: dict[int, int] = {}
            pids = set()
            messages: list[dict] = []

            def keep(i: int, r: tuple[int, int], got: dict[int, int] = got, pids: set = pids) -> None:
                got[i] = r[0]
                pids.add(r[1])
            ex.run(_square_and_tell, tasks, keep, messages.append)
            assert got == {k: k * k for k in tasks}, ex.description
            assert [r for r, _ in ex.map(_square_and_tell, tasks)] == [k * k for k in tasks]
        # each task's messages arrive, in the order it sent them
        for k in tasks:
            assert [m["seq"] for m in messages if m["task"] == k] == [0, 1, 2], ex.description
        if isinstance(ex, ProcessExecutor):
            assert os.getpid() not in pids                  # really in other processes
        if isinstance(ex, SerialExecutor):
            assert pids == {os.getpid()}


def test_a_failing_task_stops_the_run_with_its_error(dask_address) -> None:
    for ex in _executors(dask_address):
        with ex, pytest.raises(ValueError, match="task 3 cannot"):
            ex.map(_fail_on_three, list(range(5)))


def test_make_executor_choices() -> None:
    assert isinstance(make_executor(1), SerialExecutor)
    assert isinstance(make_executor(4, tasks=1), SerialExecutor)       # one task: no processes
    ex = make_executor(4, tasks=2)
    assert isinstance(ex, ProcessExecutor) and ex.workers == 2
    ex.close()
    assert isinstance(make_executor(None, default_workers=1), SerialExecutor)


def test_unreachable_scheduler_is_a_clean_error() -> None:
    pytest.importorskip("distributed")
    with pytest.raises(ExecutorError, match="cannot connect") as info:
        DaskExecutor("tcp://127.0.0.1:9", timeout=1)
    assert isinstance(info.value, DynsensError)


# --------------------------------------------------------------------------------------
# the commands behind it
# --------------------------------------------------------------------------------------
def test_check_gradients_and_convergence_on_dask_equal_this_process(dask_address, tmp_path) -> None:
    import json
    from pathlib import Path

    import numpy as np
    from click.testing import CliRunner

    import dynsens.cli.check_gradients  # noqa: F401  (registers the command)
    from dynsens.case.load import load_case
    from dynsens.cli.main import cli
    from dynsens.analysis.convergence import work_precision
    sdof = Path(__file__).resolve().parents[1] / "cases" / "sdof_step.yaml"
    reports = {}
    for how in (["--workers", "1"], ["--scheduler", dask_address]):
        stem = tmp_path / how[0].strip("-")
        r = CliRunner().invoke(cli, ["check-gradients", str(sdof), "--steps", "1e-4,1e-6", "--set",
                                     "integrator.t_end=1", "-o", str(stem), *how], catch_exceptions=False)
        assert r.exit_code == 0, r.output
        reports[how[0]] = json.loads(stem.with_suffix(".json").read_text())
    a, b = reports["--workers"], reports["--scheduler"]
    assert [c["gradients"] for c in a["columns"]] == [c["gradients"] for c in b["columns"]]
    case = load_case(sdof, ["integrator.t_end=1"])
    here, _, _ = work_precision(case, [0.004, 0.002], ["ddm-forward", "fd-forward"])
    there, _, _ = work_precision(case, [0.004, 0.002], ["ddm-forward", "fd-forward"], scheduler=dask_address)
    assert [(r.dt, r.method) for r in here] == [(r.dt, r.method) for r in there]
    for r, s in zip(here, there):
        assert r.values == s.values and all(np.array_equal(r.gradients[n], s.gradients[n]) for n in r.gradients)
