"""What an engineer decides on after ``dynsens optimize``: the objective's change, the final KKT
residual, which constraints and bounds are active, each constraint against its bound in its unit.

Read from the optimization file (the best start's last history row and outcome), so it can be
printed again for any finished file (:func:`decision_summary`).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ..case.families import member_parts
from .problem import ACTIVE_TOL, FEAS_TOL, ScaledProblem
from .store import read_history

BOUND_TOL = 1e-6    # a design variable within this fraction of its range of a bound is at it
LISTED = 30         # more rows than this: the summary lists the active and free ones only


DIMENSIONLESS = ("", "-", "1")


def _u(unit: str) -> str:
    """`` unit`` after a number; nothing for a dimensionless one (``stress_ks = 1``, not ``1 -``)."""
    return "" if unit.strip() in DIMENSIONLESS else f" {unit}"


def constraint_rows(problem: ScaledProblem, responses: np.ndarray, g: np.ndarray,
                    multipliers: np.ndarray | None, units: dict[str, str]) -> list[str]:
    """One line per constraint: response value vs its bound (its unit), margin, state."""
    lines = []
    for i, c in enumerate(problem.constraints):
        r = float(responses[problem.response_names.index(c.response)])
        unit = units.get(c.response, "")
        op = {"upper": "<=", "lower": ">=", "eq": "=="}[c.kind]
        if not np.isfinite(g[i]):
            state = "not evaluated"
        elif c.kind == "eq":
            state = "active (equality)" if abs(g[i]) <= FEAS_TOL else f"VIOLATED by {abs(r - c.bound):.4g}{_u(unit)}"
        elif g[i] < -FEAS_TOL:
            state = f"VIOLATED by {abs(r - c.bound):.4g}{_u(unit)}"
        elif g[i] <= ACTIVE_TOL:
            state = "active"
        else:
            state = f"inactive, margin {abs(r - c.bound):.4g}{_u(unit)} ({100 * g[i]:.3g} % of the bound scale)"
        mult = "" if multipliers is None or not np.isfinite(multipliers[i]) or multipliers[i] == 0 \
            else f", multiplier {multipliers[i]:.3g}"
        lines.append(f"  {c.response} = {r:.6g}{_u(unit)}  (bound {op} {c.bound:g}{_u(unit)}): {state}{mult}")
    return lines


def bound_rows(names: Sequence[str], x: np.ndarray, lower: np.ndarray, upper: np.ndarray,
               units: Sequence[str]) -> list[str]:
    """One line per design variable: value, bounds, and whether a bound is active."""
    lines = []
    for j, n in enumerate(names):
        unit = units[j] if j < len(units) else ""
        span = upper[j] - lower[j] if np.isfinite(upper[j] - lower[j]) else max(abs(x[j]), 1.0)
        at = "at its lower bound (active)" if x[j] <= lower[j] + BOUND_TOL * span else \
            "at its upper bound (active)" if x[j] >= upper[j] - BOUND_TOL * span else "free"
        lines.append(f"  {n} = {x[j]:.6g}{_u(unit)} in [{lower[j]:g}, {upper[j]:g}]: {at}")
    return lines


def removed_members(names: Sequence[str], x: np.ndarray, lower: np.ndarray,
                    upper: np.ndarray) -> dict[str, list[str]]:
    """Per design family (variables named ``family[element]``), the elements whose variable sits at
    its lower bound: in sizing and ground-structure optimization these members are removed
    (a bar at its minimum gauge carries next to nothing).  Families with none map to []."""
    removed: dict[str, list[str]] = {}
    for j, n in enumerate(names):
        parts = member_parts(n)
        if parts is None:
            continue
        family, element = parts
        span = upper[j] - lower[j] if np.isfinite(upper[j] - lower[j]) else max(abs(x[j]), 1.0)
        at_lower = bool(np.isfinite(lower[j]) and x[j] <= lower[j] + BOUND_TOL * span)
        removed.setdefault(family, [])
        if at_lower:
            removed[family].append(element)
    return removed


def removed_rows(names: Sequence[str], x: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> list[str]:
    """One line per design family: how many of its members are at the lower bound (removed)."""
    counts = {parts[0]: 0 for parts in map(member_parts, names) if parts is not None}
    for family, members in removed_members(names, x, lower, upper).items():
        counts[family] = len(members)
    total = {f: sum(1 for n in names if n.startswith(f + "[")) for f in counts}
    return [f"  family {f}: {counts[f]} of {total[f]} members at the lower bound (removed), {total[f] - counts[f]} "
            "remain" for f in counts]


def _condensed(rows: list[str], what: str, routine: Callable[[str], bool]) -> list[str]:
    """All rows up to ``LISTED`` of them; beyond, the others than the routine ones (inactive
    constraints, variables at a bound) and a count of the rest (the file has every one)."""
    if len(rows) <= LISTED:
        return rows
    kept = [r for r in rows if not routine(r)]
    if len(kept) > LISTED:
        kept = kept[:LISTED] + [f"  ... {len(kept) - LISTED} more"]
    return kept + [f"  ({len(rows)} {what} in all; {sum(map(routine, rows))} "
                   + ("inactive" if what == "constraints" else "at a bound") + ", not listed)"]


def decision_summary(path: str | Path, result: Any, design_units: Sequence[str] = (),
                     response_units: dict[str, str] | None = None) -> str:
    """Plain-text summary of the best start of an :class:`~.runner.OptimizationResult`."""
    b = result.best_outcome
    problem: ScaledProblem = result.problem
    units = response_units or {}
    h = read_history(path, b.index)
    f0, f1 = float(h["f"][0]), float(b.f)
    obj_unit = units.get(problem.objective, "")
    change = f1 - f0
    rel = f" ({100 * change / abs(f0):+.3g} %)" if f0 != 0 and np.isfinite(f0) else ""
    last_is_best = np.allclose(h["x"][-1], b.x, rtol=1e-12, atol=0)
    kkt = float(h["kkt"][-1])
    mult = np.asarray(h["multipliers"][-1], dtype=float) if last_is_best else None
    lines = [f"Decision summary (best start {b.index}):",
             f"  objective {problem.objective}: {f0:.8g}{_u(obj_unit)} at the start -> {f1:.8g}{_u(obj_unit)}"
             f" at the optimum, change {change:+.6g}{_u(obj_unit)}{rel}, {b.nit} iterations, "
             f"{b.n_sim} simulations",
             f"  final KKT residual {kkt:.2e} (scaled: ‖∇f_s − Σλ∇g_active‖∞, active constraints and bounds)"
             + ("" if last_is_best else " at the last iteration, not the returned design"),
             f"  max. scaled constraint violation {b.max_violation:.2e} (feasible within {FEAS_TOL:g})"]
    if problem.constraints:
        lines.append("constraints (value against bound, in the response's unit):")
        rows = constraint_rows(problem, np.asarray(b.responses, dtype=float), np.asarray(b.g, dtype=float),
                               mult, units)
        lines += _condensed(rows, "constraints", lambda row: "inactive" in row)
    lines.append("design variables and bounds:")
    rows = bound_rows(problem.names, np.asarray(b.x, dtype=float), problem.lower, problem.upper, design_units)
    lines += _condensed(rows, "design variables", lambda row: "(active)" in row)
    fam_rows = removed_rows(problem.names, np.asarray(b.x, dtype=float), problem.lower, problem.upper)
    if fam_rows:
        lines.append("members removed (variable at its lower bound; listed in /optimization/summary/removed):")
        lines += fam_rows
    active = [c.response for i, c in enumerate(problem.constraints) if np.isfinite(b.g[i]) and
              (abs(b.g[i]) <= ACTIVE_TOL if c.kind == "eq" else -FEAS_TOL <= b.g[i] <= ACTIVE_TOL)]
    at_bound = [ln.split(" =")[0].strip() for ln in bound_rows(problem.names, np.asarray(b.x, dtype=float),
                                                                problem.lower, problem.upper, design_units)
                if "(active)" in ln]
    lines.append(f"active: {', '.join(active + active_bounds(at_bound)) or 'none'}")
    return "\n".join(lines)


def active_bounds(at_bound: Sequence[str]) -> list[str]:
    """The ``active:`` line's bound entries: ``bound of NAME`` for each variable at a bound, up to
    ``LISTED`` of them; beyond, the variables of a design family (``family[element]``) are
    counted per family (a ground structure has thousands at their lower bound; the removed
    members are listed in the file) and the others listed, up to ``LISTED``."""
    if len(at_bound) <= LISTED:
        return [f"bound of {n}" for n in at_bound]
    per_family: dict[str, int] = {}
    others = []
    for n in at_bound:
        parts = member_parts(n)
        if parts is not None:
            per_family[parts[0]] = per_family.get(parts[0], 0) + 1
        else:
            others.append(n)
    out = [f"bound of {n}" for n in others[:LISTED]]
    if len(others) > LISTED:
        out.append(f"bounds of {len(others) - LISTED} more variables")
    return out + [f"bounds of {k} variables of family {f}" for f, k in per_family.items()]
