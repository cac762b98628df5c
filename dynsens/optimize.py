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
:class:`OptimizationError`).

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
* ``/optimization/optimum/{time, state/<field>, responses}``: the best design's time
  histories (for plots).

``--resume`` restarts SLSQP at the last recorded iterate of every unfinished start with the
iterations left; SLSQP's quasi-Newton Hessian approximation is not stored and is rebuilt
from the identity, so the resumed path differs from an uninterrupted one.
"""
from __future__ import annotations

import json
import multiprocessing as mp
import os
import queue as _queue
import time
import uuid
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import h5py
import numpy as np

from .case.load import Case, load_case_text
from .errors import DynsensError
from .io.hdf5 import OutputExistsError, append_rows, atomic_h5, write_design, write_header
from .simulation import run_case

FEAS_TOL = 1e-4      # scaled constraint violation still counted as feasible (relative to the bound)
ACTIVE_TOL = 1e-4    # scaled constraint value below which a constraint counts as active (KKT)
FAIL_PENALTY = 1e3   # added to f_s (and subtracted from g) at a design that cannot be simulated
SIM_ERRORS: tuple[type[BaseException], ...] = (DynsensError, FloatingPointError, ArithmeticError)

Sink = Callable[[dict[str, Any]], None]


class OptimizationError(DynsensError, ValueError):
    """Bad optimization input (no ``optimization`` section, start outside the bounds, ...)."""


# --------------------------------------------------------------------------------------
# the scaled problem
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ConstraintTerm:
    """One SLSQP constraint function g ≥ 0 (or g = 0) made from a response bound."""

    response: str
    kind: str            # "upper" (g = (bound − r)/d), "lower" (g = (r − bound)/d) or "eq"
    bound: float         # in the response's unit
    divisor: float       # d > 0, in the response's unit

    @property
    def label(self) -> str:
        """``stress_ks <= 350`` style label."""
        op = {"upper": "<=", "lower": ">=", "eq": "=="}[self.kind]
        return f"{self.response} {op} {self.bound:g}"


@dataclass(frozen=True)
class ScaledProblem:
    """Design scaling, objective normalization and constraint terms (picklable)."""

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    scale: np.ndarray
    objective: str
    f_ref: float
    constraints: tuple[ConstraintTerm, ...]
    response_names: tuple[str, ...]

    @property
    def affine(self) -> np.ndarray:
        """True where both bounds are finite (u ∈ [0, 1])."""
        return np.isfinite(self.lower) & np.isfinite(self.upper)

    @property
    def dx_du(self) -> np.ndarray:
        """dx/du (m,), units of the design variables."""
        return np.where(self.affine, self.upper - self.lower, self.scale)

    def to_u(self, x: np.ndarray) -> np.ndarray:
        """Physical design → scaled design."""
        x = np.asarray(x, dtype=float)
        lo = np.where(self.affine, self.lower, 0.0)
        return (x - lo) / self.dx_du

    def to_x(self, u: np.ndarray) -> np.ndarray:
        """Scaled design → physical design, clipped into the bounds."""
        lo = np.where(self.affine, self.lower, 0.0)
        return np.clip(lo + np.asarray(u, dtype=float) * self.dx_du, self.lower, self.upper)

    @property
    def u_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of u (±inf where the design variable is unbounded)."""
        with np.errstate(invalid="ignore"):
            lo = np.where(self.affine, 0.0, self.lower / self.scale)
            up = np.where(self.affine, 1.0, self.upper / self.scale)
        return lo, up

    @property
    def constraint_labels(self) -> tuple[str, ...]:
        """One label per SLSQP constraint."""
        return tuple(c.label for c in self.constraints)


def build_problem(case: Case, ref_responses: Mapping[str, float]) -> ScaledProblem:
    """Scaled problem of ``case`` with normalizations from the responses at the reference start.

    Parameters
    ----------
    case : a case with an ``optimization`` section.
    ref_responses : response values at the reference design (their units).
    """
    spec = _spec(case)
    f0 = float(ref_responses[spec.objective])
    f_ref = abs(f0) if np.isfinite(f0) and f0 != 0 else 1.0
    terms: list[ConstraintTerm] = []
    for c in spec.constraints:
        r0 = float(ref_responses[c.response])

        def divisor(b: float) -> float:
            if b != 0:
                return abs(float(b))
            return abs(r0) if np.isfinite(r0) and r0 != 0 else 1.0
        if c.lower is not None and c.upper is not None and c.lower == c.upper:
            terms.append(ConstraintTerm(c.response, "eq", float(c.upper), divisor(c.upper)))
            continue
        if c.upper is not None:
            terms.append(ConstraintTerm(c.response, "upper", float(c.upper), divisor(c.upper)))
        if c.lower is not None:
            terms.append(ConstraintTerm(c.response, "lower", float(c.lower), divisor(c.lower)))
    return ScaledProblem(case.design_names, case.lower, case.upper, case.scale, spec.objective, f_ref,
                         tuple(terms), tuple(case.response_names))


def _spec(case: Case) -> Any:
    if case.optimization is None:
        raise OptimizationError(f"{case.source} has no 'optimization' section: add one with an objective "
                                "and constraints (see the README)")
    return case.optimization


