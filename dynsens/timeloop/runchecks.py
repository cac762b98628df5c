"""Checks around one run: its size before the first step, the design's validity, and the result.

``run_case`` calls these so that every caller (``simulate``, the optimizer, finite
differences, ``check-gradients``, ``convergence``) gets the same guarantees:

* a run whose stored histories would not fit in memory, or whose step count is beyond
  reason, is refused before anything is allocated, with the estimate and what to change;
* a design at which an entry of the case has no finite value or breaks its range
  (a mass <= 0, a zero joint axis, ...) is refused with the entry's YAML path;
* a result with a non-finite response value or gradient is never returned as a success:
  it raises NonFiniteError naming the response, the design variable and the first step.
"""
from __future__ import annotations

import math
import os
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import DesignError, NonFiniteError, RunSizeError

if TYPE_CHECKING:
    from ..case.load import Case
    from .march import RunPlan, RunResult
    from ..models.base import Traits

#: steps beyond which a run is refused whatever it stores (~ days of wall time)
MAX_STEPS = 100_000_000
#: fraction of the available memory one run may plan to fill with its stored histories
MEMORY_FRACTION = 0.5
_FIELD_SIZE = {"q": "n_q", "qd": "n_q", "qdd": "n_q", "lam": "n_lam", "p": "n_p", "pd": "n_p"}


