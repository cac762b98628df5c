"""Audit of the semi-analytical design partials: a sweep of their own finite-difference step.

The direct-differentiation gradient uses ∂F_R/∂x by forward differences of relative step h
(method.md §4).  Its error is truncation (∝ h) plus round-off (∝ ε/h): plotted against h it
has a plateau between the two, and the default step sits in it when the model's parameters are
well scaled.  This audit runs the whole sensitivity analysis for a sweep of h and compares each
gradient column with the one from complex-step partials (exact to round-off), per design
variable; a variable whose error never falls below the tolerance has no plateau and is
flagged (its partials need another scale, central or complex partials).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..case.load import Case
from .partials import DEFAULT_STEPS
from ..simulation import run_case

AUDIT_STEPS = tuple(10.0 ** -k for k in range(2, 13))
PLATEAU_TOL = 1e-5


@dataclass
class PartialsAudit:
    """Per design variable: relative gradient error for each partials step, and its plateau."""

    design_names: tuple[str, ...]
    steps: tuple[float, ...]
    errors: np.ndarray                  # (n_steps, m) worst relative error over the responses
    reference: str                      # partials the errors are measured against
    default_step: float
    tol: float

    def plateau(self, j: int) -> tuple[float, float] | None:
        """(largest, smallest) step whose error is within tol for variable j; None: no plateau."""
        ok = [h for h, e in zip(self.steps, self.errors[:, j]) if e <= self.tol]
        return (max(ok), min(ok)) if ok else None

    def flagged(self) -> list[str]:
        """Design variables whose partials have no plateau."""
        return [n for j, n in enumerate(self.design_names) if self.plateau(j) is None]


def _with_partials(case: Case, method: str, step: float | None) -> Case:
    return replace(case, plan=replace(case.plan, partials=method, partials_step=step))


def _gradients(case: Case, x: np.ndarray) -> dict[str, np.ndarray]:
    res = run_case(case, x, sensitivities=True, history=())
    return {n: np.real(r.gradient) for n, r in res.responses.items() if r.gradient is not None and not r.missing}


def audit_partials(case: Case, x: np.ndarray | None = None, steps: tuple[float, ...] = AUDIT_STEPS,
                   tol: float = PLATEAU_TOL) -> PartialsAudit:
    """Sweep the forward partials' relative step over ``steps`` at design ``x`` (default x0).

    The error of variable j at step h is max over responses of
    |∇_h − ∇_ref| / max(|∇_ref|, 1e-12·‖∇_ref‖) in column j, with ∇_ref from complex partials
    (central partials at their default step when the model is not complex-safe).
    """
    x = case.x0 if x is None else np.asarray(x, dtype=float)
    try:
        ref = _gradients(_with_partials(case, "complex", None), x)
        ref_name = "complex-step partials"
    except Exception:  # noqa: BLE001  (a model that is not complex-safe: fall back)
        ref = _gradients(_with_partials(case, "central", None), x)
        ref_name = "central partials"
    m = len(case.design_names)
    errors = np.zeros((len(steps), m))
    for k, h in enumerate(steps):
        grads = _gradients(_with_partials(case, "forward", h), x)
        for n, g_ref in ref.items():
            if n not in grads:
                continue
            floor = 1e-12 * max(float(np.max(np.abs(g_ref))), 1e-300)
            err = np.abs(grads[n] - g_ref) / np.maximum(np.abs(g_ref), floor)
            errors[k] = np.maximum(errors[k], err)
    return PartialsAudit(case.design_names, tuple(steps), errors, ref_name, DEFAULT_STEPS["forward"], tol)


def audit_markdown(a: PartialsAudit) -> str:
    """Table: steps down, design variables across, errors; the plateau and flags below."""
    head = "| h | " + " | ".join(a.design_names) + " |"
    lines = [f"## Partials audit (forward partials against {a.reference}; default h = {a.default_step:g})", "",
             head, "|" + "---|" * (len(a.design_names) + 1)]
    for h, row in zip(a.steps, a.errors):
        lines.append(f"| {h:.0e} | " + " | ".join(f"{e:.1e}" for e in row) + " |")
    lines.append("")
    for j, n in enumerate(a.design_names):
        p = a.plateau(j)
        lines.append(f"- {n}: " + (f"plateau (error <= {a.tol:g}) for h in [{p[1]:.0e}, {p[0]:.0e}]" if p else
                                   f"NO PLATEAU: the error never falls to {a.tol:g}; use central or complex "
                                   "partials, or a better scale for this variable"))
    return "\n".join(lines)


def audit_json(a: PartialsAudit) -> dict[str, Any]:
    """The audit as plain JSON data."""
    return {"reference": a.reference, "default_step": a.default_step, "tol": a.tol, "steps": list(a.steps),
            "errors": {n: a.errors[:, j].tolist() for j, n in enumerate(a.design_names)},
            "plateau": {n: a.plateau(j) for j, n in enumerate(a.design_names)}, "flagged": a.flagged()}
