"""The scaled optimization problem: design and constraint scaling, one memoized simulation per
design point, KKT measure (see the package docstring)."""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np

from ..case.load import Case
from ..errors import DynsensError
from ..simulation import run_case


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
    index: int = -1      # its entry in optimization.constraints (-1: files written before it was kept)

    @property
    def sign(self) -> float:
        """∂g/∂r · d: −1 for an upper bound, +1 otherwise."""
        return -1.0 if self.kind == "upper" else 1.0

    def scaled(self, r: float) -> float:
        """g of response value ``r`` (its unit): ≥ 0 holds (= 0 for an equality)."""
        return self.sign * (r - self.bound) / self.divisor

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
    for j, c in enumerate(spec.constraints):
        r0 = float(ref_responses[c.response])

        def divisor(b: float, r0: float = r0) -> float:
            if b != 0:
                return abs(float(b))
            return abs(r0) if np.isfinite(r0) and r0 != 0 else 1.0
        if c.lower is not None and c.upper is not None and c.lower == c.upper:
            terms.append(ConstraintTerm(c.response, "eq", float(c.upper), divisor(c.upper), j))
            continue
        if c.upper is not None:
            terms.append(ConstraintTerm(c.response, "upper", float(c.upper), divisor(c.upper), j))
        if c.lower is not None:
            terms.append(ConstraintTerm(c.response, "lower", float(c.lower), divisor(c.lower), j))
    return ScaledProblem(case.design_names, case.lower, case.upper, case.scale, spec.objective, f_ref,
                         tuple(terms), tuple(case.response_names))


def _spec(case: Case) -> Any:
    if case.optimization is None:
        raise OptimizationError(f"{case.source} has no 'optimization' section: add one with an objective "
                                "and constraints (see docs/case-files.md and docs/optimization.md)")
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
    """One primal + sensitivity run at physical design ``x`` (m,) (one per load case of a
    `~dynsens.case.load_cases.LoadCaseSet`).

    Returns ``(result, "", wall_time)`` or ``(None, message, wall_time)`` when the simulation
    failed (wall time in s); never raises for a simulation failure.
    """
    from ..case.load_cases import LoadCaseSet
    t0 = time.perf_counter()
    res: Any
    try:
        if isinstance(case, LoadCaseSet):     # every load case: responses RESPONSE@LOADCASE
            res = case.run(np.asarray(x, dtype=float))
        else:
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
        g[i] = c.scaled(r)
        grad_g[i] = c.sign * dr / c.divisor
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
    """Memoized objective/constraint functions for the optimizers: one simulation per design point.

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


def _fmt(x: np.ndarray) -> str:
    return "[" + ", ".join(f"{v:.6g}" for v in np.asarray(x, dtype=float)) + "]"
