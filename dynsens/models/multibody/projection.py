r"""Projection of each accepted step's end state onto the constraint manifolds (``model.projection``).

The index-1 form holds the constraints at the acceleration level only; its positions and
velocities drift (‖Φ‖ ≈ 1e-6…1e-4 over a run).  With ``model.projection`` on, the state that
Newmark and Newton produced at the end of a step, (q, q̇), is moved onto the constraint
manifolds along the rows of J₀ = J_Φ(q, t; x) at that state (joints and Euler-parameter
normalisations):

    position:  q* = q + J₀ᵀ ν,    Φ(q*, t; x) = 0
    velocity:  q̇* = q̇ − J₀ᵀ κ,    Φ̇(q*, q̇*, t; x) = J_Φ(q*) q̇* + Φ_t = 0

(to first order the plain minimum-norm projection; the correction is of the size of the drift).
Both are solved by chord iterations with the matrix J₀J₀ᵀ, factorized once: each iteration costs
one evaluation of Φ (or Φ̇) and converges at a rate of the size of the drift.  q̈, λ and ṗ stay
as solved.  In mode ``state`` the run continues from (q*, q̇*); in mode ``output`` it continues
from the solved state (the index-1 integration is unchanged) and reports (q*, q̇*): histories,
outputs, responses, events and monitors.

Derivatives.  The projection is a map (q, q̇, x) → (q*, q̇*) of the step's end state and the
design, so the procedure the gradient differentiates is "Newmark step, then projection".  Its
Jacobian with respect to (q, q̇) comes from the linearized equations of the converged projection
(implicit-function theorem, :mod:`.projection_adjoint`): the direct mode applies it along its m
sensitivity columns, the adjoint its transpose along its r bars, neither forming it.  Without
compiled kinematics it is taken by batched complex step of the projection itself (Newton
iterations from the converged solution with its matrix M; for the adjoint all 2 n_q columns).
Its design partials — Φ and J_Φ depend on the design through lengths, points and axes — are
taken by the run's design-partials method:

    [∇q*; ∇q̇*] = A [∇q; ∇q̇] + B_x

In mode ``state`` the direct mode applies this map after the step's correction and the adjoint
its transpose before the correction's transpose (B_xᵀ of the bars joins x̄); in mode ``output``
only the reported sensitivities (direct) or the responses' seeds (adjoint) pass through it.  The
checkpointed segments of the adjoint take the same steps again, projection included.  The
design partials of the step's residual are taken at the state Newton converged to
(``Projection.raw``), where the step's equations hold.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ...case_keys import allowed
from ...errors import ModelError, ProblemCollector
from .._keys import check_keys
from ..base import StepState
from . import compiled_linearization as clin
from .assembly import jacobian_rows
from .kernel_compiled import CompiledKin
from .projection_factor import _Factored
from .projection_metric import InverseMetric, inverse_metric

if TYPE_CHECKING:  # pragma: no cover
    from .model import MultibodyModel

Array = np.ndarray
_H = 1e-30          # complex step of the state columns
# constraint equations from which a model on the sparse path projects with sparse J_Φ and
# SuperLU; below, dense J_Φ and LAPACK cost less (N-four-bar, direct mode with projection:
# dense ahead at 146 equations, sparse at 286; BENCHMARKS.md)
SPARSE_MIN_EQ = 200
MAP_BLOCK = 64      # columns of the adjoint's projection map taken in one batch


@dataclass(frozen=True)
class ProjectionSettings:
    """``model.projection``: convergence of the position projection.

    tol : relative bound on the last Newton correction, ‖Δq‖ ≤ tol (1 + ‖q‖) (dimensionless).
    max_iterations : iterations before the run stops with a ModelError.
    mode : ``output`` (the run continues from the solved state; what it reports is projected)
        or ``state`` (the run continues from the projected state).
    metric : ``euclidean`` (nearest state in the 2-norm) or ``mass`` (in the norm of the mass
        matrix; :mod:`.projection_metric`).
    """

    tol: float = 1e-13
    max_iterations: int = 12
    mode: str = "output"
    metric: str = "euclidean"


@dataclass
class ProjectionMap:
    """The derivative of one step's projection: [∇q*; ∇q̇*] = A [∇q; ∇q̇] + B_x."""

    A: Array       # (2 n_q, 2 n_q)
    Bx: Array      # (2 n_q, m)

    def apply(self, ds: StepState) -> StepState:
        """The sensitivities (n, m per leaf) of the projected state from those of the solved one."""
        n_q = ds.q.shape[0]
        d = self.A @ np.concatenate([ds.q, ds.qd]) + self.Bx
        return ds._replace(q=d[:n_q], qd=d[n_q:])

    def transpose(self, q_bar: Array, qd_bar: Array) -> tuple[Array, Array, Array]:
        """Bars (n_q, r) of the projected q*, q̇* → bars of the solved q, q̇ and x̄ (m, r)."""
        n_q = q_bar.shape[0]
        y = np.concatenate([q_bar, qd_bar])
        back = self.A.T @ y
        return back[:n_q], back[n_q:], self.Bx.T @ y


