"""Running a study: every design an independent task, rows written as they finish."""
from __future__ import annotations

import os
import socket
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..case.load import Case
from ..executor import cached_case, make_executor, remember_case
from ..io.hdf5 import OutputExistsError
from ..io.paths import check_output_path, writer_lock
from ..simulation import run_case
from .sampling import StudyError, sample_designs
from .store import (StudyTable, append_row, create_study_file, prepare_resume, read_study, set_response_units,
                    set_status)


@dataclass
class DesignTask:
    """One design of a study; picklable (the case travels as its YAML text)."""

    index: int
    case_text: str
    case_source: str
    x: np.ndarray
    gradients: bool
    run: int = 0


def evaluate_design(task: DesignTask) -> dict[str, Any]:
    """Simulate one design; never raises for a design that cannot be simulated.

    Returns the row: ``index``, ``x`` (m,), ``values`` (n_r,), ``gradients`` (n_r, m)
    when asked, ``failed``, ``message`` (the error, or the missing responses and why),
    ``wall_time`` (s), ``run``, ``worker`` and ``units`` (response units, not stored per row).
    """
    case = cached_case(task.case_text, task.case_source)
    t0 = time.perf_counter()                  # the simulation's own time (not the worker's first case load)
    m, names = len(task.x), case.response_names
    values = np.full(len(names), np.nan)
    grads = np.full((len(names), m), np.nan)
    failed, message, units = False, "", {}
    try:
        res = run_case(case, np.asarray(task.x, dtype=float), sensitivities=task.gradients, history=())
    except Exception as exc:  # noqa: BLE001 -- a design that fails is a result of the study, not an error of it
        failed, message = True, f"{type(exc).__name__}: {exc}"
    else:
        notes = []
        for i, n in enumerate(names):
            r = res.responses[n]
            units[n] = r.unit
            if r.missing:
                notes.append(f"{n} missing ({r.missing})")
                continue
            values[i] = float(np.real(r.value))
            if task.gradients and r.gradient is not None:
                grads[i] = np.real(r.gradient)
        message = "; ".join(notes)
    return {"index": task.index, "x": np.asarray(task.x, dtype=float), "values": values,
            "gradients": grads if task.gradients else None, "failed": failed, "message": message,
            "wall_time": time.perf_counter() - t0, "run": task.run,
            "worker": f"{socket.gethostname()}:{os.getpid()}", "units": units}


def run_study(case: Case, output: str | Path, sample: str | None = None, *, gradients: bool = False,
              seed: int | None = None, workers: int | None = None, scheduler: str | None = None,
              resume: bool = False, overwrite: bool = False,
              on_row: Callable[[dict[str, Any], int, int], None] | None = None) -> StudyTable:
    """Evaluate ``case`` at every design of ``sample``; one row per design appended to ``output``.

    Parameters
    ----------
    case : the case; its bounds span lhs/sobol/grid samples.
    output : STUDY.h5, created atomically, then appended as designs finish (any order).
    sample : ``lhs:N``, ``sobol:N``, ``grid:AxBx…`` or a CSV file (see
        :func:`~dynsens.study.sampling.sample_designs`); with ``resume`` it may be omitted.
    gradients : also compute the design gradients (the case's sensitivity method).
    seed : seed of lhs/sobol (default: drawn and stored).
    workers, scheduler : local processes or a Dask scheduler (:func:`dynsens.executor.make_executor`).
    resume : continue ``output``: only the designs without a row are computed.
    overwrite : replace an existing ``output``.
    on_row : called in this process after each row is on disk, with (row, rows done, rows planned).

    A design whose simulation fails is a row with ``failed`` set and the reason; it does
    not stop the study.  Ctrl-C (or any error of the study itself) leaves the file with
    status ``interrupted`` and every finished row.  One writer at a time: while another
    process writes ``output`` (a study or an optimization), this one is refused at once with
    :class:`~dynsens.io.paths.OutputLockedError` and touches nothing.
    """
    if resume and overwrite:
        raise StudyError("--resume continues OUTPUT and --overwrite replaces it: give one of them")
    # the name and folder first (a name too long must not reach a lookup), then one writer at a time:
    # a second study (new, --overwrite or --resume) of the same file is refused before it reads or writes it
    path = check_output_path(output, overwrite=True)
    with writer_lock(path):
        return _run_locked(case, path, sample, gradients, seed, workers, scheduler, resume, overwrite, on_row)


def _run_locked(case: Case, path: Path, sample: str | None, gradients: bool, seed: int | None,
                workers: int | None, scheduler: str | None, resume: bool, overwrite: bool,
                on_row: Callable[[dict[str, Any], int, int], None] | None) -> StudyTable:
    """:func:`run_study` once its output is checked and locked."""
    if resume:
        designs, done, run, sample, seed = prepare_resume(path, case, sample, seed, gradients)
    else:
        if sample is None:
            raise StudyError("a study needs --sample (lhs:N, sobol:N, grid:AxB... or a CSV file)")
        if path.exists() and not overwrite:
            raise OutputExistsError(f"{path} exists: pass --overwrite to replace it, or --resume to continue it")
        if seed is None and sample.split(":")[0].strip().lower() in ("lhs", "sobol"):
            seed = int(np.random.default_rng().integers(2 ** 31))   # drawn, then stored with the study
        designs = sample_designs(case, sample, seed)
        create_study_file(path, case, designs, sample, seed, gradients, overwrite)
        done, run = set(), 0
    todo = [i for i in range(len(designs)) if i not in done]
    tasks = [DesignTask(i, case.text, case.source, designs[i], gradients, run) for i in todo]
    remember_case(case)
    set_status(path, "running", f"{len(done)} of {len(designs)} designs done")
    count = [len(done)]
    units_known = [False]

    def store(_: int, row: dict[str, Any]) -> None:
        if not units_known[0] and row["units"]:
            set_response_units(path, row["units"])
            units_known[0] = True
        append_row(path, row)
        count[0] += 1
        if on_row is not None:
            on_row(row, count[0], len(designs))

    try:
        if tasks:
            with make_executor(workers, scheduler, tasks=len(tasks)) as executor:
                executor.run(evaluate_design, tasks, store)
    except BaseException as exc:
        why = "interrupted" if isinstance(exc, KeyboardInterrupt) else f"{type(exc).__name__}: {exc}"
        set_status(path, "interrupted", f"{why}; {count[0]} of {len(designs)} designs done: "
                                        "continue with --resume")
        raise
    table = read_study(path)
    n_failed = int(table.failed.sum())
    set_status(path, "completed", f"{len(designs)} designs, {n_failed} failed")
    table.status = "completed"
    return table
