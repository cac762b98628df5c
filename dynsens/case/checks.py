"""Checks of a case that need the built model: values at the start design, run size, unused variables.

Range rules of numeric entries (a mass > 0, a joint axis not zero, ...) are checked on the
evaluated values, so an entry written as an expression (``mass: "m - 10"``) is held to the
same rule as a literal, here at the start design and again by ``run_case`` at every design
the optimizer or a finite difference evaluates.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from ..errors import ProblemCollector
from ..expressions.restricted import CONSTANTS, ExpressionError, compile_expression
from ..timeloop.runchecks import size_problem, stability_problem

if TYPE_CHECKING:
    from ..timeloop.march import RunPlan
    from ..models.base import Model
    from ..models.parameters import ParameterTable
    from .load import DesignVariable


#: keys whose value names something (a type, a body, an event, ...): a scalar
NAME_KEYS = frozenset({"type", "name", "kind", "body", "body_1", "body_2", "joint", "marker_1", "marker_2",
                       "scheme", "partials", "matrix", "event", "response", "frame", "direction",
                       "action", "location", "at", "derivative", "coordinate", "component", "objective",
                       "method", "dof", "element", "node", "marker"})
#: keys whose value is a name or a list of names
NAME_LIST_KEYS = frozenset({"dof", "dofs", "element", "nodes", "fixed", "history"})
_SCALARS = (str, int, float, bool, type(None))


def check_reference_types(node: Any, path: str, pc: ProblemCollector) -> None:
    """Every entry that names something is a name (or a list of names where lists are allowed),
    so that the builders never meet a list or mapping where they look a name up."""
    if isinstance(node, dict):
        for key, value in node.items():
            p = f"{path}.{key}" if path else str(key)
            # a recorded quantity may name several components
            listed = key in NAME_LIST_KEYS or (key == "component" and ".quantities[" in p)
            if listed and isinstance(value, list):
                bad = [v for v in value if not isinstance(v, _SCALARS)]
                if bad:
                    pc.add(p, f"expected a list of names, found an entry {bad[0]!r}")
                continue
            if key in NAME_KEYS and not isinstance(value, _SCALARS):
                pc.add(p, f"expected a name, found {type(value).__name__} {value!r}")
                continue
            check_reference_types(value, p, pc)
    elif isinstance(node, list):
        for i, value in enumerate(node):
            check_reference_types(value, f"{path}[{i}]", pc)


def reserved_message(name: str) -> str:
    """Problem text for a case name that is also a constant or function of the expressions."""
    what = f"the constant {name} = {CONSTANTS[name]:.6g}" if name in CONSTANTS else f"the function {name}()"
    return (f"expected a name that is not a constant or function of the expressions, found {name!r}: "
            f"expressions would read {what} instead; rename it (e.g. '{name}_')")


def check_start(design: Sequence[DesignVariable], table: ParameterTable, model: Model, scheme: Any,
                plan: RunPlan, pc: ProblemCollector) -> None:
    """Every entry finite and in range at the start design; the run's size within reason; dt
    within the stability limit of a conditionally stable scheme."""
    x0 = np.array([v.value for v in design], dtype=float)
    n0 = len(pc.problems)
    for path, message in table.check(x0):
        pc.add(path, f"{message} (at the start design)")
    why = size_problem(model.traits, plan, len(design))
    if why:
        pc.add("integrator.dt", why)
    if scheme is not None and len(pc.problems) == n0:
        why = stability_problem(model, scheme, plan, x0)
        if why:
            pc.add("integrator.dt", why)


def unused_design_variables(table: ParameterTable, responses: Any) -> tuple[str, ...]:
    """Design variables that no entry of the model and no response expression names."""
    used: set[str] = set()
    if isinstance(responses, list):
        for r in responses:
            if isinstance(r, dict) and r.get("type") == "expression":
                try:
                    used |= compile_expression(str(r.get("expression")), None).symbols
                except ExpressionError:
                    pass
    return tuple(n for n, deps in zip(table.design_names, table.design_dependents())
                 if not deps and n not in used)


def bounds_problem(lower: float, upper: float) -> str | None:
    """Why a design variable cannot have the bounds ``lower``, ``upper`` (swapped, or a span
    that overflows), or None."""
    if lower >= upper:
        return f"lower >= upper ({lower} >= {upper}): did you swap the bounds?"
    if not bounds_span_finite(lower, upper):
        return (f"expected bounds whose difference is a finite number, found lower {lower} and upper {upper} "
                "(upper - lower overflows)")
    return None


def bounds_span_finite(lower: float, upper: float) -> bool:
    """Whether finite bounds have a finite span: ``upper - lower`` of two finite bounds may
    overflow (±1e308), and the scaled design, the samples of a study and the KKT measure
    would then be inf or nan.  An absent (infinite) bound has no span to check."""
    if not (math.isfinite(lower) and math.isfinite(upper)):
        return True
    return math.isfinite(upper - lower)
