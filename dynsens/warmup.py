"""Compile the compiled kernels and steps once, into numba's on-disk cache: ``python -m dynsens.warmup``.

The compiled multibody kernel (``models/multibody/compiled.py``) is compiled on its first use on a
machine, real and complex separately, and so is the compiled step
that calls it (``models/multibody/compiled_step.py``; one signature for every mechanism)
and the compiled step of spring networks (``models/structural/step_kernels.py``; one signature
for every network) with its blocks of steps, and the compiled block of sensitivity steps
(``derivatives/direct_step.py``; one signature for every dense model); all are cached on disk
beside the package.  ``make setup`` runs this module
(``--jobs 2``) so that a user's first ``dynsens simulate`` takes as long as the second, and so that no
reported timing includes compilation.  It runs a short piece (``--steps`` steps) of each multibody
case with forward partials (real arithmetic), complex partials and a complex-step run of the whole
simulation (complex arithmetic), which reaches every compiled function with every argument type
the runs use, and of the shipped Duffing chain and slider-crank on the sparse path (the spring
networks' step, the sparse multibody linearization).  With ``--jobs 2`` the real and the complex
runs compile in two processes at once (:func:`plan`).  How long each compilation takes:
BENCHMARKS.md ("Figures moved from docstrings", "CI time").

Usage: python -m dynsens.warmup [CASE.yaml ...] [--steps N] [--jobs N]   (default: the shipped
mechanisms and the sparse paths, one process)
"""
from __future__ import annotations

import argparse
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import yaml

from .case.load import Case, load_case, load_case_dict
from .models.multibody.model import MultibodyModel
from .models.structural.model import StructuralModel
from .models.structural.step import serves
from .simulation import run_case

# the shipped mechanisms (together they use every joint, force law and driver the kernel knows,
# and the constraint projection's J_Φ)
DEFAULT_CASES = ("pendulum_3d", "slider_crank", "four_bar", "hydraulic_lever", "tyrolean_weir",
                 "pendulum_projection")
CASES_DIR = Path(__file__).resolve().parent.parent / "cases"
HEARTBEAT = 15.0     # s between the warm-up's "still compiling" lines


# the three runs of a mechanism: forward partials (real arithmetic), complex partials (a real run
# whose Jacobians are complex steps: both arithmetics) and a complex-step run of the whole
# simulation (complex arithmetic); together they reach every compiled function with every
# argument type the runs use
RUNS = ("forward", "complex-step", "complex")


def _short_case(case: Case, steps: int, run: str) -> tuple[Case, Any]:
    """``case`` cut to ``steps`` steps without histories, set up for ``run``; the design to run at."""
    raw = yaml.safe_load(case.text)
    over = [f"integrator.t_end={case.plan.t0 + steps * case.plan.dt!r}", "output.history=none"]
    if run != "complex-step":
        return load_case_dict(raw, case.source, over + [f"sensitivity.partials={run}"]), None
    short = load_case_dict(raw, case.source, over)
    x = short.x0.astype(complex)
    if x.size:
        x[0] += 1e-20j * max(abs(x[0]), 1.0)
    return short, x


def warm_run(case: Case, run: str, steps: int = 150) -> float:
    """Compile what one of the :data:`RUNS` of ``case`` needs; returns the wall time (s).

    Structural models compile only their spring networks' step (real runs: ``forward``)."""
    from .models.multibody import compiled
    if not compiled.enabled():
        return 0.0
    t0 = time.perf_counter()
    if isinstance(case.model, StructuralModel):
        if run == "forward" and serves(case.model):
            run_case(_short_case(case, steps, run)[0])     # (its steps run in blocks: those compile too)
    elif isinstance(case.model, MultibodyModel):
        run_case(*_short_case(case, steps, run))
    return time.perf_counter() - t0


def warm_case(case: Case, steps: int = 150) -> float:
    """Compile what ``case`` needs (nothing for structural models); returns the wall time (s).

    Called before every timed run (gradient check, work-precision study, Table 1, benchmarks) so
    that no reported time includes compilation; with a warm cache it costs a fraction of a second.
    """
    return sum(warm_run(case, run, steps) for run in RUNS)


