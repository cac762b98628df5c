"""The ``optimization`` section of a case (objective, constraints, optimizer settings).

Validated at load time together with the rest of the case.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..errors import ProblemCollector
from ..case_keys import allowed
from ..models._keys import check_keys, did_you_mean


@dataclass(frozen=True)
class ConstraintSpec:
    """A response bounded as lower <= response <= upper (either bound may be absent)."""

    response: str
    lower: float | None = None
    upper: float | None = None


@dataclass(frozen=True)
class OptimizationSpec:
    """Objective (minimized), constraints and optimizer settings."""

    objective: str
    constraints: tuple[ConstraintSpec, ...] = ()
    method: str = "SLSQP"
    maxiter: int = 100
    ftol: float = 1e-6
    options: dict[str, Any] = field(default_factory=dict)


def validate_optimization(spec: Any, response_names: tuple[str, ...],
                          pc: ProblemCollector) -> OptimizationSpec | None:
    """Check the ``optimization`` mapping against the case's responses; None if absent or invalid."""
    if spec is None:
        return None
    if not check_keys(spec, "optimization", allowed("optimization"), pc,
                      required=("objective",)):
        return None
    n0 = len(pc.problems)
    obj = spec.get("objective")
    if obj not in response_names:
        pc.add("optimization.objective", f"unknown response {obj!r}{did_you_mean(obj, response_names)} "
                                         f"(responses: {', '.join(response_names)})")
    cons = []
    for i, c in enumerate(spec.get("constraints", []) or []):
        p = f"optimization.constraints[{i}]"
        if not check_keys(c, p, allowed("optimization.constraint"), pc, required=("response",)):
            continue
        name = c.get("response")
        if name not in response_names:
            pc.add(f"{p}.response", f"unknown response {name!r}{did_you_mean(name, response_names)}")
        lo, up = c.get("lower"), c.get("upper")
        for key, v in (("lower", lo), ("upper", up)):
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))):
                pc.add(f"{p}.{key}", f"expected a number, found {v!r}")
        if lo is None and up is None:
            pc.add(p, "give 'upper' (response <= upper) and/or 'lower'")
        elif lo is not None and up is not None and isinstance(lo, (int, float)) and isinstance(up, (int, float)) \
                and lo > up:
            pc.add(p, f"lower > upper ({lo} > {up}): did you swap the bounds?")
        cons.append(ConstraintSpec(str(name), lo, up))
    method = spec.get("method", "SLSQP")
    if method != "SLSQP":
        pc.add("optimization.method", f"only SLSQP is available, found {method!r}")
    maxiter = spec.get("maxiter", 100)
    if not isinstance(maxiter, int) or isinstance(maxiter, bool) or maxiter < 1:
        pc.add("optimization.maxiter", f"expected a positive integer, found {maxiter!r}")
    ftol = spec.get("ftol", 1e-6)
    if isinstance(ftol, bool) or not isinstance(ftol, (int, float)) or ftol <= 0:
        pc.add("optimization.ftol", f"expected a positive number, found {ftol!r}")
    if len(pc.problems) > n0:
        return None
    return OptimizationSpec(str(obj), tuple(cons), method, maxiter, float(ftol))