@dataclass
class Projection:
    """One step's projection: the solved state ``raw``, the consistent state ``projected``
    (q*, q̇*), and whether the run continues from the projected state (``feedback``)."""

    model: "MultibodyModel"
    settings: "ProjectionSettings"
    t: float
    raw: StepState
    projected: StepState
    feedback: bool
    multipliers: tuple[Array, Array]      # the converged (ν, κ), each (1, n_eq, 1)
    _map: ProjectionMap | None = field(default=None, repr=False)
    _design: Array | None = field(default=None, repr=False)
    _newton: tuple[Any, tuple[Array, Array, "_Factored"], "_Jacobians"] | None = field(default=None, repr=False)

    def linear_map(self, partials: Any) -> ProjectionMap:
        """The projection's derivative at the run's design (``partials``: DesignPartials), once:
        A by 2 n_q complex-step columns (the adjoint's transpose needs all of it), in blocks of
        MAP_BLOCK columns (each column holds its own J_Φ while it is projected)."""
        if self._map is None:
            n_q = self.raw.q.shape[0]
            I = np.eye(2 * n_q)
            A = np.empty((2 * n_q, 2 * n_q))
            for c in range(0, 2 * n_q, MAP_BLOCK):
                cols = slice(c, min(c + MAP_BLOCK, 2 * n_q))
                dq, dqd = self._state_directions(I[:n_q, cols], I[n_q:, cols], partials.params0)
                A[:n_q, cols], A[n_q:, cols] = dq, dqd
            self._map = ProjectionMap(A, self._design_columns(partials))
        return self._map

    def apply(self, ds: StepState, partials: Any) -> StepState:
        """Direct mode: sensitivities (n_q, m per leaf) of the projected state from those of the
        solved one: A·[∇q; ∇q̇] along the m columns themselves (:func:`.projection_adjoint.apply_state`;
        m complex-step columns without compiled kinematics) plus B_x."""
        if self._map is not None or np.iscomplexobj(ds.q) or np.iscomplexobj(ds.qd):
            return self.linear_map(partials).apply(ds)
        n_q = ds.q.shape[0]
        from .projection_adjoint import apply_state
        found = apply_state(self, ds.q, ds.qd, partials.params0)
        dq, dqd = found if found is not None else self._state_directions(ds.q, ds.qd, partials.params0)
        Bx = self._design_columns(partials)
        return ds._replace(q=dq + Bx[:n_q], qd=dqd + Bx[n_q:])

    def transpose(self, q_bar: Array, qd_bar: Array, partials: Any) -> tuple[Array, Array, Array]:
        """Adjoint mode: bars (n_q, r) of the projected q*, q̇* → bars of the solved q, q̇ and x̄
        (m, r).  With compiled kinematics Aᵀ is applied without forming A
        (:func:`.projection_adjoint.transpose_state`: a few constraint-row evaluations and two
        transposed solves instead of 2 n_q projected columns); otherwise as
        :meth:`ProjectionMap.transpose`."""
        if self._map is None:
            from .projection_adjoint import transpose_state
            back = transpose_state(self, q_bar, qd_bar, partials.params0)
            if back is not None:
                return back[0], back[1], self._design_columns(partials).T @ np.concatenate([q_bar, qd_bar])
        return self.linear_map(partials).transpose(q_bar, qd_bar)

    def _start(self, params: Any) -> tuple[Array, Array, "_Factored"]:
        """(ν, κ, M) of the converged projection, M = J_Φ(q*) J₀ᵀ its exact Newton matrix
        (factorized; kept for the step)."""
        if self._newton is None or self._newton[0] is not params:
            t = self.t
            J = _jacobians(self.model, t, np.stack([self.projected.q, self.raw.q], axis=1), params)
            J0T = J.at(1).T
            W_inv = _metric(self.settings, self.raw.q[:, None], params)
            if W_inv is not None:                  # M = J_Φ(q*) W⁻¹ J₀ᵀ in the mass metric
                J0T = W_inv.matrix(0, J.sparse is not None) @ J0T
            self._newton = (params, (*self.multipliers, _Factored(J.at(0) @ J0T)), J)
        return self._newton[1]

    def jacobians(self, params: Any) -> tuple[Any, Any]:
        """(J_Φ(q*), J₀ = J_Φ(q)) of the converged projection (kept with its Newton matrix)."""
        self._start(params)
        J = self._newton[2]                        # type: ignore[index]
        return J.at(0), J.at(1)

    def _state_directions(self, dQ: Array, dQD: Array, params: Any) -> tuple[Array, Array]:
        """The derivative of (q*, q̇*) along the k directions (dQ, dQD) (n_q, k each) of the
        solved (q, q̇), by complex step of the converged projection (:func:`_project_columns`)."""
        q, qd = self.raw.q[:, None], self.raw.qd[:, None]
        Qs, QDs, _, _ = _project_columns(self.model, self.settings, self.t, q + 1j * _H * dQ, qd + 1j * _H * dQD,
                                         params, self._start(params))
        return np.imag(Qs) / _H, np.imag(QDs) / _H

    def _design_columns(self, partials: Any) -> Array:
        """B_x (2 n_q, m): the design partials of the projection at the solved state, by the
        run's partials method (once per step)."""
        if self._design is None:
            q, qd = self.raw.q[:, None], self.raw.qd[:, None]
            start = self._start(partials.params0)

            def projected(prm: Any) -> Array:
                Qp, QDp, _, _ = _project_columns(self.model, self.settings, self.t, q, qd, prm, start)
                return np.concatenate([Qp[:, 0], QDp[:, 0]])

            self._design = partials.of(projected)
        return self._design