@contextmanager
def heartbeat(what: str, every: float = HEARTBEAT, echo: bool = True) -> Iterator[None]:
    """Print ``what`` now and the elapsed time every ``every`` seconds until the block ends: a
    compilation of minutes shows that it is alive."""
    if not echo:
        yield
        return
    print(f"{what} ...", flush=True)
    done = threading.Event()
    t0 = time.perf_counter()

    def tick() -> None:
        while not done.wait(every):
            print(f"  ... {time.perf_counter() - t0:.0f} s (compiling; each kernel is compiled once)", flush=True)
    thread = threading.Thread(target=tick, daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()


def warm(paths: list[Path], steps: int = 150, echo: bool = True) -> float:
    """:func:`warm_case` for each case file, announcing each and its progress; returns the wall
    time (s)."""
    t0 = time.perf_counter()
    for i, path in enumerate(paths, 1):
        with heartbeat(f"warming {path.name} ({i}/{len(paths)})", echo=echo):
            dt = warm_case(load_case(path), steps)
        if echo:
            print(f"warmed {path.name}: {dt:.1f} s", flush=True)
    return time.perf_counter() - t0


# what the default warm-up compiles besides the mechanisms: the spring networks' compiled step and
# sensitivity blocks, direct and adjoint (the shipped chain made sparse), the sparse multibody
# linearization (a shipped mechanism made sparse) and the adjoint's dense block (a mechanism's
# adjoint run)
EXTRA_RUNS = (("duffing_chain", ("model.linear_algebra=sparse",)),
                 ("duffing_chain", ("model.linear_algebra=sparse", "sensitivity.method=adjoint")),
                 ("slider_crank", ("model.linear_algebra=sparse",)),
                 ("slider_crank", ("sensitivity.method=adjoint",)))


@dataclass(frozen=True)
class Task:
    """One run of the warm-up: a case file with overrides, and which of :data:`RUNS`."""
    path: Path
    overrides: tuple[str, ...]
    run: str

    def label(self) -> str:
        where = f" {' '.join(self.overrides)}" if self.overrides else ""
        return f"{self.path.name}{where} ({self.run})"


def plan(cases: list[tuple[Path, tuple[str, ...]]], jobs: int) -> list[list[list[Task]]]:
    """Stages of per-process task lists; the lists of a stage run at once, stage after stage.

    Two processes that compile one function at the same time both compile it; the stages keep
    them on different functions: first the real runs (forward partials: the real kernels and
    compiled steps) beside the complex-step runs (the complex kernels), then the complex-partials
    runs, which call both and find them in the cache."""
    # a structural model compiles only its real step, in a module of its own: it joins the
    # complex-step runs (a short list) as their counterpart
    structural = {i for i, (p, o) in enumerate(cases) if isinstance(load_case(p, list(o)).model, StructuralModel)}
    real = [Task(p, o, "forward") for i, (p, o) in enumerate(cases) if i not in structural]
    cplx = [Task(p, o, "complex-step") for i, (p, o) in enumerate(cases) if i not in structural] + \
        [Task(p, o, "forward") for i, (p, o) in enumerate(cases) if i in structural]
    both = [Task(p, o, "complex") for i, (p, o) in enumerate(cases) if i not in structural]
    if jobs <= 1:
        return [[real + cplx + both]]
    first: list[list[Task]] = [real, cplx] + [[] for _ in range(jobs - 2)]
    return [first, [both[i::jobs] for i in range(jobs)]]


def warm_tasks(tasks: list[Task], steps: int = 150, tag: str = "") -> list[tuple[str, float]]:
    """Run ``tasks`` one after the other in this process, announcing each and its progress;
    (label, wall time s) of each."""
    out = []
    for i, task in enumerate(tasks, 1):
        with heartbeat(f"{tag}warming {task.label()} ({i}/{len(tasks)})"):
            dt = warm_run(load_case(task.path, list(task.overrides)), task.run, steps)
        print(f"{tag}warmed {task.label()}: {dt:.1f} s", flush=True)
        out.append((task.label(), dt))
    return out


def warm_parallel(cases: list[tuple[Path, tuple[str, ...]]], steps: int = 150, jobs: int = 2) -> float:
    """Every run of ``cases`` in ``jobs`` processes, stage by stage (:func:`plan`); the wall time (s)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    t0 = time.perf_counter()
    # spawn: a fresh interpreter per process (no numba state copied from this one)
    with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
        for stage in plan(cases, jobs):
            futures = [pool.submit(warm_tasks, tasks, steps, f"[{k + 1}] ") for k, tasks in enumerate(stage) if tasks]
            for f in futures:
                f.result()
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> None:
    """Command-line entry point."""
    ap = argparse.ArgumentParser(prog="python -m dynsens.warmup", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("cases", nargs="*", type=Path,
                    help="case files (default: the shipped mechanisms and the sparse paths)")
    ap.add_argument("--steps", type=int, default=150, help="steps of each run (default 150)")
    ap.add_argument("--jobs", type=int, default=1, help="processes that compile at once (default 1; "
                                                        "`make setup` uses 2)")
    args = ap.parse_args(argv)
    from .models.multibody import compiled
    if not compiled.enabled():
        print("compiled kernel off (numba missing or DYNSENS_KERNEL=numpy): nothing to warm")
        return
    cases: list[tuple[Path, tuple[str, ...]]] = [(p, ()) for p in args.cases]
    if not args.cases:
        cases = [(CASES_DIR / f"{n}.yaml", ()) for n in DEFAULT_CASES] + \
            [(CASES_DIR / f"{n}.yaml", o) for n, o in EXTRA_RUNS]
        cases = [(p, o) for p, o in cases if p.exists()]
    if not cases:
        print("no case files found: pass the cases to warm")
        return
    jobs = max(1, args.jobs)
    print(f"compiling dynsens' numba kernels into the on-disk cache, once: {len(cases)} cases, "
          f"{len(RUNS)} runs each, in {jobs} process{'es' if jobs > 1 else ''}; about 3 min on 2 quiet cores "
          f"with --jobs 2 (5 with 1; twice that on a busy machine)", flush=True)
    if jobs == 1:
        t0 = time.perf_counter()
        warm_tasks(plan(cases, 1)[0][0], args.steps)
        total = time.perf_counter() - t0
    else:
        total = warm_parallel(cases, args.steps, jobs)
    print(f"numba cache warm ({total:.1f} s); later runs start at once", flush=True)


if __name__ == "__main__":
    main()
