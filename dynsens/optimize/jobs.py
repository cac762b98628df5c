"""One optimization start: the case's optimizer driven by an :class:`~.problem.Evaluator`, rows streamed to a
sink."""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..executor import cached_case, publish
from .methods import run_method
from .problem import FEAS_TOL, Evaluation, Evaluator, ScaledProblem, Sink, kkt_measure, max_violation

# --------------------------------------------------------------------------------------
# one start (runs in the caller, a worker process or a Dask worker: see dynsens.executor)
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
    method: str = "SLSQP"      # optimization.method (see dynsens.optimize.methods)


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


def _plain(v: Any) -> Any:
    """numpy → plain Python (msgpack-friendly for Dask events)."""
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    return v


def run_start(job: StartJob) -> StartOutcome:
    """Run the case's optimizer for one start; stream every evaluation and iteration row to the
    caller (:func:`dynsens.executor.publish`)."""
    t_begin = time.perf_counter()
    case = cached_case(job.case_text, job.case_source)
    problem = job.problem
    sink: Sink = publish
    sent: list[dict[str, Any]] = []
    seq = [0]
    state: dict[str, Any] = {"n_sim": 0, "failed": 0, "message": "", "t_last": t_begin, "it": job.iteration0}

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
    prev: dict[str, Any] = {"u": ev0.u, "f": ev0.f_scaled}

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

    def on_iteration(uk: np.ndarray) -> None:
        state["it"] += 1
        emit("iteration", iteration_row(evaluator(uk)))

    res = run_method(job.method, evaluator, u0, int(remaining), float(job.ftol), on_iteration)
    ev = evaluator(res.u)
    if ev.failed and evaluator.last_good is not None:
        ev = evaluator.last_good
    out = outcome(ev, res.success, res.status, res.message, state["it"])
    out.slsqp_nit = job.iteration0 + res.nit
    return out
