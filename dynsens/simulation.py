"""Run a loaded case: the library entry point behind ``dynsens simulate``."""
from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np

from .case.load import Case
from .errors import CaseError, NonFiniteError
from .march import RunResult, integrate
from .runchecks import check_design, check_result, check_run_size, stability_problem
from .sensitivity_drift import sensitivity_constraint_residual


def run_case(case: Case, x: np.ndarray | None = None, *, sensitivities: bool | None = None,
             history: tuple[str, ...] | None = None,
             progress: Callable[[int, int], None] | None = None) -> RunResult:
    """Simulate ``case`` at design ``x`` (default: the case's initial design).

    Parameters
    ----------
    x : design (m,), real or complex (complex forces ``sensitivities=False``).
    sensitivities : override the case's ``sensitivity.enabled``.
    history : override which state histories are stored.

    Raises DesignError (an entry invalid at ``x``), RunSizeError (the run would not fit),
    NonFiniteError (a non-finite state, response value or gradient) with their context.
    """
    x = case.x0 if x is None else np.asarray(x)
    plan = case.plan
    if sensitivities is not None:
        plan = replace(plan, sensitivities=sensitivities)
    if np.iscomplexobj(x):
        plan = replace(plan, sensitivities=False)
    if history is not None:
        plan = replace(plan, history=history)
    check_design(case, x)
    check_run_size(case, plan)
    try:
        result = integrate(case.model, x, case.scheme, plan, case.new_response_set(),
                           design_names=case.design_names, design_scale=case.scale, progress=progress)
    except CaseError as exc:       # found by the model at run time (e.g. redundant joints): name the file
        if exc.source is not None:
            raise
        raise CaseError(exc.problems, case.source) from None
    except NonFiniteError as exc:  # name the stability limit when the scheme's is the cause
        why = stability_problem(case.model, case.scheme, plan, np.real(x))
        if why is None:
            raise
        raise NonFiniteError(f"{exc}. Cause: integrator.dt: {why}") from None
    check_result(case, result)
    if plan.sensitivity_history and result.sensitivity_history:
        drift = sensitivity_constraint_residual(case.model, result)
        if drift:
            result.monitors.update(drift)
    return result
