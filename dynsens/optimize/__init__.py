"""Gradient-based design optimization: SLSQP on the direct-differentiation gradients.

The library behind ``dynsens optimize``.  The case's ``optimization`` section names the
objective (minimized) and the constraints (``lower <= response <= upper``); the design
variables, their bounds and scales come from ``design.variables``.

Scaling (what SLSQP sees)
-------------------------
* Design: a variable with finite bounds is mapped to u = (x − lower)/(upper − lower) ∈ [0, 1];
  a variable with an infinite bound to u = x/scale (its bounds scaled alike).
* Objective: f_s = f/|f(x_ref)| with x_ref the first start (the case's x0 or ``-x``); 1 when
  f(x_ref) = 0.  The stored ``f`` is the objective in the response's own unit.
* Constraints: each bound becomes one SLSQP function g ≥ 0: ``r <= upper`` gives
  g = (upper − r)/d, ``r >= lower`` gives g = (r − lower)/d, ``lower == upper`` an equality,
  with d = |bound|, or |r(x_ref)| (1 if that is 0) when the bound is 0.  g < 0 is a
  violation in relative terms; a design is *feasible* when every g ≥ −``FEAS_TOL``.

One simulation per design point serves the objective, every constraint and all their
gradients (memoized by u).  A simulation that fails at a trial point (Newton divergence
``ConvergenceError``, ``NonFiniteError``, ``ModelError``, or a response that is
``missing``, e.g. an event that never fired, or not finite) is recorded and reported to
SLSQP as a finite penalty (f_s raised by ``FAIL_PENALTY``, every g lowered by it) so that
its line search backs off; a start whose first design cannot be simulated is not
optimized (and for the reference start the whole run stops with an
``OptimizationError``).

Output file (OPT.h5, appended after every iteration so an interruption loses nothing)
--------------------------------------------------------------------------------------
* root attributes as every dynsens file (``status``: running, converged, failed or
  interrupted; ``message``);
* ``/design/{names, values, x0, lower, upper}``;
* ``/optimization`` attributes: objective, constraints (JSON), f_ref, g_scale, maxiter,
  ftol, starts, seed, response_names, constraint_labels, feas_tol;
* ``/optimization/start_<k>/history/*``: one row per SLSQP iteration (row 0 is the start
  design) — ``iteration``, ``segment`` (0, then +1 per ``--resume``), ``x`` (m,) and
  ``u`` (m,), ``f`` (objective, its unit), ``f_scaled``, ``g`` (n_c,) scaled constraints,
  ``responses`` (n_r,) every response value, ``grad_f`` (m,) = ∂f_s/∂u, ``grad_g``
  (n_c, m) = ∂g/∂u, ``multipliers`` (n_c,), ``kkt`` (‖∇f_s − Σλ∇g_active‖∞ with λ ≥ 0 by
  NNLS over active constraints and bounds), ``max_violation`` (max(0, −min g)), ``step``
  (‖Δu‖∞), ``df`` (Δf_s), ``wall_time`` (s, this iteration), ``elapsed`` (s since the
  start began, over all segments), ``n_sim`` (simulations this iteration), ``failed``
  (failed simulations this iteration), ``message`` (the last failure, or empty);
* ``/optimization/start_<k>/evaluations/*``: one row per simulation — ``x``, ``u``, ``f``,
  ``g`` (NaN when failed), ``failed``, ``message``, ``wall_time`` (s), ``iteration``;
* ``/optimization/start_<k>`` attributes: ``x_start``, ``finished``, ``success``,
  ``status``, ``message``, ``nit`` (iterations recorded in ``history``: its rows − 1),
  ``slsqp_nit`` (SLSQP's own count, which also counts iterations it ends on without
  calling back), ``nfev`` (simulations), ``n_failed``, ``x_opt``, ``f_opt``, ``g_opt``,
  ``responses_opt``, ``max_violation``, ``feasible``, ``wall_time`` (s);
* ``/optimization/summary/*``: one row per start (``start``, ``x``, ``f``,
  ``max_violation``, ``success``, ``feasible``, ``nit``, ``n_sim``, ``message``), attribute
  ``best``;
* ``/optimization/optimum/{x, time, state/<field>, responses}``: the best design's time
  histories (for plots and ``dynsens export``); ``/optimization/initial``: the same for the
  start design x0.

``--resume`` restarts SLSQP at the last recorded iterate of every unfinished start with the
iterations left; SLSQP's quasi-Newton Hessian approximation is not stored and is rebuilt
from the identity, so the resumed path differs from an uninterrupted one.
"""
from __future__ import annotations

import sys as _sys
import types as _types
from typing import Any as _Any

from .jobs import StartOutcome, run_start
from .plots import plot_optimization
from .problem import (ACTIVE_TOL, FAIL_PENALTY, FEAS_TOL, ConstraintTerm, Evaluation, Evaluator, OptimizationError,
                      ScaledProblem, build_problem, evaluate, kkt_measure, max_violation, scaled_evaluation,
                      simulate)
from .runner import OptimizationResult, optimize_case, resolve_x0, start_points
from .store import read_history, set_status

__all__ = ["ACTIVE_TOL", "ConstraintTerm", "Evaluation", "Evaluator", "FAIL_PENALTY", "FEAS_TOL",
           "OptimizationError", "OptimizationResult", "ScaledProblem", "StartOutcome", "build_problem",
           "evaluate", "kkt_measure", "max_violation", "optimize_case", "plot_optimization", "read_history",
           "resolve_x0",
           "run_start", "scaled_evaluation", "set_status", "simulate", "start_points"]


class _CallableModule(_types.ModuleType):
    """``dynsens.optimize(...)`` is the API function :func:`dynsens.api.optimize`, while
    ``dynsens.optimize.<name>`` (and ``import dynsens.optimize.problem``) stay this subpackage."""

    def __call__(self, *args: _Any, **kwargs: _Any) -> _Any:
        from ..api import optimize
        return optimize(*args, **kwargs)


_sys.modules[__name__].__class__ = _CallableModule