# --------------------------------------------------------------------------------------
# one simulation per design point
# --------------------------------------------------------------------------------------
@dataclass
class Evaluation:
    """Objective, constraints and their gradients at one design (one simulation).

    ``f`` is in the objective's unit; ``f_scaled``, ``g`` and the gradients are what SLSQP
    sees (∂/∂u).  A failed simulation has ``failed=True``, a ``message``, NaN values and
    no gradients.
    """

    x: np.ndarray
    u: np.ndarray
    f: float
    f_scaled: float
    g: np.ndarray
    grad_f: np.ndarray | None
    grad_g: np.ndarray | None
    responses: np.ndarray
    failed: bool = False
    message: str = ""
    wall_time: float = 0.0


def simulate(case: Case, x: np.ndarray) -> tuple[Any, str, float]:
    """One primal + sensitivity run at physical design ``x`` (m,).

    Returns ``(result, "", wall_time)`` or ``(None, message, wall_time)`` when the simulation
    failed (wall time in s); never raises for a simulation failure.
    """
    t0 = time.perf_counter()
    try:
        res = run_case(case, np.asarray(x, dtype=float), sensitivities=True, history=())
    except SIM_ERRORS as exc:
        return None, f"{type(exc).__name__}: {exc}", time.perf_counter() - t0
    return res, "", time.perf_counter() - t0


def scaled_evaluation(problem: ScaledProblem, x: np.ndarray, res: Any, message: str = "",
                      wall_time: float = 0.0) -> Evaluation:
    """The :class:`Evaluation` SLSQP sees, from a simulation result (``None`` when it failed)."""
    x = np.asarray(x, dtype=float)
    u = problem.to_u(x)
    nc, m = len(problem.constraints), x.size

    def failed(msg: str) -> Evaluation:
        return Evaluation(x, u, np.nan, np.nan, np.full(nc, np.nan), None, None,
                          np.full(len(problem.response_names), np.nan), True, msg, wall_time)
    if res is None:
        return failed(message or "simulation failed")
    rv = res.responses
    needed = [problem.objective] + [c.response for c in problem.constraints]
    for name in dict.fromkeys(needed):
        r = rv[name]
        if r.missing:
            return failed(f"response '{name}' is missing: {r.missing}")
        if r.gradient is None:
            return failed(f"response '{name}' has no gradient (sensitivities disabled?)")
        if not (np.isfinite(np.real(r.value)) and np.all(np.isfinite(np.real(r.gradient)))):
            return failed(f"response '{name}' is not finite: {r.value}")
    dxdu = problem.dx_du
    f = float(np.real(rv[problem.objective].value))
    grad_f = np.real(rv[problem.objective].gradient) * dxdu / problem.f_ref
    g = np.empty(nc)
    grad_g = np.empty((nc, m))
    for i, c in enumerate(problem.constraints):
        r = float(np.real(rv[c.response].value))
        dr = np.real(rv[c.response].gradient) * dxdu
        sign = -1.0 if c.kind == "upper" else 1.0
        g[i] = sign * (r - c.bound) / c.divisor
        grad_g[i] = sign * dr / c.divisor
    return Evaluation(x, u, f, f / problem.f_ref, g, grad_f, grad_g, _response_values(problem, res),
                      False, "", wall_time)


def _response_values(problem: ScaledProblem, res: Any) -> np.ndarray:
    rv = res.responses
    return np.array([float(np.real(rv[n].value)) if not rv[n].missing else np.nan
                     for n in problem.response_names])


def evaluate(case: Case, problem: ScaledProblem, x: np.ndarray) -> Evaluation:
    """Simulate ``case`` at physical design ``x`` (m,) with sensitivities; never raises for a
    simulation failure (it is returned as ``failed``)."""
    res, msg, wall = simulate(case, x)
    return scaled_evaluation(problem, x, res, msg, wall)


def kkt_measure(ev: Evaluation, problem: ScaledProblem, active_tol: float = ACTIVE_TOL
                ) -> tuple[float, np.ndarray]:
    """KKT residual ‖∇f_s − Σ λ_i ∇g_i‖∞ (λ ≥ 0 by NNLS over the active constraints and bounds).

    Returns the residual (scaled, dimensionless) and the constraint multipliers (n_c,).
    """
    from scipy.optimize import nnls
    if ev.grad_f is None or ev.grad_g is None:
        return float("nan"), np.full(len(problem.constraints), np.nan)
    m = ev.u.size
    cols: list[np.ndarray] = []
    owner: list[tuple[int, float]] = []        # (constraint index or -1, sign)
    for i, c in enumerate(problem.constraints):
        if c.kind == "eq":
            cols += [ev.grad_g[i], -ev.grad_g[i]]
            owner += [(i, 1.0), (i, -1.0)]
        elif ev.g[i] <= active_tol:
            cols.append(ev.grad_g[i])
            owner.append((i, 1.0))
    lo, up = problem.u_bounds
    for j in range(m):
        e = np.zeros(m)
        e[j] = 1.0
        if np.isfinite(lo[j]) and ev.u[j] <= lo[j] + 1e-8:
            cols.append(e)
            owner.append((-1, 1.0))
        if np.isfinite(up[j]) and ev.u[j] >= up[j] - 1e-8:
            cols.append(-e)
            owner.append((-1, 1.0))
    mult = np.zeros(len(problem.constraints))
    if not cols:
        return float(np.max(np.abs(ev.grad_f))) if m else 0.0, mult
    A = np.array(cols).T
    lam, _ = nnls(A, ev.grad_f)
    resid = ev.grad_f - A @ lam
    for (i, s), lv in zip(owner, lam):
        if i >= 0:
            mult[i] += s * lv
    return float(np.max(np.abs(resid))), mult


