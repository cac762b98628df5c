r"""Newton-Raphson on the step equation, and the sensitivity solve that reuses it.

Within a step, q, q̇ and p are functions of the unknowns z = [q̈; λ; ṗ] through the
corrector, so the iteration matrix is the total derivative (method.md §3)

.. math:: S = ∂F_R/∂z + (c_q ∂F_R/∂q + c_{q̇} ∂F_R/∂\dot q) E_q + c_p ∂F_R/∂p E_p

with (c_q, c_q̇, c_p) = (βΔt², γΔt, γΔt) for Newmark and (0, 0, 0) for the initial
solve at t0.  The sensitivity step (method.md §4) is the same linear system with the
matrix right-hand side −P: :func:`solve_sensitivity` uses the factor of S at the
converged state handed back by :func:`solve_step`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
import scipy.sparse as sp

from ..errors import ConvergenceError, NonFiniteError
from ..integrators.newmark import Prediction
from ..models.base import Linearization, Model, StepState
from .linalg import Counters, Factor, SingularMatrixError, abs_product


# Componentwise backward error below which a residual is round-off (≈ 500 ε).
ROUNDOFF = 1e-13
# the bound of the round-off test's quick rejection, widened by more than its rounding error
ROUNDOFF_BOUND_MARGIN = 1.01
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


def _real_norm(v: np.ndarray) -> float:
    """2-norm of the real part, scaled so that huge entries do not overflow the sum of squares."""
    if not v.size:
        return 0.0
    r = v.real
    n = math.sqrt(float(r @ r))
    if 0.0 < n < 1e150:             # the common case: no overflow or underflow to guard
        return n
    big = float(np.max(np.abs(r)))
    if big == 0.0 or not np.isfinite(big):
        return big
    return big * float(np.linalg.norm(r / big))


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
        self._scales = [0.0, 0.0, 0.0]   # largest block norms of z so far
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
        """Solve the step equation at time t (s) starting from the guess z0 (n_z,)."""
        st = self.settings
        z = z0.copy()
        history: list[float] = []
        lin: Linearization | None = None
        factor: Factor | None = None
        dz = np.zeros_like(z)   # the last correction; read only from the second iteration on
        for it in range(1, st.max_iterations + 1):
            s = correct(pred, *self._split(z))
            R = self.model.residual(t, s, params)
            self.counters.residual_evaluations += 1
            rnorm = _real_norm(R)
            history.append(rnorm)
            if not math.isfinite(rnorm):
                raise NonFiniteError(self._nonfinite_message(R, s, t, step, it))
            if it > 1 and self._at_roundoff(R, z, rnorm):
                # each residual entry is within round-off of the terms that make it up (Oettli-
                # Prager backward error): no correction can improve z, whatever the conditioning.
                # The last factor is one correction dz away from z
                fresh = self.sensitivities and self._within(z, dz, self.reuse_tolerance)
                return self._accept(t, s, params, coeffs, lin, factor, it - 1, fresh=fresh)
            try:
                lin, factor = self._linearize_and_factor(t, s, params, coeffs)
            except SingularMatrixError as exc:
                why = self.model.diagnose_singular(t, s, params)
                raise ConvergenceError(
                    f"singular iteration matrix ({exc}{'; ' + why if why else ''})", t=t, step=step,
                    iterations=it, residual_history=history,
                    hint="a mechanism at a singular (e.g. dead-centre) configuration, redundant "
                         "constraints, zero masses or unsupported (rigid-body) degrees of freedom: "
                         "change the geometry or the joint set") from None
            dz = factor.solve(-R)
            z = z + dz
            self.counters.newton_iterations += 1
            if not self.newton:
                s = correct(pred, *self._split(z))
                return StepOutcome(s, lin, factor, it)
            if self._converged(z, dz) or self._stagnated(history, z, dz):
                s = correct(pred, *self._split(z))
                return self._accept(t, s, params, coeffs, lin, factor, it, fresh=True)
        # a mechanism that locks (near-dependent constraint equations at the step's start) is not
        # helped by a smaller step: say so instead
        locked = ""
        if self.model.traits.n_lam:
            locked = self.model.diagnose_singular(t, correct(pred, *self._split(z0)), params, rel_tol=LOCK_RTOL)
        raise ConvergenceError(
            "Newton-Raphson did not converge", t=t, step=step, iterations=st.max_iterations,
            residual_history=history,
            hint=(f"the mechanism locks here, near a singular pose ({locked}); a smaller time step "
                  "does not help: check the geometry, the joint set and the driving motion" if locked else
                  "reduce the time step, check that the loads and parameters are physical, "
                  "or raise solver.max_iterations"))

    def _accept(self, t: float, s: StepState, params: Any, coeffs: tuple[float, float, float],
                lin: Linearization | None, factor: Factor | None, iterations: int,
                fresh: bool) -> StepOutcome:
        """Converged at s.  The sensitivity solve needs S at the converged state (method.md §4):
        in ``reuse`` mode the last factor serves when it is ``fresh`` (its iterate is one
        correction within the Newton tolerance, or the reuse tolerance, away from s); otherwise,
        and always in ``converged`` mode, S is factorized again at s."""
        if self.sensitivities and self.refactor and (self.need_converged_factor or not fresh):
            lin, factor = self._linearize_and_factor(t, s, params, coeffs)
        return StepOutcome(s, lin, factor, iterations)

    def _at_roundoff(self, R: np.ndarray, z: np.ndarray, rnorm: float) -> bool:
        """|R_i| ≤ c·ε·(|S| |z|)_i for every row i, with S the last iteration matrix; rnorm = ‖Re R‖₂."""
        S = self._S
        if S is None:
            return False
        # the test implies ‖R‖₂ ≤ c·ε·‖|S| |z|‖₂ ≤ c·ε·‖S‖_F ‖z‖₂: a residual above that bound
        # (with a margin for the bound's own rounding) fails it without forming |S| |z|.  Only
        # where the stored entries are the matrix's own (dense, or sparse without duplicates)
        if not sp.issparse(S) or getattr(S, "has_canonical_format", False):
            data = (S.data if sp.issparse(S) else S.reshape(-1)).real
            if rnorm > ROUNDOFF_BOUND_MARGIN * ROUNDOFF * _real_norm(data) * _real_norm(z):
                return False
        terms = abs_product(S, np.abs(z.real))
        return bool(np.all(np.abs(R.real) <= ROUNDOFF * terms))

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

    def _converged(self, z: np.ndarray, dz: np.ndarray) -> bool:
        return self._within(z, dz, self.settings.rtol)

    def _within(self, z: np.ndarray, dz: np.ndarray, rtol: float) -> bool:
        """The block test of :class:`NewtonSettings` with relative tolerance rtol (updates the
        block scales)."""
        ok = True
        zn, dzn = self._block_norms(z, dz)
        scales = self._scales
        atol = self.settings.atol
        for i, k in enumerate(self._present):
            scales[k] = max(scales[k], zn[i])
            # a block that has been exactly zero so far (accelerations of a static start) has
            # no scale of its own: measure its correction against the whole unknown vector
            ref = max(zn[i], scales[k]) if scales[k] > 0 else _real_norm(z)
            if dzn[i] > rtol * ref + atol:
                ok = False
        return ok

    def _stagnated(self, history: list[float], z: np.ndarray, dz: np.ndarray) -> bool:
        """Newton at the noise floor: the last two residual norms are not below half the best
        one before them, while the whole correction is within the tolerance of ‖z‖.  A block
        that is nothing but round-off (the accelerations of a static start, ~1e-11 against
        multipliers of 1e7) can meet neither its own relative test nor the round-off test."""
        if len(history) < 3:
            return False
        floor = 0.5 * min(history[:-2])
        st = self.settings
        return history[-1] > floor and history[-2] > floor and \
            _real_norm(dz) <= st.rtol * _real_norm(z) + st.atol

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
