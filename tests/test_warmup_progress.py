"""The numba warm-up of `make setup` shows its progress (issue 37)."""
from __future__ import annotations

import pytest


def test_the_warm_up_announces_each_case_and_shows_it_is_alive(capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 37: `make setup`'s warm-up was silent for minutes; it now names each case before it
    starts and prints the elapsed time while numba compiles."""
    import time
    from dynsens.warmup import heartbeat
    with heartbeat("warming x.yaml (1/2)", every=0.05):
        time.sleep(0.3)
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "warming x.yaml (1/2) ..."
    assert len(out) >= 3 and all("s (compiling" in line for line in out[1:])


def test_the_parallel_plan_runs_each_run_once_and_keeps_the_arithmetics_apart() -> None:
    """`make setup` compiles in two processes (`--jobs 2`): the first stage puts the real runs and
    the complex-step runs (disjoint compiled functions) in different processes, the second the
    complex-partials runs (both arithmetics, cached by then); every run is planned exactly once."""
    from dynsens.warmup import CASES_DIR, RUNS, plan
    cases = [(CASES_DIR / "pendulum_3d.yaml", ()), (CASES_DIR / "four_bar.yaml", ()),
             (CASES_DIR / "duffing_chain.yaml", ("model.linear_algebra=sparse",))]
    serial = plan(cases, 1)[0][0]
    parallel = [t for stage in plan(cases, 2) for tasks in stage for t in tasks]
    assert sorted(map(repr, serial)) == sorted(map(repr, parallel)) and len(set(parallel)) == len(parallel)
    assert len(serial) == 2 * len(RUNS) + 1          # the structural chain: its real step only
    (real, cplx), second = plan(cases, 2)
    assert {t.run for t in real} == {"forward"} and "pendulum_3d.yaml" in {t.path.name for t in real}
    assert {t.run for t in cplx if t.path.name != "duffing_chain.yaml"} == {"complex-step"}
    assert {t.run for tasks in second for t in tasks} == {"complex"}


def test_the_parallel_warm_up_runs_in_processes_of_its_own(capsys: pytest.CaptureFixture[str]) -> None:
    from dynsens.warmup import CASES_DIR, warm_parallel
    assert warm_parallel([(CASES_DIR / "sdof_step.yaml", ())], steps=3, jobs=2) > 0.0
