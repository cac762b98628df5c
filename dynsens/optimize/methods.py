"""The optimizers behind ``optimization.method``, each driven through the same scaled problem.

Every method minimizes f_s(u) subject to g(u) ≥ 0 (and g(u) = 0 where a constraint is an
equality) in the bounds of u, with the exact gradients of one simulation per design point
(:class:`~.problem.Evaluator`), and calls ``on_iteration(u)`` once per iteration so that the
history, the KKT measure and ``--resume`` are the same for all:

* ``SLSQP`` (scipy): sequential quadratic programming with a dense quasi-Newton Hessian:
  O(m²) memory and O(m³) per iteration; the default, fastest for tens of variables.
* ``MMA`` and ``CCSAQ`` (nlopt, Svanberg's method of moving asymptotes and its conservative
  convex separable quadratic sibling): one separable convex subproblem per iteration, O(m·n_c)
  memory: for hundreds to thousands of variables.  Inequality constraints only.  An iteration
  is one design nlopt evaluates (inner iterations included); ``maxiter`` bounds them.
* ``trust-constr`` (scipy): an interior-point / trust-region method with a quasi-Newton (BFGS)
  Hessian of the Lagrangian.
* ``IPOPT`` (cyipopt, Wächter & Biegler's primal-dual interior-point filter line-search method):
  the exact gradients and a limited-memory (L-BFGS) Hessian of the Lagrangian, O(m·k) memory:
  for many variables, with equality constraints.  Needs the Ipopt library (Debian:
  ``coinor-libipopt-dev``) and ``pip install 'dynsens[ipopt]'``.

``--resume`` restarts the method at the last recorded iterate; none of these keeps a state
that the file could restore (SLSQP's Hessian, MMA's asymptotes are rebuilt).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..case.optimization import METHODS
from .problem import Evaluator, OptimizationError, ScaledProblem

EXTRA = {"MMA": "mma", "CCSAQ": "mma", "IPOPT": "ipopt"}
MODULE = {"mma": "nlopt", "ipopt": "cyipopt"}     # the module each extra provides


@dataclass
class MethodResult:
    """What a method ends with: its last design (scaled), whether it converged, its own status
    code and message, and its iteration count."""

    u: np.ndarray
    success: bool
    status: int
    message: str
    nit: int


def _split(problem: ScaledProblem) -> tuple[list[int], list[int]]:
    ineq = [i for i, c in enumerate(problem.constraints) if c.kind != "eq"]
    eq = [i for i, c in enumerate(problem.constraints) if c.kind == "eq"]
    return ineq, eq


def check_method(method: str, problem: ScaledProblem) -> None:
    """Raise OptimizationError when ``method`` is unknown, not installed or cannot take the problem."""
    if method not in METHODS:
        raise OptimizationError(f"optimization.method: expected one of {', '.join(METHODS)}, found {method!r}")
    if method in EXTRA:
        module = MODULE[EXTRA[method]]
        try:
            __import__(module)
        except ImportError:
            library = " and the Ipopt library (Debian: apt-get install coinor-libipopt-dev)" \
                if method == "IPOPT" else ""
            raise OptimizationError(f"optimization.method: {method} needs {module}{library}: pip install "
                                    f"'dynsens[{EXTRA[method]}]'") from None
        if method != "IPOPT" and _split(problem)[1]:
            raise OptimizationError(f"optimization.method: {method} takes inequality constraints only; the "
                                    "case has an equality (lower == upper): use SLSQP or trust-constr")


def run_method(method: str, evaluator: Evaluator, u0: np.ndarray, maxiter: int, ftol: float,
               on_iteration: Callable[[np.ndarray], None]) -> MethodResult:
    """Run ``method`` from the scaled design ``u0`` for at most ``maxiter`` iterations."""
    problem = evaluator.problem
    check_method(method, problem)
    if method == "SLSQP":
        return _slsqp(evaluator, u0, maxiter, ftol, on_iteration)
    if method == "trust-constr":
        return _trust_constr(evaluator, u0, maxiter, ftol, on_iteration)
    if method == "IPOPT":
        return _ipopt(evaluator, u0, maxiter, ftol, on_iteration)
    return _nlopt(method, evaluator, u0, maxiter, ftol, on_iteration)


def _slsqp(evaluator: Evaluator, u0: np.ndarray, maxiter: int, ftol: float,
           on_iteration: Callable[[np.ndarray], None]) -> MethodResult:
    from scipy.optimize import Bounds, minimize
    problem = evaluator.problem
    cons = []
    for typ, idx in zip(("ineq", "eq"), _split(problem)):
        if idx:
            cons.append({"type": typ, "fun": evaluator.cons, "jac": evaluator.cons_jac, "args": (idx,)})
    lo, up = problem.u_bounds
    res = minimize(evaluator.fun, u0, jac=evaluator.jac, method="SLSQP", bounds=Bounds(lo, up),
                   constraints=cons, callback=on_iteration, options={"maxiter": int(maxiter), "ftol": float(ftol)})
    return MethodResult(np.asarray(res.x, dtype=float), bool(res.success), int(res.status), f"SLSQP: {res.message}",
                        int(res.nit))


INTERIOR = 1e-3     # trust-constr's start: this share of each variable's range inside its bounds


def _trust_constr(evaluator: Evaluator, u0: np.ndarray, maxiter: int, ftol: float,
                  on_iteration: Callable[[np.ndarray], None]) -> MethodResult:
    from scipy.optimize import BFGS, Bounds, NonlinearConstraint, minimize
    problem = evaluator.problem
    cons = []
    for idx, upper in zip(_split(problem), (np.inf, 0.0)):
        if idx:
            cons.append(NonlinearConstraint(lambda u, idx=idx: evaluator.cons(u, idx), 0.0, upper,
                                            jac=lambda u, idx=idx: evaluator.cons_jac(u, idx), hess=BFGS()))
    lo, up = problem.u_bounds
    count = [0]

    def callback(u: np.ndarray, state: object) -> bool:
        count[0] += 1
        on_iteration(np.asarray(u, dtype=float))
        return False

    # an interior-point method: a start on a bound (barrier infinite) ends at once with "xtol"
    # and the start reported as the optimum; start a little inside
    width = np.where(np.isfinite(up - lo), up - lo, 1.0)
    u0 = np.clip(u0, lo + INTERIOR * width, up - INTERIOR * width)
    # scipy counts the first call (at u0) as an iteration: maxiter + 1 calls of the callback at most
    res = minimize(evaluator.fun, u0, jac=evaluator.jac, hess=BFGS(), method="trust-constr",
                   bounds=Bounds(lo, up, keep_feasible=True), constraints=cons, callback=callback,
                   options={"maxiter": int(maxiter), "gtol": float(ftol), "xtol": float(ftol) * 1e-2})
    success = bool(res.success) and int(res.status) in (1, 2)
    return MethodResult(np.asarray(res.x, dtype=float), success, int(res.status), f"trust-constr: {res.message}",
                        count[0])


def _nlopt(method: str, evaluator: Evaluator, u0: np.ndarray, maxiter: int, ftol: float,
           on_iteration: Callable[[np.ndarray], None]) -> MethodResult:
    import nlopt
    problem = evaluator.problem
    m = u0.size
    opt = nlopt.opt(nlopt.LD_MMA if method == "MMA" else nlopt.LD_CCSAQ, m)
    lo, up = problem.u_bounds
    opt.set_lower_bounds(np.where(np.isfinite(lo), lo, -np.inf))
    opt.set_upper_bounds(np.where(np.isfinite(up), up, np.inf))
    calls = [0]
    best: list[np.ndarray] = [np.asarray(u0, dtype=float)]

    def objective(u: np.ndarray, grad: np.ndarray) -> float:
        u = np.array(u, dtype=float)
        if calls[0] > 0:              # the first call is the start design, already recorded
            on_iteration(u)
        calls[0] += 1
        if grad.size:
            grad[:] = evaluator.jac(u)
        best[0] = u
        return float(evaluator.fun(u))

    ineq, _ = _split(problem)
    if ineq:
        def constraints(result: np.ndarray, u: np.ndarray, grad: np.ndarray) -> None:
            # nlopt's form c(u) <= 0 is -g(u) <= 0
            result[:] = -evaluator.cons(np.array(u, dtype=float), ineq)
            if grad.size:
                grad[:] = -evaluator.cons_jac(np.array(u, dtype=float), ineq)
        opt.add_inequality_mconstraint(constraints, np.zeros(len(ineq)))
    opt.set_min_objective(objective)
    opt.set_ftol_rel(float(ftol))
    opt.set_maxeval(int(maxiter) + 1)
    try:
        u = opt.optimize(np.asarray(u0, dtype=float))
        code = int(opt.last_optimize_result())
    except nlopt.RoundoffLimited:
        u, code = best[0], nlopt.ROUNDOFF_LIMITED
    except (RuntimeError, ValueError) as exc:
        return MethodResult(best[0], False, -1, f"{method} failed: {exc}", max(calls[0] - 1, 0))
    messages = {nlopt.SUCCESS: "converged", nlopt.STOPVAL_REACHED: "stop value reached",
                nlopt.FTOL_REACHED: "relative change of the objective below ftol",
                nlopt.XTOL_REACHED: "change of the design below xtol",
                nlopt.MAXEVAL_REACHED: "iteration limit reached", nlopt.MAXTIME_REACHED: "time limit reached",
                nlopt.ROUNDOFF_LIMITED: "stopped by round-off"}
    success = code in (nlopt.SUCCESS, nlopt.FTOL_REACHED, nlopt.XTOL_REACHED, nlopt.STOPVAL_REACHED)
    return MethodResult(np.asarray(u, dtype=float), success, code, f"{method}: {messages.get(code, code)}",
                        max(calls[0] - 1, 0))


def _ipopt(evaluator: Evaluator, u0: np.ndarray, maxiter: int, ftol: float,
           on_iteration: Callable[[np.ndarray], None]) -> MethodResult:
    import cyipopt
    problem = evaluator.problem
    ineq, eq = _split(problem)
    order = ineq + eq                      # g ≥ 0 for the inequalities, g = 0 for the equalities
    last: list[np.ndarray] = [np.asarray(u0, dtype=float)]
    count = [0]

    class _Problem:
        def objective(self, u: np.ndarray) -> float:
            last[0] = np.array(u, dtype=float)
            return float(evaluator.fun(last[0]))

        def gradient(self, u: np.ndarray) -> np.ndarray:
            return np.asarray(evaluator.jac(np.array(u, dtype=float)), dtype=float)

        def constraints(self, u: np.ndarray) -> np.ndarray:
            return np.asarray(evaluator.cons(np.array(u, dtype=float), order), dtype=float)

        def jacobian(self, u: np.ndarray) -> np.ndarray:
            # dense, row-major: IPOPT's default structure when none is given
            return np.asarray(evaluator.cons_jac(np.array(u, dtype=float), order), dtype=float).ravel()

        def intermediate(self, alg_mod: int, iter_count: int, *args: float) -> bool:
            # Ipopt < 3.14 does not hand the iterate to the callback: the accepted point is the
            # last one whose objective the line search evaluated; iteration 0 is the start
            if iter_count > 0:
                count[0] = iter_count
                on_iteration(last[0])
            return True

    lo, up = problem.u_bounds
    nlp = cyipopt.Problem(n=u0.size, m=len(order), problem_obj=_Problem(),
                          lb=np.where(np.isfinite(lo), lo, -1e20), ub=np.where(np.isfinite(up), up, 1e20),
                          cl=np.zeros(len(order)), cu=np.r_[np.full(len(ineq), 1e20), np.zeros(len(eq))])
    for key, value in (("hessian_approximation", "limited-memory"), ("max_iter", int(maxiter)),
                       ("tol", float(ftol)), ("print_level", 0), ("sb", "yes")):
        nlp.add_option(key, value)
    u, info = nlp.solve(np.asarray(u0, dtype=float))
    status = int(info["status"])
    # 0: solved, 1: solved to the acceptable level, 3: the step became tiny for several iterations
    # (Ipopt's STOP_AT_TINY_STEP: x no longer changes at machine precision; a tol below the
    # attainable KKT accuracy ends here, at the optimum; feasibility is checked after the method)
    message = info["status_msg"]
    message = message.decode() if isinstance(message, bytes) else str(message)
    return MethodResult(np.asarray(u, dtype=float), status in (0, 1, 3), status, f"IPOPT: {message}", count[0])