class _Jacobians:
    """J_Φ (n_eq, n_q) at k configurations: ``dense`` (k, n_eq, n_q), or ``sparse``, k CSC
    matrices (a model on the sparse path: J_Φ has a row per equation on its bodies' columns)."""

    def __init__(self, dense: Array | None = None, sparse: list[Any] | None = None):
        self.dense, self.sparse = dense, sparse
        first = dense if dense is not None else sparse[0]        # type: ignore[index]
        self.k = dense.shape[0] if dense is not None else len(sparse)  # type: ignore[arg-type]
        self.n_eq, self.dtype = first.shape[-2], first.dtype

    def at(self, b: int) -> Any:
        """J_Φ at configuration b."""
        return self.dense[b] if self.dense is not None else self.sparse[b]   # type: ignore[index]

    def normal(self, W_inv: InverseMetric | None = None) -> "_Factored":
        """J_b W_b⁻¹ J_bᵀ of every configuration b (W = I without ``W_inv``), factorized."""
        if W_inv is None:
            if self.dense is not None:
                return _Factored(self.dense @ self.dense.transpose(0, 2, 1))
            return _Factored([J @ J.T for J in self.sparse])     # type: ignore[union-attr]
        if self.dense is not None:
            return _Factored(self.dense @ W_inv.blocks_dense() @ self.dense.transpose(0, 2, 1))
        return _Factored([J @ W_inv.matrix(b, True) @ J.T for b, J in enumerate(self.sparse)])  # type: ignore[arg-type]

    def transpose_times(self, nu: Array, W_inv: InverseMetric | None = None) -> Array:
        """(n_q, k): column b is W_b⁻¹ J_bᵀ ν_b (W = I without ``W_inv``) for the multipliers nu
        (k or 1, n_eq, 1; one set of multipliers serves every configuration)."""
        if self.dense is not None:
            out = (self.dense.transpose(0, 2, 1) @ nu)[:, :, 0].T
        else:
            last = nu.shape[0] - 1
            out = np.stack([J.T @ nu[min(b, last), :, 0] for b, J in enumerate(self.sparse)], axis=1)  # type: ignore[arg-type]
        return out if W_inv is None else W_inv.times(out)


def _jacobians(model: "MultibodyModel", t: float, Q: Array, params: Any) -> _Jacobians:
    """J_Φ at the k configurations (columns of Q (n_q, k)) at time t (s): by the compiled kernel,
    with the linearization's own arithmetic, when the model's kinematics are compiled (as CSC
    matrices on the sparse path's pattern when the model is linearized sparse); term by term
    otherwise (complex-safe either way)."""
    rows = level_rows(model, t, Q, np.zeros_like(Q), params, model.eq_row_weights, model.norm_row_weights)
    return rows if rows is not None else _Jacobians(dense=jacobian_rows(model.eqs, Q, params, t).transpose(2, 0, 1))