def max_violation(g: np.ndarray, problem: ScaledProblem) -> float:
    """Largest scaled constraint violation (0 when feasible); equality: |g|."""
    if not len(g):
        return 0.0
    v = [abs(gi) if c.kind == "eq" else max(0.0, -gi) for gi, c in zip(g, problem.constraints)]
    return float(max(v))


class Evaluator:
    """Memoized objective/constraint functions for SLSQP: one simulation per design point.

    Every simulation is reported to ``on_evaluation``.  Failed points return a finite
    penalty (see the module docstring) and the gradients of the last good point.
    """

    def __init__(self, case: Case, problem: ScaledProblem, on_evaluation: Callable[[Evaluation], None],
                 cache_size: int = 32):
        self.case = case
        self.problem = problem
        self.on_evaluation = on_evaluation
        self.cache: dict[bytes, Evaluation] = {}
        self.cache_size = cache_size
        self.n_sim = 0
        self.n_failed = 0
        self.last_good: Evaluation | None = None

    @staticmethod
    def _key(u: np.ndarray) -> bytes:
        return np.ascontiguousarray(u, dtype=float).tobytes()

    def __call__(self, u: np.ndarray) -> Evaluation:
        """Evaluation at scaled design ``u`` (simulates only when not cached)."""
        u = np.asarray(u, dtype=float)
        k = self._key(u)
        ev = self.cache.get(k)
        if ev is None:
            ev = evaluate(self.case, self.problem, self.problem.to_x(u))
            ev.u = u.copy()
            self.n_sim += 1
            self.n_failed += ev.failed
            if len(self.cache) >= self.cache_size:
                self.cache.pop(next(iter(self.cache)))
            self.cache[k] = ev
            if not ev.failed:
                self.last_good = ev
            self.on_evaluation(ev)
        return ev

    def _ref(self) -> Evaluation:
        if self.last_good is None:
            raise OptimizationError("no design could be simulated")
        return self.last_good

    def fun(self, u: np.ndarray) -> float:
        """f_s (penalized at a failed point)."""
        ev = self(u)
        return ev.f_scaled if not ev.failed else self._ref().f_scaled + FAIL_PENALTY

    def jac(self, u: np.ndarray) -> np.ndarray:
        """∂f_s/∂u."""
        ev = self(u)
        return (ev if not ev.failed else self._ref()).grad_f.copy()  # type: ignore[union-attr]

    def cons(self, u: np.ndarray, idx: list[int]) -> np.ndarray:
        """Constraint values g[idx] (penalized at a failed point)."""
        ev = self(u)
        if ev.failed:
            return np.minimum(self._ref().g[idx], 0.0) - FAIL_PENALTY
        return ev.g[idx].copy()

    def cons_jac(self, u: np.ndarray, idx: list[int]) -> np.ndarray:
        """∂g[idx]/∂u."""
        ev = self(u)
        return (ev if not ev.failed else self._ref()).grad_g[idx].copy()  # type: ignore[index]


# --------------------------------------------------------------------------------------
# one start (runs in the caller, a worker process or a Dask worker)
# --------------------------------------------------------------------------------------
@dataclass
class StartJob:
    """Everything a worker needs to run (or continue) one start; picklable."""

    index: int
    case_text: str
    case_source: str
    problem: ScaledProblem
    x_start: np.ndarray
    maxiter: int
    ftol: float
    iteration0: int = 0        # iterations done before (resume)
    segment: int = 0
    elapsed0: float = 0.0      # s, over earlier segments
    resume: bool = False
    seed_eval: Evaluation | None = None
    sink: str = "direct"       # direct | queue | dask
    topic: str = ""


@dataclass
class StartOutcome:
    """Result of one start (attributes of ``/optimization/start_<k>``)."""

    index: int
    x_start: np.ndarray
    x: np.ndarray
    f: float
    g: np.ndarray
    responses: np.ndarray
    max_violation: float
    feasible: bool
    success: bool
    status: int
    message: str
    nit: int
    n_sim: int
    n_failed: int
    wall_time: float
    messages: list[dict[str, Any]] = field(default_factory=list)
    slsqp_nit: int = 0


_CASES: dict[tuple[str, str], Case] = {}
_QUEUE: Any = None
_DIRECT_SINK: Sink | None = None


def _case_from_text(text: str, source: str) -> Case:
    key = (text, source)
    if key not in _CASES:
        _CASES.clear()
        _CASES[key] = load_case_text(text, source)
    return _CASES[key]


def _plain(v: Any) -> Any:
    """numpy → plain Python (msgpack-friendly for Dask events)."""
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    return v


def _make_sink(job: StartJob) -> Sink:
    if job.sink == "queue":
        q = _QUEUE
        return lambda msg: q.put(msg)
    if job.sink == "dask":
        from distributed import get_worker
        worker = get_worker()
        return lambda msg: worker.log_event(job.topic, msg)
    assert _DIRECT_SINK is not None
    return _DIRECT_SINK


