"""The case keys that choose the derivative mode: ``sensitivity.method`` and
``sensitivity.memory_budget`` (kept apart from the loader so that it stays one place to read)."""
from __future__ import annotations

import re
from typing import Any

from ..derivatives.checkpoints import DEFAULT_MEMORY_BUDGET
from ..errors import ProblemCollector

METHODS = ("direct", "adjoint", "auto")
_UNITS = {"": 1, "b": 1, "kb": 1e3, "mb": 1e6, "gb": 1e9, "kib": 2**10, "mib": 2**20, "gib": 2**30}
_SIZE = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*([a-zA-Z]*)\s*$")


MAX_MEMORY_BUDGET = 2.0 ** 62   # bytes: beyond any machine, and still an exact integer count


def derivative_settings(sens: dict[str, Any], pc: ProblemCollector) -> dict[str, Any]:
    """RunPlan fields ``method`` and ``memory_budget`` (bytes) from the ``sensitivity`` mapping;
    problems are reported under their key paths."""
    method = sens.get("method", "direct")
    if method not in METHODS:
        pc.add("sensitivity.method", f"expected one of {', '.join(METHODS)}, found {method!r}")
        method = "direct"
    budget = sens.get("memory_budget", DEFAULT_MEMORY_BUDGET)
    value = None
    try:        # a size too large for a float (10**400, "1e400 GiB") is no size: refused below
        if isinstance(budget, (int, float)) and not isinstance(budget, bool):
            value = float(budget)
        elif isinstance(budget, str) and (m := _SIZE.match(budget)) and m.group(2).lower() in _UNITS:
            value = float(m.group(1)) * _UNITS[m.group(2).lower()]
    except OverflowError:
        value = None
    if value is None or not 0 < value <= MAX_MEMORY_BUDGET:
        pc.add("sensitivity.memory_budget",
               f"expected a positive size in bytes or with a unit (e.g. 2 GiB, 500 MB; finite, at most "
               f"2**62 = {int(MAX_MEMORY_BUDGET)} bytes), found {budget!r}")
        value = DEFAULT_MEMORY_BUDGET
    return {"method": str(method), "memory_budget": value}


def adjoint_problems(method: str, unsupported: list[str], pc: ProblemCollector) -> None:
    """``sensitivity.method: adjoint`` on a case the adjoint does not cover yet: one problem."""
    if method == "adjoint" and unsupported:
        pc.add("sensitivity.method", f"the adjoint does not cover {'; '.join(unsupported)} yet: "
                                     "use direct (or auto, which falls back to direct)")
