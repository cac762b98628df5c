"""What an engineer decides on after ``dynsens optimize``: the objective's change, the final KKT
residual, which constraints and bounds are active, each constraint against its bound in its unit.

Read from the optimization file (the best start's last history row and outcome), so it can be
printed again for any finished file (:func:`decision_summary`).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .problem import ACTIVE_TOL, FEAS_TOL, ScaledProblem
from .store import read_history

BOUND_TOL = 1e-6    # a design variable within this fraction of its range of a bound is at it


def _u(unit: str) -> str:
    return f" {unit}" if unit and unit != "-" else ""     # a ratio (unit "-") reads best bare


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
        lines += constraint_rows(problem, np.asarray(b.responses, dtype=float), np.asarray(b.g, dtype=float),
                                 mult, units)
    lines.append("design variables and bounds:")
    lines += bound_rows(problem.names, np.asarray(b.x, dtype=float), problem.lower, problem.upper,
                        design_units)
    active = [c.response for i, c in enumerate(problem.constraints) if np.isfinite(b.g[i]) and
              (abs(b.g[i]) <= ACTIVE_TOL if c.kind == "eq" else -FEAS_TOL <= b.g[i] <= ACTIVE_TOL)]
    at_bound = [ln.split(" =")[0].strip() for ln in bound_rows(problem.names, np.asarray(b.x, dtype=float),
                                                                problem.lower, problem.upper, design_units)
                if "(active)" in ln]
    lines.append(f"active: {', '.join(active + [f'bound of {n}' for n in at_bound]) or 'none'}")
    return "\n".join(lines)