def run_start(job: StartJob) -> StartOutcome:
    """Run SLSQP for one start; stream every evaluation and iteration row to the job's sink."""
    from scipy.optimize import Bounds, minimize
    t_begin = time.perf_counter()
    case = _case_from_text(job.case_text, job.case_source)
    problem = job.problem
    sink = _make_sink(job)
    sent: list[dict[str, Any]] = []
    seq = [0]
    state = {"n_sim": 0, "failed": 0, "message": "", "t_last": t_begin, "it": job.iteration0}

    def emit(kind: str, row: dict[str, Any]) -> None:
        msg = {"start": job.index, "kind": kind, "seq": seq[0], "row": {k: _plain(v) for k, v in row.items()}}
        seq[0] += 1
        sent.append(msg)
        sink(msg)

    def on_eval(ev: Evaluation) -> None:
        state["n_sim"] += 1
        if ev.failed:
            state["failed"] += 1
            state["message"] = ev.message
        emit("evaluation", {"x": ev.x, "u": ev.u, "f": ev.f, "g": ev.g, "failed": ev.failed,
                            "message": ev.message, "wall_time": ev.wall_time, "iteration": state["it"]})

    seed = job.seed_eval
    evaluator = Evaluator(case, problem, on_eval)
    if seed is not None:                      # simulated by the caller: record it here
        evaluator.cache[evaluator._key(seed.u)] = seed
        evaluator.last_good = None if seed.failed else seed
        evaluator.n_sim += 1
        evaluator.n_failed += seed.failed
        on_eval(seed)
    u0 = problem.to_u(job.x_start)
    ev0 = evaluator(u0)
    prev = {"u": ev0.u, "f": ev0.f_scaled}

    def iteration_row(ev: Evaluation) -> dict[str, Any]:
        now = time.perf_counter()
        kkt, mult = kkt_measure(ev, problem)
        row = {"iteration": state["it"], "segment": job.segment, "x": ev.x, "u": ev.u, "f": ev.f,
               "f_scaled": ev.f_scaled, "g": ev.g, "responses": ev.responses,
               "grad_f": ev.grad_f, "grad_g": ev.grad_g, "multipliers": mult, "kkt": kkt,
               "max_violation": max_violation(ev.g, problem),
               "step": float(np.max(np.abs(ev.u - prev["u"]))) if ev.u.size else 0.0,
               "df": ev.f_scaled - prev["f"], "wall_time": now - state["t_last"],
               "elapsed": job.elapsed0 + now - t_begin, "n_sim": state["n_sim"],
               "failed": state["failed"], "message": state["message"]}
        state.update(n_sim=0, failed=0, message="", t_last=now)
        prev.update(u=ev.u, f=ev.f_scaled)
        return row

    def outcome(ev: Evaluation, success: bool, status: int, message: str, nit: int) -> StartOutcome:
        mv = max_violation(ev.g, problem) if not ev.failed else float("inf")
        return StartOutcome(job.index, np.asarray(job.x_start, float), ev.x, ev.f, ev.g, ev.responses, mv,
                            bool(not ev.failed and mv <= FEAS_TOL), success, status, message, nit,
                            evaluator.n_sim, evaluator.n_failed,
                            job.elapsed0 + time.perf_counter() - t_begin, sent)

    if ev0.failed:
        return outcome(ev0, False, -1, f"the start design cannot be simulated: {ev0.message}", job.iteration0)
    if not job.resume:
        emit("iteration", iteration_row(ev0))
    remaining = job.maxiter - job.iteration0
    if remaining <= 0:
        return outcome(ev0, False, 9, "Iteration limit reached", job.iteration0)

    def callback(xk: np.ndarray) -> None:
        state["it"] += 1
        emit("iteration", iteration_row(evaluator(xk)))

    cons = []
    for kind, typ in (("ineq", "ineq"), ("eq", "eq")):
        idx = [i for i, c in enumerate(problem.constraints) if (c.kind == "eq") == (kind == "eq")]
        if idx:
            cons.append({"type": typ, "fun": evaluator.cons, "jac": evaluator.cons_jac, "args": (idx,)})
    lo, up = problem.u_bounds
    res = minimize(evaluator.fun, u0, jac=evaluator.jac, method="SLSQP", bounds=Bounds(lo, up),
                   constraints=cons, callback=callback,
                   options={"maxiter": int(remaining), "ftol": float(job.ftol)})
    ev = evaluator(np.asarray(res.x, dtype=float))
    if ev.failed and evaluator.last_good is not None:
        ev = evaluator.last_good
    out = outcome(ev, bool(res.success), int(res.status), str(res.message), state["it"])
    out.slsqp_nit = job.iteration0 + int(res.nit)
    return out


# --------------------------------------------------------------------------------------
# the output file (written only by the calling process)
# --------------------------------------------------------------------------------------
def _str(v: str) -> np.ndarray:
    return np.array(v, dtype=h5py.string_dtype())


def _start_group(k: int) -> str:
    return f"optimization/start_{k}"


def _write_row(path: Path, msg: dict[str, Any]) -> None:
    group = f"{_start_group(msg['start'])}/{'history' if msg['kind'] == 'iteration' else 'evaluations'}"
    rows = {}
    for k, v in msg["row"].items():
        if v is None:
            continue
        rows[k] = _str(v) if isinstance(v, str) else np.asarray(v, dtype=float if k not in
                                                                ("iteration", "segment", "n_sim", "failed")
                                                                else None)
    if msg["kind"] == "evaluation":
        rows["failed"] = np.asarray(bool(msg["row"]["failed"]))
    else:
        rows["failed"] = np.asarray(int(msg["row"]["failed"]))
    append_rows(path, group, rows)


def _set_attrs(path: Path, group: str, attrs: Mapping[str, Any]) -> None:
    with h5py.File(path, "a") as f:
        g = f.require_group(group) if group else f
        for k, v in attrs.items():
            g.attrs[k] = v
        f.flush()


def set_status(path: str | Path, status: str, message: str) -> None:
    """Root ``status``/``message`` of an optimization file (e.g. ``interrupted`` after Ctrl-C)."""
    _set_attrs(Path(path), "", {"status": status, "message": message})


