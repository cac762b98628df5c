"""Run a loaded case: the library entry point behind ``dynsens simulate``."""
from __future__ import annotations

import logging
from dataclasses import dataclass, field, fields, replace
from typing import Callable

import numpy as np

from .case.load import Case
from .errors import CaseError, NonFiniteError
from .timeloop.march import RunResult, integrate
from .timeloop.records import RecordedQuantity, Recorder, quantities_read_by
from .timeloop.runchecks import check_design, check_result, check_run_size, unstable_scheme_note
from .derivatives.constraint_drift import sensitivity_constraint_residual

log = logging.getLogger(__name__)


@dataclass
class SimulationResult(RunResult):
    """A `RunResult` with the case's recorded quantities
    (``output.quantities``), by name, on the run's time grid."""

    quantities: dict[str, RecordedQuantity] = field(default_factory=dict)
    events: dict[str, float] = field(default_factory=dict)   # fired events: name -> time (s)

    @property
    def ended_by(self) -> str:
        """How the run ended, in words: "reached t_end = 12 s" or "ended by event E1 at t = 7.78 s"."""
        if self.events:
            name, t = next(reversed(self.events.items()))
            return f"ended by event {name} at t = {t:.6g} s"
        return self.message


def run_case(case: Case, x: np.ndarray | None = None, *, sensitivities: bool | None = None,
             history: tuple[str, ...] | None = None,
             progress: Callable[[int, int], None] | None = None,
             record: bool | None = None) -> SimulationResult:
    """Simulate ``case`` at design ``x`` (default: the case's initial design).

    Parameters
    ----------
    x
        Design (m,), real or complex (complex forces ``sensitivities=False``).
    sensitivities
        Override the case's ``sensitivity.enabled``.
    history
        Override which state histories are stored.
    progress
        Called as ``progress(step, n_steps)`` while the run advances.
    record
        Keep the recorded quantities (``output.quantities``; for a case that names none,
        the quantities its responses read); default: yes, unless ``history=()`` asks for a run
        that stores no time histories (as the finite-difference, optimization and convergence
        runs do).

    Raises
    ------
    DesignError
        An entry invalid at ``x``, with its context.
    RunSizeError
        The run would not fit, with its context.
    NonFiniteError
        A non-finite state, response value or gradient, with its context.
    """
    x = case.x0 if x is None else np.asarray(x)
    plan = case.plan
    if sensitivities is not None:
        plan = replace(plan, sensitivities=sensitivities)
    if np.iscomplexobj(x):
        plan = replace(plan, sensitivities=False)
    if history is not None:
        plan = replace(plan, history=history)
    if record is None:
        record = history is None or bool(history)
    check_design(case, x)
    check_run_size(case, plan)
    responses = case.new_response_set(record=record)
    if record and not case.quantities:
        specs = quantities_read_by(responses)
        if specs:
            responses.attach_recorder(Recorder(specs))
    try:
        run = integrate(case.model, x, case.scheme, plan, responses,
                        design_names=case.design_names, design_scale=case.scale, progress=progress)
    except CaseError as exc:       # found by the model at run time (e.g. redundant joints): name the file
        if exc.source is not None:
            raise
        raise CaseError(exc.problems, case.source) from None
    except NonFiniteError as exc:  # name the stability limit when the scheme's is the cause
        growth = any(w in str(exc) for w in ("grows without bound", "diverges"))
        why = unstable_scheme_note(case.model, case.scheme, plan, np.real(x), growth)
        if why is None:
            raise
        raise NonFiniteError(f"{exc}. Cause: integrator.dt: {why}") from None
    check_result(case, run)
    if plan.sensitivity_history and run.sensitivity_history:
        drift = sensitivity_constraint_residual(case.model, run)
        if drift:
            run.monitors.update(drift)
    quantities = responses.recorder.result() if responses.recorder is not None else {}
    events = {k: float(np.real(e.t)) for k, e in responses.fired.items()}
    log.debug("run at x = %s: %s, %.3f s", np.real(x), run.message, run.wall_time)
    return SimulationResult(**{f.name: getattr(run, f.name) for f in fields(run)}, quantities=quantities,
                            events=events)