def level_rows(model: "MultibodyModel", t: float, Q: Array, QD: Array, params: Any, eq_w: Array,
               norm_w: Array) -> _Jacobians | None:
    """Constraint rows at the k states (columns of Q, QD (n_q, k)) at time t (s), weighted as
    output row 0 of ``eq_w``, ``norm_w`` (see ``compiled_linearization.constraint_rows``; the
    model's own weights give J_Φ); None when the model's kinematics are not compiled."""
    empty = np.zeros(0)
    kin = model.kinematics(StepState(Q.T, QD.T, np.zeros_like(Q.T), empty, empty, empty), params)
    if not isinstance(kin, CompiledKin):
        return None
    cl, lay = kin.arrays, model.layout
    cf, _ = model.coefficients(t, kin.kp)
    cf = np.ascontiguousarray(cf, kin.dtype)
    if model.traits.sparse and model.traits.n_lam >= SPARSE_MIN_EQ:
        st = model.sparse_structure()
        side_slot, prod_nb, _, _, _, n_cp, prod_eq, eq_slot, n_eq_slots = st.args
        Jc = clin.compact_constraint_jacobians(
            kin.C, kin.ABV, kin.Lp, cf, cl.is_point, cl.side_ptr, cl.side_prim, cl.side_coef, side_slot,
            prod_nb, n_cp, prod_eq, eq_slot, n_eq_slots, eq_w, norm_w, cl.norm_eq, cl.norm_body,
            model.traits.n_lam)
        return _Jacobians(sparse=st.constraint_jacobians(Jc))
    return _Jacobians(dense=clin.constraint_jacobians(
        kin.C, kin.ABV, kin.Lp, cf, cl.pb, cl.is_point, cl.side_ptr, cl.side_prim, cl.side_coef, lay.n_cp,
        cl.prod_eq, eq_w, norm_w, cl.norm_eq, cl.norm_body, model.traits.n_lam))


def _metric(settings: "ProjectionSettings", Q: Array, params: Any) -> InverseMetric | None:
    """W⁻¹ at the k solved configurations (columns of Q) for the mass metric; None (W = I) otherwise."""
    return inverse_metric(Q, params) if settings.metric == "mass" else None


def _levels(model: "MultibodyModel", t: float, Q: Array, QD: Array, params: Any) -> Array:
    """(Φ, Φ̇, Φ̈) (k, n_eq, 3) at the k states (columns of Q, QD (n_q, k)), q̈ = 0."""
    zeros = np.zeros(0)
    s = StepState(Q.T, QD.T, np.zeros_like(Q.T), zeros, zeros, zeros)
    return model.constraint_levels(t, model.kinematics(s, params))[0]


def _converged(step: Array, value: Array, tol: float) -> bool:
    """Every column's last correction (n, k), real parts, within tol of its value."""
    return bool(np.all(np.linalg.norm(np.real(step), axis=0)
                       <= tol * (1.0 + np.linalg.norm(np.real(value), axis=0))))


def _project_columns(model: "MultibodyModel", settings: "ProjectionSettings", t: float, Q: Array,
                     QD: Array, params: Any, start: tuple[Array, Array, "_Factored"] | None = None
                     ) -> tuple[Array, Array, Array, Array]:
    """(q*, q̇*) (n_q, k each) and the multipliers (ν, κ) (k, n_eq, 1) for k solved states
    (columns of Q, QD); complex-safe.  Without ``start``: chord iterations with J₀J₀ᵀ from ν = κ = 0
    to convergence.  With ``start`` = (ν, κ, M) of the converged projection of a nearby state:
    Newton iterations with its exact matrix M = J_Φ(q*) J₀ᵀ — one for complex steps of that state
    (it gives the imaginary parts exactly), two for a real perturbation δ (converged to O(δ⁴))."""
    J0 = _jacobians(model, t, Q, params)                                 # k times (n_eq, n_q)
    W_inv = _metric(settings, Q, params)
    if start is None:
        A = J0.normal(W_inv)
        nu = np.zeros((J0.k, J0.n_eq, 1), J0.dtype)
        kappa = np.zeros_like(nu)
    else:
        nu, kappa, A = start
    complex_parts = np.iscomplexobj(Q) or np.iscomplexobj(QD) or np.iscomplexobj(params.pv)
    Qs, QDs = Q + J0.transpose_times(nu, W_inv), QD - J0.transpose_times(kappa, W_inv)
    for level in (0, 1):                       # positions, then velocities at the projected positions
        done = 0                               # iterations until the real parts converged
        for it in range(settings.max_iterations if start is None else 1 if complex_parts else 2):
            res = _levels(model, t, Qs, QDs, params)[:, :, level:level + 1]   # (k, n_eq, 1)
            d = A.solve(res)
            if level == 0:
                nu = nu - d
                new = Q + J0.transpose_times(nu, W_inv)
                step, Qs = new - Qs, new
            else:
                kappa = kappa + d
                new = QD - J0.transpose_times(kappa, W_inv)
                step, QDs = new - QDs, new
            if start is not None:
                done = it + 1
                continue
            if done == 0 and _converged(step, new, settings.tol):
                done = it + 1
            # imaginary parts (complex step) start from their full size, not from the drift's,
            # and contract at the same rate: as many iterations again, one more for safety
            if done and (not complex_parts or it + 1 >= 2 * done + 1):
                break
        if not done:
            what = ("position", "q") if level == 0 else ("velocity", "q̇")
            raise ModelError(
                f"projection onto the {what[0]} constraints did not converge at t = {float(np.real(t)):.6g} s: "
                f"last correction ‖Δ{what[1]}‖ = {float(np.max(np.linalg.norm(np.real(step), axis=0))):.3g} "
                f"after {settings.max_iterations} iterations (model.projection.tol = {settings.tol:.3g}, "
                "relative); the step left the constraints too far, or the constraint Jacobian is "
                "(nearly) singular at this pose")
    return Qs, QDs, nu, kappa