def _outcome_attrs(o: StartOutcome) -> dict[str, Any]:
    return {"finished": True, "success": o.success, "status": o.status, "message": o.message, "nit": o.nit,
            "nfev": o.n_sim, "n_failed": o.n_failed, "x_opt": o.x, "f_opt": o.f, "g_opt": o.g,
            "responses_opt": o.responses, "max_violation": o.max_violation, "feasible": o.feasible,
            "wall_time": o.wall_time, "slsqp_nit": o.slsqp_nit}


def _outcome_from_file(f: h5py.File, k: int) -> StartOutcome:
    a = f[_start_group(k)].attrs
    return StartOutcome(k, a["x_start"], a["x_opt"], float(a["f_opt"]), a["g_opt"], a["responses_opt"],
                        float(a["max_violation"]), bool(a["feasible"]), bool(a["success"]), int(a["status"]),
                        str(a["message"]), int(a["nit"]), int(a["nfev"]), int(a["n_failed"]),
                        float(a["wall_time"]), slsqp_nit=int(a.get("slsqp_nit", 0)))


# --------------------------------------------------------------------------------------
# the driver
# --------------------------------------------------------------------------------------
@dataclass
class OptimizationResult:
    """All starts of a run and the best one."""

    path: Path
    problem: ScaledProblem
    starts: list[StartOutcome]
    best: int

    @property
    def best_outcome(self) -> StartOutcome:
        """The best start (lowest objective among the feasible ones)."""
        return self.starts[self.best]

    @property
    def converged(self) -> bool:
        """SLSQP reported success for the best start."""
        return self.best_outcome.success

    @property
    def feasible(self) -> bool:
        """The best design satisfies every constraint within FEAS_TOL."""
        return self.best_outcome.feasible


def start_points(case: Case, n: int, seed: int, x0: np.ndarray) -> np.ndarray:
    """``n`` start designs (n, m): ``x0``, then a Latin hypercube sample in the bounds."""
    pts = [np.asarray(x0, dtype=float)]
    if n > 1:
        lo, up = case.lower, case.upper
        bad = [nm for nm, a, b in zip(case.design_names, lo, up) if not (np.isfinite(a) and np.isfinite(b))]
        if bad:
            raise OptimizationError(f"--starts {n} needs finite bounds for every design variable "
                                    f"(unbounded: {', '.join(bad)})")
        from scipy.stats import qmc
        sample = qmc.LatinHypercube(d=len(lo), rng=seed).random(n - 1)
        pts += list(lo + sample * (up - lo))
    return np.array(pts)


def resolve_x0(case: Case, x0: Mapping[str, float] | None) -> np.ndarray:
    """The case's initial design with ``x0`` entries replaced; checks names and bounds."""
    x = case.x0.copy()
    for name, v in (x0 or {}).items():
        if name not in case.design_names:
            raise OptimizationError(f"-x {name}={v}: unknown design variable {name!r} "
                                    f"(design variables: {', '.join(case.design_names)})")
        j = case.design_names.index(name)
        lo, up = case.lower[j], case.upper[j]
        if not (np.isfinite(v) and lo <= v <= up):
            raise OptimizationError(f"-x {name}={v:g} is outside the bounds of design variable {name!r}: "
                                    f"[{lo:g}, {up:g}]")
        x[j] = float(v)
    return x


def _init_file(path: Path, case: Case, x_ref: np.ndarray, overwrite: bool) -> None:
    with atomic_h5(path, overwrite) as f:
        write_header(f, case.text, case.source, "running", "")
        write_design(f, case.design_names, x_ref, case.lower, case.upper)
        f["design"].create_dataset("x0", data=x_ref)
        f.create_group("optimization")


def _problem_attrs(problem: ScaledProblem) -> dict[str, Any]:
    return {"objective": problem.objective, "f_ref": problem.f_ref,
            "constraints": json.dumps([c.__dict__ for c in problem.constraints]),
            "constraint_labels": json.dumps(list(problem.constraint_labels)),
            "response_names": json.dumps(list(problem.response_names)),
            "g_scale": np.array([c.divisor for c in problem.constraints], dtype=float),
            "feas_tol": FEAS_TOL}


def _problem_from_file(f: h5py.File, case: Case) -> ScaledProblem:
    a = f["optimization"].attrs
    terms = tuple(ConstraintTerm(**c) for c in json.loads(a["constraints"]))
    return ScaledProblem(case.design_names, case.lower, case.upper, case.scale, str(a["objective"]),
                         float(a["f_ref"]), terms, tuple(json.loads(a["response_names"])))


