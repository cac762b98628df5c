r"""Newton-Raphson on the step equation, and the sensitivity solve that reuses it.

Within a step, q, q̇ and p are functions of the unknowns z = [q̈; λ; ṗ] through the
corrector, so the iteration matrix is the total derivative (method.md §3)

.. math:: S = ∂F_R/∂z + (c_q ∂F_R/∂q + c_{q̇} ∂F_R/∂\dot q) E_q + c_p ∂F_R/∂p E_p

with (c_q, c_q̇, c_p) = (βΔt², γΔt, γΔt) for Newmark and (0, 0, 0) for the initial
solve at t0.  The sensitivity step (method.md §4) is the same linear system with the
matrix right-hand side −P: :func:`solve_sensitivity` uses the factor of S at the
converged state handed back by :func:`solve_step`.

The iteration itself is :func:`.newton_core.newton_iterations`, defined once: here it runs as
Python on the model's methods and :class:`~.linalg.Factor` (:class:`_PythonStep`), or compiled
when the model offers a compiled step (:meth:`~dynsens.models.base.Model.compiled_step`); this
module keeps the solver's memory between steps and turns how an iteration ended into the
outcome or the error.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
import scipy.sparse as sp

from ..errors import ConvergenceError, NonFiniteError
from ..integrators.newmark import Prediction
from ..models.base import Linearization, Model, StepState
from .linalg import Counters, Factor, SingularMatrixError, abs_product
from .newton_core import (AT_ROUNDOFF, CONVERGED, NOT_FINITE, ROUNDOFF, ROUNDOFF_BOUND_MARGIN, SINGULAR,
                          SOLVED_LINEAR, above_roundoff_bound, newton_iterations, real_norm as _real_norm,
                          within_roundoff)

__all__ = ["ROUNDOFF", "ROUNDOFF_BOUND_MARGIN", "NewtonSettings", "StepOutcome", "StepSolver"]


# σ_min/σ_max of the constraint Jacobian below which a failing step is reported as a lock-up
LOCK_RTOL = 1e-2
# factors of a constant iteration matrix kept, one per coefficient triple (oldest dropped first)
MAX_CACHED_FACTORS = 64


@dataclass(frozen=True)
class NewtonSettings:
    """Newton tolerances: converged when, for every block b of z (q̈, λ, ṗ),
    ‖Δz_b‖ ≤ rtol·max(‖z_b‖, scale_b) + atol, scale_b being the largest ‖z_b‖ seen so far
    in the run (so the test is relative to the problem's own magnitudes, in any units); a
    block that has been zero throughout is measured against ‖z‖.  Two more acceptances, both at
    round-off: every residual entry within round-off of the terms S·z that make it up, or the
    residual norm stalled at its noise floor while ‖Δz‖ ≤ rtol·‖z‖ + atol (a block that is
    nothing but round-off cannot meet its own relative test)."""

    rtol: float = 1e-10
    atol: float = 0.0
    max_iterations: int = 25


@dataclass
class StepOutcome:
    """Result of one step solve: new state, linearization and factor at the solution."""

    state: StepState
    lin: Linearization | None
    factor: Factor | None
    iterations: int
    finite: bool = False      # every entry of the state is known to be finite (a compiled step checked)


class StepSolver:
    """Solves F_R(z) = 0 on one step; one instance per run holds the plan and the counters.

    Parameters
    ----------
    model : the residual.
    newton : whether Newton iterations are needed (False for linear models: one solve).
    refactor : whether S changes during the run (False for constant matrices: factor once
        per distinct coefficient triple).
    need_converged_factor : always factor S at the converged state for the sensitivity solve
        (``sensitivity.matrix: converged``).
    sensitivities : sensitivities follow each step (a stale factor must then be renewed).
    reuse_tolerance : relative size of the last Newton correction up to which the factor of
        the iterate before it still serves the sensitivity solve when Newton stops on a
        round-off residual (its error is of that size); at most the Newton tolerance unless
        the design partials are themselves no more accurate (forward differences).
    """

    def __init__(self, model: Model, settings: NewtonSettings, counters: Counters, *,
                 newton: bool, refactor: bool, need_converged_factor: bool, sensitivities: bool = False,
                 reuse_tolerance: float = 0.0):
        self.model = model
        self.settings = settings
        self.counters = counters
        self.newton = newton
        self.refactor = refactor
        self.need_converged_factor = need_converged_factor
        self.sensitivities = sensitivities
        self.reuse_tolerance = max(reuse_tolerance, settings.rtol)
        t = model.traits
        self._blocks = [slice(0, t.n_q), slice(t.n_q, t.n_q + t.n_lam),
                        slice(t.n_q + t.n_lam, t.n_z)]
        self._present = [k for k, n in enumerate((t.n_q, t.n_lam, t.n_p)) if n]
        self._starts = np.array([self._blocks[k].start for k in self._present], dtype=np.intp)
        self._present_array = np.array(self._present, dtype=np.intp)
        self._scales = [0.0, 0.0, 0.0]   # largest block norms of z so far
        # the model's compiled step, when it has one for real runs (None: the iteration in Python)
        offer = getattr(model, "compiled_step", None)     # (a model outside the Model base may lack it)
        self._compiled_step = offer(newton, refactor) if offer is not None else None
        self._cache: dict[tuple[float, float, float], tuple[Linearization, Factor]] = {}
        self._S: Any = None  # the last iteration matrix, for the round-off test
        self._dense_general = False

    def _split(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        b = self._blocks
        return z[b[0]], z[b[1]], z[b[2]]

    def _linearize_and_factor(self, t: float, s: StepState, params: Any,
                              coeffs: tuple[float, float, float]) -> tuple[Linearization, Factor]:
        if not self.refactor and coeffs in self._cache:
            return self._cache[coeffs]
        self.counters.linearizations += 1
        lin = self.model.linearize(t, s, params)
        S = lin.iteration_matrix(*coeffs, n_q=self.model.traits.n_q)
        self._S = S
        factor = Factor(S, self.counters, dense_general=self._dense_general, within=lin.dense_pattern)
        # the structure of S does not change: a dense S that was not diagonal stays so
        self._dense_general = factor.kind == "dense" or (factor.kind == "banded" and isinstance(S, np.ndarray))
        if coeffs != (0.0, 0.0, 0.0):
            self.counters.step_factorizations += 1
        if not self.refactor:
            if len(self._cache) >= MAX_CACHED_FACTORS:   # adaptive steps: a new triple per step size
                del self._cache[next(iter(self._cache))]
            self._cache[coeffs] = (lin, factor)
        return lin, factor

    def solve_step(self, t: float, step: int, pred: Prediction, z0: np.ndarray, params: Any,
                   coeffs: tuple[float, float, float],
                   correct: Callable[[Prediction, np.ndarray, np.ndarray, np.ndarray], StepState]
                   ) -> StepOutcome:
        """Solve the step equation at time t (s) starting from the guess z0 (n_z,): the
        iteration of :func:`.newton_core.newton_iterations`, compiled when the model offers a
        compiled step for it (a step with the scheme's corrector, coefficients not all zero)."""
        st = self.settings
        history = np.empty(st.max_iterations)
        compiled = self.compiled_for(t, pred, params, coeffs)
        args = self._settings_arguments()
        result = None
        if compiled is not None:
            scales = np.array(self._scales)      # (compiled: typed arrays)
            try:
                result = compiled.iterate(z0.copy(), *args, scales, self._present_array, history)
            except ZeroDivisionError:
                # a law divided by zero (a spring whose two ends met): the Python path takes the
                # step again, and its evaluation names the element (a ModelError, no traceback)
                compiled = None
        if compiled is None:
            ops = _PythonStep(self, t, pred, params, coeffs, correct)
            status, it, z, dz, s, R, lf, fresh, n_res, n_lin = newton_iterations(
                ops, z0.copy(), *args, self._scales, self._present, history)
            lin, factor = lf if lf is not None else (None, None)
            finite = False        # (not known: the stepper looks)
            self.counters.residual_evaluations += n_res
            self.counters.newton_iterations += n_lin - (status == SINGULAR)
        else:
            assert result is not None
            status, it, z, dz, s, R, lf, fresh, n_res, n_lin, kept, finite = result
            self.keep_scales(scales)
            s = compiled.state(s)
            if status == CONVERGED or status == AT_ROUNDOFF:
                compiled.keep(s, kept)
            lin, factor, self._S = compiled.linearization_and_factor(lf, self.counters, self.sensitivities)
            self.count_compiled(n_res, n_lin, status == SINGULAR)
        if status == CONVERGED or status == AT_ROUNDOFF or status == SOLVED_LINEAR:
            return self._outcome(t, s, params, coeffs, lin, factor, it, status, fresh, finite)
        if status == NOT_FINITE:
            raise NonFiniteError(self._nonfinite_message(R, s, t, step, it))
        residual_history = history[:it].tolist()
        if status == SINGULAR:
            reason = ops.error if compiled is None else compiled.singular_reason(lf)
            why = self.model.diagnose_singular(t, s, params)
            raise ConvergenceError(
                f"singular iteration matrix ({reason}{'; ' + why if why else ''})", t=t, step=step,
                iterations=it, residual_history=residual_history,
                hint=self.model.singular_hint)
        # a mechanism that locks (near-dependent constraint equations at the step's start) is not
        # helped by a smaller step: say so instead
        locked = ""
        if self.model.traits.n_lam:
            locked = self.model.diagnose_singular(t, correct(pred, *self._split(z0)), params, rel_tol=LOCK_RTOL)
        raise ConvergenceError(
            "Newton-Raphson did not converge", t=t, step=step, iterations=st.max_iterations,
            residual_history=residual_history,
            hint=(f"the mechanism locks here, near a singular pose ({locked}); a smaller time step "
                  "does not help: check the geometry, the joint set and the driving motion" if locked else
                  "reduce the time step, check that the loads and parameters are physical, "
                  "or raise solver.max_iterations"))

    @property
    def has_compiled_step(self) -> bool:
        """Whether the model offers compiled steps for this run's iterations."""
        return self._compiled_step is not None

    def compiled_for(self, t: float, pred: Prediction, params: Any, coeffs: tuple[float, float, float]) -> Any:
        """The model's compiled step (a :class:`~.compiled_iteration.CompiledStep`) for the step
        ending at t (s) with this prediction and corrector coefficients, or None: the iteration
        runs in Python (no compiled step for the model or this step; the initial solve)."""
        if self._compiled_step is None or coeffs == (0.0, 0.0, 0.0):
            return None
        return self._compiled_step(t, pred, params, coeffs)

    def iteration_arguments(self) -> tuple:
        """The arguments of a compiled block of steps after its steps (:mod:`.compiled_march`):
        the tolerances, Newton or one solve, whether sensitivities follow, the block scales (a new
        array: the compiled steps update it), the present blocks and a residual history."""
        return (*self._settings_arguments(), np.array(self._scales), self._present_array,
                np.empty(self.settings.max_iterations))

    def _settings_arguments(self) -> tuple:
        """The iteration's settings after its step data and unknowns: the tolerances, Newton or
        one solve, whether sensitivities follow."""
        st = self.settings
        return (st.rtol, st.atol, self.reuse_tolerance, st.max_iterations, self.newton, self.sensitivities)

    def keep_scales(self, scales: np.ndarray) -> None:
        """The block scales (3,) after a compiled step: the solver's memory for the next step."""
        self._scales = scales.tolist()

    def count_compiled(self, n_res: int, n_lin: int, singular: bool) -> None:
        """Count the work of a compiled iteration: n_res residuals, n_lin linearizations and
        factorizations, each followed by a solve unless S was singular."""
        c = self.counters
        c.linearizations += n_lin
        c.factorizations += n_lin
        c.step_factorizations += n_lin
        solves = n_lin - singular
        c.solves += solves
        c.solve_columns += solves
        c.residual_evaluations += n_res
        c.newton_iterations += solves

    def compiled_outcome(self, compiled: Any, t: float, s: StepState, params: Any,
                         coeffs: tuple[float, float, float], status: int, iterations: int, lf: Any,
                         fresh: bool, n_res: int, n_lin: int, scales: np.ndarray) -> StepOutcome:
        """The outcome of a step a compiled block took (:mod:`dynsens.timeloop.step_blocks`):
        what :meth:`solve_step` makes of a compiled iteration that ended in state s at time t
        (s) with this status, last linearization and factor ``lf`` and block scales, its work
        counted; ``compiled``: the :class:`~.compiled_iteration.CompiledStep` of that step."""
        self.keep_scales(scales)
        lin, factor, self._S = compiled.linearization_and_factor(lf, self.counters, self.sensitivities) \
            if lf is not None else (None, None, None)
        self.count_compiled(n_res, n_lin, False)
        return self._outcome(t, s, params, coeffs, lin, factor, iterations, status, fresh, True)

    def _outcome(self, t: float, s: StepState, params: Any, coeffs: tuple[float, float, float],
                 lin: Linearization | None, factor: Factor | None, iterations: int, status: int, fresh: bool,
                 finite: bool) -> StepOutcome:
        """The outcome of an iteration that ended with an accepted status (converged, at
        round-off or one linear solve)."""
        if status == SOLVED_LINEAR:
            return StepOutcome(s, lin, factor, iterations, finite)
        return self._accept(t, s, params, coeffs, lin, factor, iterations, status == CONVERGED or fresh, finite)

    def _accept(self, t: float, s: StepState, params: Any, coeffs: tuple[float, float, float],
                lin: Linearization | None, factor: Factor | None, iterations: int,
                fresh: bool, finite: bool) -> StepOutcome:
        """Converged at s.  The sensitivity solve needs S at the converged state (method.md §4):
        in ``reuse`` mode the last factor serves when it is ``fresh`` (its iterate is one
        correction within the Newton tolerance, or the reuse tolerance, away from s); otherwise,
        and always in ``converged`` mode, S is factorized again at s."""
        if self.sensitivities and self.refactor and (self.need_converged_factor or not fresh):
            lin, factor = self._linearize_and_factor(t, s, params, coeffs)
        return StepOutcome(s, lin, factor, iterations, finite)

    def _at_roundoff(self, R: np.ndarray, z: np.ndarray, rnorm: float) -> bool:
        """|R_i| ≤ c·ε·(|S| |z|)_i for every row i, with S the last iteration matrix; rnorm = ‖Re R‖₂."""
        S = self._S
        if S is None:
            return False
        # the quick rejection only where the stored entries are the matrix's own (dense, or
        # sparse without duplicates)
        if not sp.issparse(S) or getattr(S, "has_canonical_format", False):
            if above_roundoff_bound(rnorm, (S.data if sp.issparse(S) else S.reshape(-1)).real, z):
                return False
        return within_roundoff(R, abs_product(S, np.abs(z.real)))

    def _nonfinite_message(self, R: np.ndarray, s: StepState, t: float, step: int, it: int) -> str:
        """Say where a non-finite residual comes from: an overflowing (diverging) coordinate,
        or, when the state is still moderate, the equation that produced NaN (parameters)."""
        head = f"NaN/Inf appeared at t = {t:.6g} s (step {step}), Newton iteration {it}"
        q = np.abs(s.q.real)
        if q.size and np.all(np.isfinite(q)) and np.max(q) > 1e100:
            k = int(np.argmax(q))
            return (f"{head}: the solution diverges at {self.model.describe_equation(k)} (|q| = {q[k]:.3g}); "
                    "reduce the time step, check the stiffness signs and the load magnitudes")
        k = int(np.flatnonzero(~np.isfinite(R))[0])
        where = self.model.describe_equation(k)   # the DOF and the YAML entries acting there
        return (f"{head}: first in the equation of {where}; check the parameters of the elements "
                "acting there, the initial conditions and the time step")

    def _block_norms(self, z: np.ndarray, dz: np.ndarray) -> tuple[list[float], list[float]]:
        """2-norms of the real parts of the present blocks of z and dz (one reduction for both;
        the overflow-safe :func:`_real_norm` per block when the squares overflow)."""
        r = np.array((z.real, dz.real))
        sq = np.add.reduceat(r * r, self._starts, axis=1)
        if sq.max() < 1e300:
            zn, dzn = np.sqrt(sq).tolist()
            return zn, dzn
        return ([_real_norm(z[self._blocks[k]]) for k in self._present],
                [_real_norm(dz[self._blocks[k]]) for k in self._present])

    def snapshot(self) -> tuple[list[float], Any, bool]:
        """What the next steps' convergence decisions depend on (block scales, the last
        iteration matrix of the round-off test, the factor kind): a run restarted from a
        checkpoint with it repeats the same iterations bit for bit."""
        return list(self._scales), self._S, self._dense_general

    def restore(self, snap: tuple[list[float], Any, bool]) -> None:
        """Return to a :meth:`snapshot`."""
        self._scales, self._S, self._dense_general = list(snap[0]), snap[1], snap[2]

    def solve_sensitivity(self, factor: Factor, pseudo_load: np.ndarray) -> np.ndarray:
        """∇z (n_z, m) from S ∇z = −P with the factor of the converged step."""
        return factor.solve(-pseudo_load)


class _PythonStep:
    """The step operations of :mod:`.newton_core` for any model, run as Python: the model's
    residual and linearization, :class:`~.linalg.Factor` and the solver's tests."""

    __slots__ = ("solver", "t", "pred", "params", "coeffs", "correct_fn", "error")

    def __init__(self, solver: StepSolver, t: float, pred: Prediction, params: Any,
                 coeffs: tuple[float, float, float],
                 correct: Callable[[Prediction, np.ndarray, np.ndarray, np.ndarray], StepState]):
        self.solver, self.t, self.pred, self.params = solver, t, pred, params
        self.coeffs, self.correct_fn = coeffs, correct
        self.error = ""        # why S was singular

    def correct(self, z: np.ndarray) -> StepState:
        return self.correct_fn(self.pred, *self.solver._split(z))

    def residual(self, s: StepState) -> tuple[np.ndarray, None]:
        return self.solver.model.residual(self.t, s, self.params), None

    def factor_solve(self, s: StepState, evaluation: None, rhs: np.ndarray
                     ) -> tuple[bool, tuple[Linearization, Factor] | None, np.ndarray]:
        try:
            lin, factor = self.solver._linearize_and_factor(self.t, s, self.params, self.coeffs)
        except SingularMatrixError as exc:
            self.error = str(exc)
            return False, None, rhs
        return True, (lin, factor), factor.solve(rhs)

    def no_factor(self) -> None:
        return None

    def at_roundoff(self, lf: Any, R: np.ndarray, z: np.ndarray, rnorm: float) -> bool:
        return self.solver._at_roundoff(R, z, rnorm)

    def block_norms(self, z: np.ndarray, dz: np.ndarray) -> tuple[list[float], list[float]]:
        return self.solver._block_norms(z, dz)
