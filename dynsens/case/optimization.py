"""The ``optimization`` section of a case (objective, constraints, optimizer settings).

Validated at load time together with the rest of the case.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..errors import ProblemCollector
from ..case_keys import allowed
from ..models._keys import check_keys, did_you_mean
from .responses_spec import read_number


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
        # a bound is finite (nan would hold for no value): no bound is a key left out
        lo, up = (read_number(c[k], f"{p}.{k}", pc) if c.get(k) is not None else None for k in ("lower", "upper"))
        if c.get("lower") is None and c.get("upper") is None:
            pc.add(p, "give 'upper' (response <= upper) and/or 'lower'")
        elif lo is not None and up is not None and lo > up:
            pc.add(p, f"lower > upper ({lo} > {up}): did you swap the bounds?")
        cons.append(ConstraintSpec(str(name), lo, up))
    method = spec.get("method", "SLSQP")
    if method != "SLSQP":
        pc.add("optimization.method", f"only SLSQP is available, found {method!r}")
    maxiter = spec.get("maxiter", 100)
    if not isinstance(maxiter, int) or isinstance(maxiter, bool) or maxiter < 1:
        pc.add("optimization.maxiter", f"expected a positive integer, found {maxiter!r}")
    ftol = read_number(spec.get("ftol", 1e-6), "optimization.ftol", pc, positive=True)
    if len(pc.problems) > n0:
        return None
    return OptimizationSpec(str(obj), tuple(cons), method, maxiter, float(ftol or 0.0))   # None: returned above