def optimize_case(case: Case, output: str | Path, *, starts: int | None = None, seed: int | None = None,
                  x0: Mapping[str, float] | None = None, maxiter: int | None = None,
                  ftol: float | None = None, workers: int | None = None, scheduler: str | None = None,
                  resume: bool = False, overwrite: bool = False,
                  on_message: Callable[[dict[str, Any]], None] | None = None,
                  on_start_done: Callable[[StartOutcome], None] | None = None) -> OptimizationResult:
    """Optimize ``case`` with SLSQP from one or more starts; history to ``output`` (HDF5).

    Parameters
    ----------
    case : a case with an ``optimization`` section.
    output : OPT.h5 path; created atomically, then appended after every iteration.
    starts : number of starts (default 1): the first at x0, the rest a Latin hypercube
        sample in the bounds (``scipy.stats.qmc.LatinHypercube``, ``seed``).
    seed : seed of the Latin hypercube (default: drawn and stored in the file).
    x0 : design values (case units) replacing the case's initial design; must be in the bounds.
    maxiter, ftol : SLSQP settings (default: the case's ``optimization`` section).
    workers : worker processes for several starts (default min(starts, CPUs)); 1 runs in-process.
    scheduler : address of a Dask distributed scheduler; starts run there instead.
    resume : continue the unfinished starts recorded in ``output``.
    overwrite : replace an existing ``output``.
    on_message : called in this process with every evaluation/iteration message once written.
    on_start_done : called with each finished start.

    Raises
    ------
    OptimizationError
        No optimization section, start outside the bounds, the reference start cannot be
        simulated, inconsistent ``--resume``.
    """
    global _DIRECT_SINK
    spec = _spec(case)
    path = Path(output)
    maxiter = int(maxiter if maxiter is not None else spec.maxiter)
    ftol = float(ftol if ftol is not None else spec.ftol)
    if maxiter < 1 or ftol <= 0:
        raise OptimizationError(f"expected maxiter >= 1 and ftol > 0, found {maxiter} and {ftol:g}")
    outcomes: dict[int, StartOutcome] = {}
    jobs: list[StartJob] = []
    if resume:
        problem, pts, jobs, outcomes = _resume_jobs(path, case, starts, seed, x0, maxiter, ftol)
    else:
        if path.exists() and not overwrite:
            raise OutputExistsError(f"{path} exists: pass --overwrite to replace it, or --resume to continue it")
        n = int(starts or 1)
        if n < 1:
            raise OptimizationError(f"--starts must be >= 1, found {n}")
        x_ref = resolve_x0(case, x0)
        if seed is None:
            seed = int(np.random.SeedSequence().entropy % (2 ** 31))
        pts = start_points(case, n, seed, x_ref)
        _init_file(path, case, x_ref, overwrite)
        # the reference start is simulated here: it fixes the normalizations (one simulation,
        # handed to start 0 so that it is not repeated)
        res0, msg0, wall0 = simulate(case, x_ref)
        ref_values = {n: (float(np.real(r.value)) if not r.missing else np.nan)
                      for n, r in res0.responses.items()} if res0 is not None else \
            {n: np.nan for n in case.response_names}
        problem = build_problem(case, ref_values)
        ev0 = scaled_evaluation(problem, x_ref, res0, msg0, wall0)
        _set_attrs(path, "optimization", {**_problem_attrs(problem), "maxiter": maxiter, "ftol": ftol,
                                          "starts": n, "seed": seed, "x_starts": pts})
        for k, xs in enumerate(pts):
            _set_attrs(path, _start_group(k), {"x_start": xs, "finished": False})
        if ev0.failed:
            msg = {"start": 0, "kind": "evaluation", "seq": 0,
                   "row": {"x": ev0.x, "u": problem.to_u(ev0.x), "f": np.nan,
                           "g": np.full(len(problem.constraints), np.nan), "failed": True,
                           "message": ev0.message, "wall_time": ev0.wall_time, "iteration": 0}}
            _write_row(path, msg)
            text = f"the start design x0 = {_fmt(x_ref)} cannot be simulated: {ev0.message}"
            _set_attrs(path, _start_group(0), {"finished": True, "success": False, "message": text})
            set_status(path, "failed", text)
            raise OptimizationError(text)
        for k, xs in enumerate(pts):
            jobs.append(StartJob(k, case.text, case.source, problem, xs, maxiter, ftol,
                                 seed_eval=ev0 if k == 0 else None))
    _CASES[(case.text, case.source)] = case
    if resume:
        _set_attrs(path, "", {"status": "running", "message": ""})
        _set_attrs(path, "optimization", {"maxiter": maxiter, "ftol": ftol})
    expected = {j.index: 0 for j in jobs}
    pending: dict[int, dict[int, dict[str, Any]]] = {j.index: {} for j in jobs}

    def handle(msg: dict[str, Any]) -> None:
        k = msg["start"]
        pending[k][msg["seq"]] = msg
        while expected[k] in pending[k]:
            m_ = pending[k].pop(expected[k])
            expected[k] += 1
            _write_row(path, m_)
            if on_message is not None:
                on_message(m_)

    def finish(o: StartOutcome) -> None:
        for m_ in o.messages:            # anything the live stream has not delivered yet
            if m_["seq"] >= expected[o.index]:
                handle(m_)
        _set_attrs(path, _start_group(o.index), _outcome_attrs(o))
        outcomes[o.index] = o
        if on_start_done is not None:
            on_start_done(o)

    try:
        if jobs:
            n_workers = min(len(jobs), workers or (os.cpu_count() or 1))
            if scheduler:
                _run_dask(jobs, scheduler, handle, finish)
            elif n_workers > 1:
                _run_pool(jobs, n_workers, handle, finish)
            else:
                _DIRECT_SINK = handle
                try:
                    for j in jobs:
                        finish(run_start(j))
                finally:
                    _DIRECT_SINK = None
    except KeyboardInterrupt:
        set_status(path, "interrupted", "interrupted: continue with --resume")
        raise
    except BaseException as exc:
        set_status(path, "failed", f"{type(exc).__name__}: {exc}")
        raise
    result = _finalize(path, case, problem, [outcomes[k] for k in sorted(outcomes)])
    return result


