"""Optimization followed by its verification, and bounds tightened until the optimum holds.

An active constraint sits on its bound on the optimizer's time grid.  At half the step it moves
by the constraint's discretization error, in either direction; a peak after the window can
exceed it outright.  With ``optimization.verification.rounds`` > 0 the optimum is re-optimized,
from where it stands, with every bound the verification found violated tightened by the
shortfall it measured (times ``safety``): the margin is the measured error of the constraint,
not a guess.  Verification always judges against the case's own bounds.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, cast

import numpy as np
import yaml

from ..case.load import Case, load_case_dict
from ..case.load_cases import LoadCaseSet, load_any_text
from .problem import OptimizationError, ScaledProblem
from .runner import OptimizationResult, optimize_case
from .verify import excesses, verify_design
from .verify_cases import AnyVerification, store_any_verification, verify_load_cases


def tightened_case(case: Case, problem: ScaledProblem, bounds: dict[int, float]) -> Case:
    """``case`` with the bounds of constraint terms ``bounds`` (term index → new bound) replaced.

    A case with load cases gets one constraint entry per load case (``RESPONSE@all`` split), so
    that a bound is tightened only in the load case whose verification failed."""
    raw = yaml.safe_load(case.text)
    if any(problem.constraints[i].index < 0 for i in bounds):
        raise OptimizationError("the bounds cannot be tightened: the optimization file was written before "
                                "dynsens kept each constraint's entry; optimize without --resume")
    if isinstance(case, LoadCaseSet):
        raw["optimization"]["constraints"] = _entries_per_term(problem, bounds)
        tight = load_any_text(yaml.safe_dump(raw, sort_keys=False), case.source)
        tight.executor = case.executor
        return cast(Case, tight)
    for i, b in bounds.items():
        term = problem.constraints[i]
        raw["optimization"]["constraints"][term.index][term.kind] = float(b)
    return load_case_dict(raw, case.source)


def _entries_per_term(problem: ScaledProblem, bounds: dict[int, float]) -> list[dict[str, Any]]:
    """The ``optimization.constraints`` entries of ``problem``: one per (entry, response), with
    the bounds ``bounds`` (term index → bound) in place of the case's."""
    entries: dict[tuple[int, str], dict[str, Any]] = {}
    for i, t in enumerate(problem.constraints):
        entry = entries.setdefault((t.index, t.response), {"response": t.response})
        b = float(bounds.get(i, t.bound))
        if t.kind == "eq":
            entry["lower"] = entry["upper"] = b
        else:
            entry[t.kind] = b
    return list(entries.values())


def optimize_verified(case: Case, output: str | Path, *, verify: bool | None = None, rounds: int | None = None,
                      on_round: Callable[[int, AnyVerification], None] | None = None,
                      **optimize_kwargs: Any) -> tuple[OptimizationResult, AnyVerification | None]:
    """:func:`~dynsens.optimize.runner.optimize_case`, then :func:`verify_design` at the best design
    (:func:`~dynsens.optimize.verify_cases.verify_load_cases` for a case with load cases).

    Parameters
    ----------
    verify : run the verification (default: the case's ``optimization.verification.enabled``).
    rounds : re-optimizations with tightened bounds while the verification fails (default: the
        case's ``optimization.verification.rounds``); each starts from the last optimum, one start.
    on_round : called with (round, verification) after every verification (round 0: the first).
    optimize_kwargs : passed to ``optimize_case`` for the first round.

    Returns the last round's result (its file is ``output``; ``/verification`` holds the
    verification against the case's own bounds and, after tightening, a ``rounds`` table) and
    the verification (None when not run).
    """
    assert case.optimization is not None
    spec = case.optimization.verification
    result = optimize_case(case, output, **optimize_kwargs)
    if not (spec.enabled if verify is None else verify):
        return result, None
    n_rounds = spec.rounds if rounds is None else int(rounds)
    problem0 = result.problem             # the case's own bounds and scaling judge every round

    def check(res: OptimizationResult) -> AnyVerification:
        x = res.best_outcome.x
        if isinstance(case, LoadCaseSet):     # every load case at its own refined step and longer window
            return verify_load_cases(case, x, refine=spec.refine, horizon=spec.horizon, tail=spec.tail,
                                     problem=problem0)
        return verify_design(case, x, refine=spec.refine, horizon=spec.horizon, tail=spec.tail, problem=problem0)

    v = check(result)
    table = [_row(problem0, {}, result, v)]
    if on_round is not None:
        on_round(0, v)
    bounds: dict[int, float] = {}
    for k in range(1, n_rounds + 1):
        if v.passed or not np.isfinite(result.best_outcome.f):
            break
        for i, excess in excesses(v, problem0).items():
            term = problem0.constraints[i]
            bounds[i] = bounds.get(i, term.bound) + term.sign * spec.safety * excess
        tight = tightened_case(case, problem0, bounds)
        x_start = dict(zip(case.design_names, result.best_outcome.x))
        kwargs = {key: val for key, val in optimize_kwargs.items() if key not in ("starts", "x0", "resume", "seed")}
        kwargs["overwrite"] = True
        result = optimize_case(tight, output, x0=x_start, starts=1, seed=0, **kwargs)
        v = check(result)
        table.append(_row(problem0, bounds, result, v))
        if on_round is not None:
            on_round(k, v)
    v.rounds = table
    store_any_verification(output, v, table if len(table) > 1 else None)
    return result, v


def _row(problem: ScaledProblem, bounds: dict[int, float], result: OptimizationResult,
         v: AnyVerification) -> dict[str, Any]:
    b = result.best_outcome
    return {"bounds": [bounds.get(i, t.bound) for i, t in enumerate(problem.constraints)],
            "f": b.f, "passed": v.passed, "x": b.x, "nit": b.nit, "n_sim": b.n_sim, "wall_time": b.wall_time}