def project(model: "MultibodyModel", settings: "ProjectionSettings", t: float, s: StepState,
            params: Any) -> tuple[StepState, Projection]:
    """The state s at t (s) projected onto Φ = 0 and Φ̇ = 0 (module docstring): the state the run
    continues from (the projected one in mode ``state``, s in mode ``output``) and the projection."""
    Q, QD, nu, kappa = _project_columns(model, settings, t, s.q[:, None], s.qd[:, None], params)
    projected = s._replace(q=Q[:, 0], qd=QD[:, 0])
    feedback = settings.mode == "state"
    return (projected if feedback else s), Projection(model, settings, t, s, projected, feedback,
                                                      (nu, kappa))


def solved_monitors(model: "MultibodyModel", t: float, solved: StepState, s: StepState, params: Any,
                    Phi: Array) -> dict[str, float]:
    """‖Φ‖, ‖Φ̇‖ of the state ``solved`` Newton solved at t before the projection that gave the
    reported state s (``Phi``: the levels at s; at t0, or for a state not projected, solved is s)."""
    if solved is not s:
        Phi = model.constraint_levels(t, model.kinematics(solved, params))[0][0]
    return {"constraint_position_solved": float(np.linalg.norm(np.real(Phi[:, 0]))),
            "constraint_velocity_solved": float(np.linalg.norm(np.real(Phi[:, 1])))}


def read_projection(spec: Any, path: str, problems: ProblemCollector) -> ProjectionSettings | None:
    """``model.projection`` of a case: the settings, or None when absent or ``enabled: false``."""
    if spec is None:
        return None
    n0 = len(problems.problems)
    if not check_keys(spec, path, allowed("multibody.projection"), problems):
        return None
    enabled = spec.get("enabled", True)
    if not isinstance(enabled, bool):
        problems.add(f"{path}.enabled", f"expected true or false, found {enabled!r}")
    tol = spec.get("tol", ProjectionSettings.tol)
    if isinstance(tol, str):            # YAML reads 1e-13 (no decimal point) as text
        try:
            tol = float(tol)
        except ValueError:
            pass
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not 0 < tol < 1e-3:
        problems.add(f"{path}.tol", f"expected a number in (0, 1e-3) (relative correction), found {tol!r}")
    mode = spec.get("mode", ProjectionSettings.mode)
    if mode not in ("state", "output"):
        problems.add(f"{path}.mode", f"expected state or output, found {mode!r}")
    its = spec.get("max_iterations", ProjectionSettings.max_iterations)
    if isinstance(its, bool) or not isinstance(its, int) or its < 2:
        problems.add(f"{path}.max_iterations", f"expected an integer >= 2, found {its!r}")
    metric = spec.get("metric", ProjectionSettings.metric)
    if metric not in ("mass", "euclidean"):
        problems.add(f"{path}.metric", f"expected mass or euclidean, found {metric!r}")
    if enabled is not True or len(problems.problems) > n0:
        return None
    return ProjectionSettings(float(tol), int(its), str(mode), str(metric))


__all__ = ["Projection", "ProjectionMap", "ProjectionSettings", "project", "read_projection",
           "solved_monitors"]
