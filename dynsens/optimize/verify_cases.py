"""Verification of a design over named load cases.

A constraint ``RESPONSE@CASE`` holds in load case CASE, a transient with its own loads, initial
state, step and window.  So each load case is verified as a case of its own
(:func:`~dynsens.optimize.verify.verify_from`): its own run, its step divided by ``refine``, its
window extended from its own end, and its window less the tail; every constraint of that load
case is checked in those runs with the optimizer's scaling, and its members at every stored
step.  The design passes when it passes in every load case: a constraint that fails in one load
case at the refined step or on the longer window fails the design, as for a single case.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from typing import Any, Union, cast

import numpy as np

from ..case.load_cases import SEPARATOR, LoadCaseSet
from .problem import OptimizationError, ScaledProblem, build_problem
from .verify import (ConstraintCheck, Verification, base_run, check_verification_settings, format_verification,
                     store_verification, verify_from, write_constraint_table, write_verification)


@dataclass
class LoadCaseVerification:
    """The verification of one design in every load case.

    cases : load case name → its verification (constraint labels ``RESPONSE@CASE``);
    constraints : every constraint check in the optimizer's order (the same objects as in
        ``cases``), so that bounds can be tightened term by term.
    """

    x: np.ndarray
    refine: int
    cases: dict[str, Verification]
    constraints: list[ConstraintCheck]
    rounds: list[dict[str, Any]] = field(default_factory=list)   # optimization rounds (verified.py)

    @property
    def passed(self) -> bool:
        """The design passes the verification in every load case."""
        return all(v.passed for v in self.cases.values())

    @property
    def failing(self) -> list[str]:
        """The load cases in which the design does not pass."""
        return [n for n, v in self.cases.items() if not v.passed]

    @property
    def warnings(self) -> list[str]:
        """Every load case's warnings, each prefixed by its load case."""
        return [f"load case {n}: {w}" for n, v in self.cases.items() for w in v.warnings]


AnyVerification = Union[Verification, LoadCaseVerification]


def case_problem(problem: ScaledProblem, name: str) -> tuple[ScaledProblem, list[int]]:
    """The constraints of load case ``name`` (``RESPONSE@name``) as that load case's own problem
    (responses without the suffix, the optimizer's bounds and scaling), and their positions in
    ``problem.constraints``."""
    suffix = SEPARATOR + name
    positions = [i for i, t in enumerate(problem.constraints) if t.response.endswith(suffix)]
    terms = tuple(replace(problem.constraints[i], response=problem.constraints[i].response[:-len(suffix)])
                  for i in positions)
    return replace(problem, constraints=terms), positions


def verify_load_cases(cases: LoadCaseSet, x: Any = None, *, refine: int = 2, horizon: float | str | None = "auto",
                      tail: float = 0.1, problem: ScaledProblem | None = None) -> LoadCaseVerification:
    """Verify design ``x`` (default x0) in every load case of ``cases``, each at its step divided
    by ``refine`` and on its window extended (``horizon``: "auto", an end time in s, or None),
    every constraint ``RESPONSE@CASE`` in its own load case's runs.

    ``problem`` is the optimizer's scaled problem (default: built from the load cases' own runs
    at ``x``).  Raises OptimizationError naming the load case when its own run fails or a stated
    horizon does not lie beyond its window.
    """
    check_verification_settings(refine, tail)
    x = cases.x0 if x is None else np.asarray(x, dtype=float)
    bases = {n: base_run(c, x, f"load case {n} of the design") for n, c in cases.cases.items()}
    if problem is None:
        ref = {f"{r}{SEPARATOR}{n}": v for n, b in bases.items() for r, v in b.responses.items()}
        problem = build_problem(cast(Any, cases), ref)
    per_case: dict[str, Verification] = {}
    checks: list[ConstraintCheck | None] = [None] * len(problem.constraints)
    for name, case in cases.cases.items():
        sub, positions = case_problem(problem, name)
        try:
            v = verify_from(case, x, bases[name], sub, refine=refine, horizon=horizon, tail=tail)
        except OptimizationError as exc:
            raise OptimizationError(f"load case {name}: {exc}") from None
        for i, c in zip(positions, v.constraints):
            # named as the optimizer names it, so that a failure names its load case
            c.label, c.response = problem.constraints[i].label, problem.constraints[i].response
            checks[i] = c
        per_case[name] = v
    assert all(c is not None for c in checks)   # every response of a load-case problem is RESPONSE@CASE
    return LoadCaseVerification(np.asarray(x, dtype=float), refine, per_case, cast(list[ConstraintCheck], checks))


def format_any_verification(v: AnyVerification) -> str:
    """The verification (of one case, or per load case) as tables and plain sentences."""
    if isinstance(v, Verification):
        return format_verification(v)
    lines: list[str] = []
    for name, cv in v.cases.items():
        lines.append(f"load case {name}: " + ("passes" if cv.passed else "does NOT pass"))
        lines += ["  " + line for line in format_verification(cv, verdict=False).splitlines()]
    lines.append("The design PASSES the verification in every load case." if v.passed else
                 f"The design does NOT pass the verification in load case {', '.join(v.failing)}: a constraint "
                 "that holds only on the optimizer's time grid and window is not a result "
                 "(see docs/optimization.md).")
    return "\n".join(lines)


def store_any_verification(path: Any, v: AnyVerification, rounds: list[dict[str, Any]] | None = None) -> None:
    """Write ``v`` into the HDF5 file at ``path`` as the group ``/verification`` (replaced): one
    case in the layout of :func:`~dynsens.optimize.verify.write_verification`, load cases in that
    of :func:`write_over_cases`; ``rounds/`` when the bounds were tightened."""
    store_verification(path, v, rounds, write=write_verification if isinstance(v, Verification) else write_over_cases)


def write_over_cases(g: Any, v: LoadCaseVerification) -> None:
    """Write the verification over load cases ``v`` into the (empty) HDF5 group ``g``.

    Attributes ``passed`` (in every load case), ``refine``, ``warnings`` (JSON, each prefixed by
    its load case), ``x``, ``load_cases`` (JSON list of names) and ``failing`` (JSON list);
    ``constraints/{label, status, note, load_case}`` and ``value_<run>``, ``margin_<run>``: every
    constraint in the optimizer's order, each from its own load case's runs (NaN where a load case
    has no such run); ``load_cases/<name>/``: that load case's verification in the one-case layout.
    """
    import h5py
    g.attrs.update({"passed": v.passed, "refine": v.refine, "warnings": json.dumps(v.warnings),
                    "x": np.asarray(v.x, dtype=float), "load_cases": json.dumps(list(v.cases)),
                    "failing": json.dumps(v.failing)})
    runs = list(dict.fromkeys(r.name for cv in v.cases.values() for r in cv.runs))
    c = g.create_group("constraints")
    write_constraint_table(c, v.constraints, runs)
    case_of = {id(k): n for n, cv in v.cases.items() for k in cv.constraints}
    c.create_dataset("load_case", data=np.array([case_of[id(k)] for k in v.constraints], dtype=h5py.string_dtype()))
    for name, cv in v.cases.items():
        write_verification(g.create_group(f"load_cases/{name}"), cv)
