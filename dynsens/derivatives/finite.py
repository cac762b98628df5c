"""Non-finite sensitivities stop the run where they appear, named in the case's words.

The direct mode checks one sum per trail block (NaN or Inf anywhere makes it non-finite) and
only then looks for the first record, field, equation and design variable; the adjoint checks
each step's multipliers μ (one sum per record) and names the step and the response.  Either
way a non-finite gradient never reaches a result, and the message says where it began, also
when no sensitivity histories are stored.
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from ..errors import NonFiniteError
from ..models.base import Model, StepState
from ..timeloop.stepping import HISTORY_FIELDS, StepRecord, equation_offsets

_WHY = ("the design derivative of the model is not finite there (an entry's derivative at this design "
        "or state, e.g. sqrt or a power of a variable at 0); the run is failed, not completed")


def all_finite(*arrays: np.ndarray) -> bool:
    """True when the arrays hold no NaN or Inf (one sum each; an overflowing sum of finite
    entries also reads as non-finite, and :func:`first_nonfinite` then finds nothing)."""
    return all(bool(np.isfinite(np.sum(a))) for a in arrays if a.size)


def _variable(names: Sequence[str], j: int) -> str:
    return f"'{names[j]}'" if j < len(names) else f"design variable #{j}"


def first_nonfinite(model: Model, trail: Sequence[StepRecord], ds_of: Sequence[StepState | None],
                    design_part: np.ndarray | None, names: Sequence[str]) -> None:
    """Raise NonFiniteError at the first record of ``trail`` whose sensitivity state (``ds_of``)
    has a NaN or Inf: its step, time, field, equation (:meth:`Model.describe_equation`) and
    design variable; ``design_part`` (records, n_z, m) says whether the model's design
    derivative there is the cause.  Returns when every entry is finite."""
    offsets = equation_offsets(model)
    for k, (rec, ds) in enumerate(zip(trail, ds_of)):
        if ds is None:
            continue
        for field, v in zip(HISTORY_FIELDS, ds):
            bad = np.argwhere(~np.isfinite(v))
            if not bad.size:
                continue
            row, j = (int(bad[0][0]), int(bad[0][1])) if v.ndim == 2 else (int(bad[0][0]), 0)
            cause = ""
            if design_part is not None and k < len(design_part) and not np.all(np.isfinite(design_part[k])):
                cause = " (the design derivative of the residual is not finite at this step)"
            raise NonFiniteError(
                f"the sensitivities with respect to {_variable(names, j)} went non-finite first at step "
                f"{rec.step} (t = {rec.t:.6g} s), in the derivative of {field} of "
                f"{model.describe_equation(offsets[field] + row)}{cause}: {_WHY}")


def nonfinite_adjoint(rec: StepRecord | None, mu: np.ndarray, responses: Sequence[str], what: str) -> None:
    """Raise NonFiniteError for adjoint multipliers ``mu`` (n, r) with a NaN or Inf, naming the
    responses whose columns are non-finite and the step (``rec``) or the stage (``what``)."""
    cols = np.flatnonzero(~np.all(np.isfinite(np.reshape(mu, (-1, len(responses)))), axis=0)) \
        if len(responses) else np.zeros(0, int)
    names = ", ".join(f"'{responses[int(c)]}'" for c in cols) or "a response"
    where = f"at step {rec.step} (t = {rec.t:.6g} s)" if rec is not None else what
    raise NonFiniteError(f"the adjoint of response {names} went non-finite {where} (sweeping back from "
                         f"t_end): {_WHY}")


def check_adjoint_step(rec: StepRecord, mu: np.ndarray, responses: Sequence[str]) -> None:
    """One sum over μ of a step; the message only when it is not finite."""
    if not all_finite(mu):
        if np.all(np.isfinite(mu)):      # finite entries whose sum overflowed
            return
        nonfinite_adjoint(rec, mu, responses, "")


def check_adjoint_gradient(xbar: np.ndarray, responses: Sequence[str], what: str) -> None:
    """x̄ (m, r) after a block of records (``what``: which steps) must stay finite."""
    if not np.all(np.isfinite(xbar)):
        nonfinite_adjoint(None, xbar, responses, what)


def check_block(model: Model, trail: Sequence[StepRecord], ds_of: Sequence[StepState | None],
                last: Any, design_part: np.ndarray | None, names: Sequence[str]) -> None:
    """One sum per block: the last sensitivity state and scheme memory ``last`` (a NaN or Inf
    anywhere before is carried into it) and the multipliers' sensitivities of every record
    (which nothing carries forward); on a non-finite sum, find the first entry."""
    lam = [ds.lam for ds in ds_of if ds is not None and ds.lam.size]
    if all_finite(*last, *lam):
        return
    first_nonfinite(model, trail, ds_of, design_part, names)