def available_memory() -> int:
    """Bytes of memory available to a new allocation (MemAvailable on Linux, else physical)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return 2**40


def run_bytes(traits: Traits, plan: RunPlan, m: int, history: tuple[str, ...] | None = None) -> int:
    """Bytes a run stores: (steps + 1) × (time + state histories + sensitivity histories × m)."""
    fields = plan.history if history is None else history
    per_step = 8 * (1 + sum(getattr(traits, _FIELD_SIZE[f]) for f in fields if f in _FIELD_SIZE))
    if plan.sensitivity_history and plan.sensitivities:
        per_step += 8 * m * sum(getattr(traits, _FIELD_SIZE[f]) for f in fields if f in _FIELD_SIZE)
    return (_steps(plan) + 1) * per_step


def _steps(plan: RunPlan) -> int:
    """Steps of the run: those of the grid of dt, or, with adaptive steps, the fewest it can take
    (every step dt_max long; it may take many more)."""
    if plan.adaptive is None:
        return plan.n_steps
    return max(1, int(np.ceil((plan.t_end - plan.t0) / plan.adaptive.dt_max - 1e-9)))


def _gib(b: float) -> str:
    return f"{b / 2**30:.3g} GiB" if b >= 2**28 else f"{b / 2**20:.3g} MiB"


def size_problem(traits: Traits, plan: RunPlan, m: int, history: tuple[str, ...] | None = None) -> str | None:
    """Why a run of this size is refused (steps, estimate, what to change), or None."""
    n = _steps(plan)
    if n > MAX_STEPS:
        return (f"expected at most {MAX_STEPS:.0e} steps, found (t_end - t0)/dt = {n:.3e}: increase dt or "
                "shorten the interval")
    need = run_bytes(traits, plan, m, history)
    avail = available_memory()
    if need > MEMORY_FRACTION * avail:
        fields = ", ".join(plan.history if history is None else history) or "none"
        return (f"{n:.3e} steps storing histories [{fields}]"
                + (f" and their sensitivities to {m} variables" if plan.sensitivity_history else "")
                + f" need about {_gib(need)}, more than half the {_gib(avail)} available: increase dt, "
                "shorten t_end, or store fewer histories (output.history: none; output.sensitivity_history: false)")
    return None


def check_run_size(case: Case, plan: RunPlan) -> None:
    """Raise RunSizeError when ``plan`` is refused by :func:`size_problem`."""
    why = size_problem(case.model.traits, plan, len(case.design))
    if why:
        raise RunSizeError(f"{case.source}: integrator.dt: {why}")


def check_design(case: Case, x: Any) -> None:
    """Raise DesignError when an entry of ``case`` has no finite value or breaks its range at ``x``."""
    table = getattr(case, "parameters", None)
    if table is None:
        return
    problems = table.check(x)
    if problems:
        xs = ", ".join(f"{n} = {v:.6g}" for n, v in zip(case.design_names, np.real(np.asarray(x))))
        raise DesignError(f"the design [{xs}] is not valid for {case.source}: "
                          + "; ".join(f"{p}: {msg}" for p, msg in problems))


def _first_nonfinite_step(arr: np.ndarray, column: int | None) -> int | None:
    """First step (row) of a (N, n, m) sensitivity history with a non-finite entry in ``column``."""
    a = arr[..., column] if column is not None else arr
    bad = ~np.isfinite(a.reshape(a.shape[0], -1)).all(axis=1)
    return int(np.flatnonzero(bad)[0]) if bad.any() else None


def check_result(case: Case, result: RunResult) -> None:
    """Raise NonFiniteError when a present response value or gradient entry is NaN or infinite."""
    for name, r in result.responses.items():
        if r.missing:
            continue
        if not np.all(np.isfinite(r.value)):
            raise NonFiniteError(f"{case.source}: response '{name}' is {np.real(r.value)!r} at the end of a run "
                                 f"that completed {result.counters.get('steps', '?')} steps: its definition "
                                 "(responses) has no finite value here; the run is failed, not completed")
        if r.gradient is None:
            continue
        bad = np.flatnonzero(~np.isfinite(r.gradient))
        if bad.size:
            j = int(bad[0])
            var = case.design_names[j] if j < len(case.design_names) else f"#{j}"
            first = None
            for arr in result.sensitivity_history.values():
                k = _first_nonfinite_step(arr, j)
                if k is not None:
                    first = k if first is None else min(first, k)
            where = (f"the sensitivities went non-finite first at step {first} (t = {result.time[first]:.6g} s)"
                     if first is not None else
                     "set output.sensitivity_history: true to see the first step where they went non-finite")
            raise NonFiniteError(f"{case.source}: the gradient of response '{name}' with respect to '{var}' is "
                                 f"{np.real(r.gradient[j])!r}; {where}. The derivative is not finite at this "
                                 "design (e.g. sqrt or a power of a variable at 0); the run is failed, not completed")


def stability_limit(model: Any, scheme: Any, t0: float, x: np.ndarray) -> tuple[float, float, float] | None:
    """(dt_max s, Ω_crit, ω_max rad/s) of a conditionally stable Newmark scheme (2β < γ) for the
    model linearized at its initial state and design ``x``; None when the scheme is unconditionally
    stable or the model has constraints or first-order states (no plain M, K pair).

    The scheme gives Ω_crit (:meth:`~dynsens.integrators.newmark.Newmark.stability_limit`;
    undamped Newmark: ω·dt ≤ 1/sqrt(γ/2 − β), central differences 2); this finds ω_max.
    """
    from ..models.base import StepState
    crit = scheme.stability_limit()
    tr = model.traits
    if math.isinf(crit) or tr.n_lam or tr.n_p or tr.n_q > 2000:
        return None
    params = model.parameters(np.asarray(x, dtype=float))
    q0, qd0, p0 = model.initial_state(params)
    s = StepState(q0, qd0, np.zeros_like(q0), np.zeros(0), p0, np.zeros(0))
    lin = model.linearize(t0, s, params)
    if lin.R_q is None:
        return None
    M, K = (a.toarray() if hasattr(a, "toarray") else np.asarray(a, dtype=float) for a in (lin.R_z, lin.R_q))
    try:
        w2 = np.linalg.eigvals(np.linalg.solve(M, K))
    except np.linalg.LinAlgError:
        return None
    w2 = np.real(w2[np.isfinite(w2)])
    if not w2.size or w2.max() <= 0:
        return None
    omega = float(np.sqrt(w2.max()))
    return crit / omega, crit, omega


def stability_problem(model: Any, scheme: Any, plan: RunPlan, x: np.ndarray) -> str | None:
    """Why ``plan.dt`` is past the scheme's stability limit at design ``x`` (the run would grow
    without bound), or None."""
    lim = stability_limit(model, scheme, plan.t0, x)
    if lim is None or plan.dt <= lim[0] * (1 + 1e-9):
        return None
    dt_max, crit, omega = lim
    return (f"expected at most the stability limit of newmark with beta = {scheme.beta:g}, gamma = {scheme.gamma:g}: "
            f"dt <= Omega_crit/omega_max = {crit:.4g}/{omega:.6g} rad/s = {dt_max:.4g} s (omega_max: the highest "
            f"natural frequency of the model linearized at t0 at this design), found {plan.dt:g} s; past it the "
            "solution grows without "
            "bound. Reduce dt, or use beta = 1/4 (unconditionally stable)")


def unstable_scheme_note(model: Any, scheme: Any, plan: RunPlan, x: np.ndarray, growth: bool) -> str | None:
    """Why a run that went non-finite may owe it to the scheme: past the stability limit
    (:func:`stability_problem`), or, for a run that grew without bound (``growth``) where no
    limit is computed (constraints, first-order states), a conditionally stable scheme
    (2β < γ) as such; None otherwise."""
    why = stability_problem(model, scheme, plan, x)
    if why is not None or not growth:
        return why
    if not scheme.unconditionally_stable and stability_limit(model, scheme, plan.t0, x) is None:
        return (f"newmark with beta = {scheme.beta:g} < gamma/2 = {scheme.gamma / 2:g} is only conditionally "
                "stable (dt <= Omega_crit/omega_max, Omega_crit = 1/sqrt(gamma/2 - beta)), and its limit is not "
                "computed for a model with constraints or first-order states: reduce dt, or use beta = 1/4 "
                "(unconditionally stable)")
    return None