def _resume_jobs(path: Path, case: Case, starts: int | None, seed: int | None, x0: Mapping[str, float] | None,
                 maxiter: int, ftol: float) -> tuple[ScaledProblem, np.ndarray, list[StartJob],
                                                     dict[int, StartOutcome]]:
    if not path.exists():
        raise OptimizationError(f"--resume: {path} does not exist (run without --resume to start)")
    jobs: list[StartJob] = []
    done: dict[int, StartOutcome] = {}
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise OptimizationError(f"--resume: cannot read {path}: {exc}") from None
    with f:
        if "optimization" not in f or "f_ref" not in f["optimization"].attrs:
            raise OptimizationError(f"--resume: {path} is not a dynsens optimization file "
                                    "(or it was interrupted before its first design was simulated)")
        if str(f.attrs.get("case", "")) != case.text:
            raise OptimizationError(f"--resume: {path} was made from a different case (or other --set "
                                    "options): give the same case file and --set options")
        a = f["optimization"].attrs
        n = int(a["starts"])
        if starts is not None and int(starts) != n:
            raise OptimizationError(f"--resume: {path} has {n} start(s); --starts {starts} cannot change that")
        if seed is not None and int(seed) != int(a["seed"]):
            raise OptimizationError(f"--resume: {path} used --seed {int(a['seed'])}; --seed cannot change it")
        if x0:
            raise OptimizationError("--resume continues from the recorded designs: -x/--x0 cannot be combined "
                                    "with it")
        problem = _problem_from_file(f, case)
        pts = np.asarray(a["x_starts"], dtype=float)
        for k in range(n):
            g = f.get(_start_group(k))
            if g is not None and bool(g.attrs.get("finished", False)) and "x_opt" in g.attrs:
                done[k] = _outcome_from_file(f, k)
                continue
            h = g.get("history") if g is not None else None
            if h is not None and h["x"].shape[0] > 0:
                jobs.append(StartJob(k, case.text, case.source, problem, h["x"][-1], maxiter, ftol,
                                     iteration0=int(h["iteration"][-1]), segment=int(h["segment"][-1]) + 1,
                                     elapsed0=float(h["elapsed"][-1]), resume=True))
            else:
                jobs.append(StartJob(k, case.text, case.source, problem, pts[k], maxiter, ftol))
    return problem, pts, jobs, done


def _run_pool(jobs: list[StartJob], n_workers: int, handle: Callable[[dict[str, Any]], None],
              finish: Callable[[StartOutcome], None]) -> None:
    """Starts in forked worker processes; rows come back through a queue to this process."""
    global _QUEUE
    ctx = mp.get_context("fork")
    _QUEUE = ctx.Queue()
    pool = ProcessPoolExecutor(max_workers=n_workers, mp_context=ctx)
    try:
        futs: dict[Future, StartJob] = {}
        for j in jobs:
            j.sink = "queue"
            futs[pool.submit(run_start, j)] = j
        _drain(lambda: _QUEUE.get(timeout=0.05), futs, handle, finish)
    except BaseException:
        # stop the starts still running (our own worker processes) instead of waiting for them
        procs = list(getattr(pool, "_processes", {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for proc in procs:
            proc.terminate()
        raise
    else:
        pool.shutdown(wait=True)
    finally:
        _QUEUE = None


def _drain(get: Callable[[], dict[str, Any]], futs: dict[Any, StartJob],
           handle: Callable[[dict[str, Any]], None], finish: Callable[[StartOutcome], None]) -> None:
    left = dict(futs)
    while left:
        try:
            handle(get())
            continue
        except _queue.Empty:
            pass
        for fu in [fu for fu in left if fu.done()]:
            del left[fu]
            finish(fu.result())


def _run_dask(jobs: list[StartJob], address: str, handle: Callable[[dict[str, Any]], None],
              finish: Callable[[StartOutcome], None]) -> None:
    """Starts as tasks on a Dask distributed cluster; rows come back as worker events."""
    try:
        from distributed import Client
    except ImportError:
        raise OptimizationError("--scheduler needs Dask distributed: pip install 'dynsens[dask]'") from None
    topic = f"dynsens-optimize-{uuid.uuid4().hex}"
    q: _queue.Queue = _queue.Queue()
    try:
        client = Client(address, timeout=30)
    except (OSError, TimeoutError) as exc:
        raise OptimizationError(f"--scheduler {address}: cannot connect ({exc})") from None
    with client:
        client.subscribe_topic(topic, lambda ev: q.put(ev[1]))
        try:
            futs = {}
            for j in jobs:
                j.sink, j.topic = "dask", topic
                futs[client.submit(run_start, j, pure=False)] = j
            try:
                _drain(lambda: q.get(timeout=0.05), futs, handle, finish)
            except BaseException:
                client.cancel(list(futs))
                raise
        finally:
            client.unsubscribe_topic(topic)


def _fmt(x: np.ndarray) -> str:
    return "[" + ", ".join(f"{v:.6g}" for v in np.asarray(x, dtype=float)) + "]"


def _finalize(path: Path, case: Case, problem: ScaledProblem, outs: list[StartOutcome]) -> OptimizationResult:
    """Summary table, the best design's time histories, final status."""
    def rank(o: StartOutcome) -> tuple[int, float, float]:
        ok = np.isfinite(o.f)
        return (0 if o.feasible else 1 if ok else 2, o.f if o.feasible else o.max_violation,
                o.f if ok else np.inf)
    best = min(range(len(outs)), key=lambda i: rank(outs[i]))
    res = OptimizationResult(path, problem, outs, outs[best].index)
    res.best = best
    b = outs[best]
    with h5py.File(path, "a") as f:
        if "optimization/summary" in f:
            del f["optimization/summary"]
        s = f.create_group("optimization/summary")
        s.create_dataset("start", data=np.array([o.index for o in outs]))
        s.create_dataset("x", data=np.array([o.x for o in outs], dtype=float))
        s.create_dataset("f", data=np.array([o.f for o in outs], dtype=float))
        s.create_dataset("max_violation", data=np.array([o.max_violation for o in outs], dtype=float))
        s.create_dataset("success", data=np.array([o.success for o in outs]))
        s.create_dataset("feasible", data=np.array([o.feasible for o in outs]))
        s.create_dataset("nit", data=np.array([o.nit for o in outs]))
        s.create_dataset("n_sim", data=np.array([o.n_sim for o in outs]))
        s.create_dataset("message", data=np.array([o.message for o in outs], dtype=h5py.string_dtype()))
        s.attrs["best"] = b.index
        f.flush()
    if np.isfinite(b.f):
        _store_optimum(path, case, b.x)
    status = "converged" if b.success else "failed"
    msg = (f"start {b.index}: {b.message}; " + ("feasible" if b.feasible else
                                                  f"infeasible (max violation {b.max_violation:.3g})"))
    set_status(path, status, msg)
    return res


def _store_optimum(path: Path, case: Case, x: np.ndarray) -> None:
    hist = tuple(case.plan.history) or ("q",)
    try:
        r = run_case(case, x, sensitivities=False, history=hist)
    except SIM_ERRORS:
        return
    with h5py.File(path, "a") as f:
        if "optimization/optimum" in f:
            del f["optimization/optimum"]
        g = f.create_group("optimization/optimum")
        g.create_dataset("x", data=np.asarray(x, dtype=float))
        g.create_dataset("time", data=r.time)
        st = g.create_group("state")
        for k, v in r.history.items():
            st.create_dataset(k, data=v, compression="gzip" if v.size > 10000 else None)
        st.attrs["q_labels"] = np.array(r.labels.get("q", []), dtype=h5py.string_dtype())
        rg = g.create_group("responses")
        for n, rv in r.responses.items():
            rg.attrs[n] = float(np.real(rv.value)) if not rv.missing else np.nan
        f.flush()


def read_history(path: str | Path, start: int = 0) -> dict[str, np.ndarray]:
    """The per-iteration history of one start as numpy arrays (strings decoded)."""
    with h5py.File(path, "r") as f:
        h = f[f"{_start_group(start)}/history"]
        out = {k: v[()] for k, v in h.items()}
    if "message" in out:
        out["message"] = np.array([m.decode() if isinstance(m, bytes) else m for m in out["message"]], dtype=object)
    return out


# --------------------------------------------------------------------------------------
# plots
# --------------------------------------------------------------------------------------
def plot_optimization(path: str | Path, outdir: str | Path, max_lines: int = 8) -> list[Path]:
    """PNG plots of an optimization file: the history and the best design's time histories.

    Writes ``<stem>_history.png`` (objective, max. constraint violation and KKT residual
    over the iterations of every start) and ``<stem>_optimum.png`` (the ``max_lines``
    largest displacement histories q(t) of the best design).  Returns the files written.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    path, outdir = Path(path), Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    written = []
    with h5py.File(path, "r") as f:
        opt = f["optimization"]
        objective = str(opt.attrs["objective"])
        fig, axes = plt.subplots(3, 1, figsize=(7, 8), sharex=True)
        for name in sorted(k for k in opt if k.startswith("start_")):
            if "history" not in opt[name]:
                continue
            h = opt[name]["history"]
            it = h["iteration"][()]
            axes[0].plot(it, h["f"][()], "o-", ms=3, label=name.replace("_", " "))
            axes[1].semilogy(it, np.maximum(h["max_violation"][()], 1e-16), "o-", ms=3)
            axes[2].semilogy(it, np.maximum(h["kkt"][()], 1e-16), "o-", ms=3)
        axes[0].set_ylabel(objective)
        axes[1].set_ylabel("max. violation (scaled)")
        axes[2].set_ylabel("KKT residual (scaled)")
        axes[2].set_xlabel("iteration")
        axes[0].legend(fontsize=8)
        for ax in axes:
            ax.grid(True, alpha=0.3)
        fig.suptitle(f"{path.name}: optimization history")
        fig.tight_layout()
        p = outdir / f"{path.stem}_history.png"
        fig.savefig(p, dpi=100)
        plt.close(fig)
        written.append(p)
        if "optimum" in opt and "q" in opt["optimum/state"]:
            t = opt["optimum/time"][()]
            q = opt["optimum/state/q"][()]
            labels = [lb.decode() if isinstance(lb, bytes) else lb for lb in opt["optimum/state"].attrs["q_labels"]]
            order = np.argsort(-np.max(np.abs(q), axis=0))[:max_lines]
            fig, ax = plt.subplots(figsize=(7, 4))
            for j in order:
                ax.plot(t, q[:, j], label=labels[j] if j < len(labels) else f"q[{j}]")
            ax.set_xlabel("t [s]")
            ax.set_ylabel("q")
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=8, ncol=2)
            ax.set_title(f"best design x = {_fmt(opt['optimum/x'][()])}")
            fig.tight_layout()
            p = outdir / f"{path.stem}_optimum.png"
            fig.savefig(p, dpi=100)
            plt.close(fig)
            written.append(p)
    return written


__all__ = ["ConstraintTerm", "Evaluation", "Evaluator", "FAIL_PENALTY", "FEAS_TOL",
           "OptimizationError", "OptimizationResult", "ScaledProblem", "StartOutcome", "build_problem",
           "evaluate", "kkt_measure", "optimize_case", "plot_optimization", "read_history", "resolve_x0",
           "run_start", "scaled_evaluation", "set_status", "simulate", "start_points"]
