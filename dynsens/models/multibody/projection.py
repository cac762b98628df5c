r"""Projection of each accepted step's end state onto the constraint manifolds (``model.projection``).

The index-1 form holds the constraints at the acceleration level only; its positions and
velocities drift (‖Φ‖ ≈ 1e-6…1e-4 over a run).  With ``model.projection`` on, the state that
Newmark and Newton produced at the end of a step, (q, q̇), is replaced by the closest consistent
one — the same closest-point problem as the initial assembly (:mod:`.assembly`), plain 2-norm:

    position:  q* − q − J_Φ(q*)ᵀ ν = 0,   Φ(q*, t; x) = 0        (joints and normalisations)
    velocity:  q̇* = q̇ − J_Φᵀ (J_Φ J_Φᵀ)⁻¹ Φ̇(q*, q̇, t; x)          (J_Φ at q*; Φ̇ = J_Φ q̇ + Φ_t)

The position problem is solved by Newton iterations with the Gauss–Newton matrix
[[I, −J_Φᵀ], [J_Φ, 0]] at the current iterate (the curvature term ∂(J_Φᵀν)/∂q is of the size of
the drift and only slows convergence from quadratic to fast linear); the velocity problem is
linear.  q̈, λ and ṗ stay as solved.  The run continues from (q*, q̇*): outputs, events,
monitors and the next step's predictor see the projected state.

Derivatives.  The projection is a map (q, q̇, x) → (q*, q̇*) of the step's end state and the
design, so the procedure the gradient differentiates is "Newmark step, then projection".  Its
derivative is the implicit-function derivative of the converged equations above, with the
exact matrix K = [[I − ∂(J_Φᵀν)/∂q, −J_Φᵀ], [J_Φ, 0]] and the design partials of Φ and J_Φ
(lengths are design variables) taken by the run's design-partials method:

    ∇q* = P_q ∇q + P_x,                 [P_q; ·] = K⁻¹ [I; 0],  [P_x; ·] = −K⁻¹ ∂_x G
    ∇q̇* = V_q ∇q* + V_q̇ ∇q̇ + V_x,       V_q̇ = I − J_Φᵀ(J_Φ J_Φᵀ)⁻¹ J_Φ

(V_q by batched complex step, exact to round-off).  The direct mode applies this map after the
step's correction; the adjoint applies its transpose before the correction's transpose and adds
P_xᵀ q̄* + V_xᵀ q̄̇* to x̄; the checkpointed segments take the same steps again, projection
included.  The design partials of the step's residual are taken at the state Newton converged
to (``Projection.raw``), where the step's equations hold.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ...case_keys import allowed
from ...errors import ModelError, ProblemCollector
from .._keys import check_keys
from ..base import StepState
from .assembly import _ctx, _jac, closest_point_matrix, closest_point_residual, jacobian_rows

if TYPE_CHECKING:  # pragma: no cover
    from .model import MultibodyModel

Array = np.ndarray


@dataclass(frozen=True)
class ProjectionSettings:
    """``model.projection``: convergence of the position projection.

    tol : relative bound on the last Newton correction, ‖Δq‖ ≤ tol (1 + ‖q‖) (dimensionless).
    max_iterations : iterations before the run stops with a ModelError.
    mode : ``state`` (the run continues from the projected state) or ``output`` (the run
        continues from the solved state; what it reports is projected).
    """

    tol: float = 1e-13
    max_iterations: int = 12
    mode: str = "state"


@dataclass
class ProjectionMap:
    """The derivative of one step's projection (module docstring): dense matrices."""

    Pq: Array      # (n_q, n_q)  ∂q*/∂q
    Px: Array      # (n_q, m)    ∂q*/∂x
    Vq: Array      # (n_q, n_q)  ∂q̇*/∂q* (at fixed q̇)
    Vqd: Array     # (n_q, n_q)  ∂q̇*/∂q̇
    Vx: Array      # (n_q, m)    ∂q̇*/∂x (at fixed q*, q̇)

    def apply(self, ds: StepState) -> StepState:
        """The sensitivities (n, m per leaf) of the projected state from those of the solved one."""
        dq = self.Pq @ ds.q + self.Px
        dqd = self.Vq @ dq + self.Vqd @ ds.qd + self.Vx
        return ds._replace(q=dq, qd=dqd)

    def transpose(self, q_bar: Array, qd_bar: Array) -> tuple[Array, Array, Array]:
        """Bars (n_q, r) of the projected q*, q̇* → bars of the solved q, q̇ and x̄ (m, r)."""
        q_star_bar = q_bar + self.Vq.T @ qd_bar
        return self.Pq.T @ q_star_bar, self.Vqd.T @ qd_bar, self.Px.T @ q_star_bar + self.Vx.T @ qd_bar


@dataclass
class Projection:
    """One step's projection: the solved state ``raw``, the consistent state ``projected``
    (q*, q̇*), ν, and whether the run continues from the projected state (``feedback``)."""

    model: "MultibodyModel"
    t: float
    raw: StepState
    projected: StepState
    nu: Array
    feedback: bool
    _map: ProjectionMap | None = field(default=None, repr=False)

    def linear_map(self, partials: Any) -> ProjectionMap:
        """The projection's derivative at the run's design (``partials``: DesignPartials), once."""
        if self._map is None:
            self._map = projection_map(self.model, self, partials)
        return self._map

    def apply(self, ds: StepState, partials: Any) -> StepState:
        """Direct mode: sensitivities of the projected state from those of the solved one."""
        return self.linear_map(partials).apply(ds)

    def transpose(self, q_bar: Array, qd_bar: Array, partials: Any) -> tuple[Array, Array, Array]:
        """Adjoint mode: see :meth:`ProjectionMap.transpose`."""
        return self.linear_map(partials).transpose(q_bar, qd_bar)


def _velocity(model: "MultibodyModel", q: Array, qd: Array, params: Any, t: float) -> Array:
    """q̇* = q̇ − J_Φᵀ (J_Φ J_Φᵀ)⁻¹ Φ̇(q, q̇) at q (n_q,) or for a batch q, q̇ (n_q, k); complex-safe."""
    Q = q.reshape(q.shape[0], -1)
    QD = np.ascontiguousarray(np.broadcast_to(qd.reshape(qd.shape[0], -1), Q.shape)).astype(
        np.result_type(Q, qd, float))
    J = jacobian_rows(model.eqs, Q, params, t).transpose(2, 0, 1)              # (k, n_eq, n_q)
    phid = model.constraint_values(_ctx(Q, QD, params, t))[1].T[:, :, None]     # (k, n_eq, 1)
    kappa = np.linalg.solve(J @ J.transpose(0, 2, 1), phid)
    out = (QD.T[:, :, None] - J.transpose(0, 2, 1) @ kappa)[:, :, 0].T
    return out if q.ndim == 2 else out[:, 0]


def project(model: "MultibodyModel", settings: ProjectionSettings, t: float, s: StepState,
            params: Any) -> tuple[StepState, Projection]:
    """The state s at t (s) projected onto Φ = 0 and Φ̇ = 0 (module docstring): the state the run
    continues from (the projected one in mode ``state``, s in mode ``output``) and the projection."""
    q_raw = s.q
    q, nu = q_raw.copy(), np.zeros(model.traits.n_lam, np.result_type(q_raw, params.pv, float))
    scale = 1.0 + float(np.linalg.norm(np.real(q_raw)))
    extra, step = 0, np.inf
    for _ in range(settings.max_iterations):
        J = jacobian_rows(model.eqs, q, params, t)
        phi = model.constraint_values(_ctx(q, None, params, t))[0][:, 0]
        g = q - q_raw - J.T @ nu
        # [[I, −Jᵀ], [J, 0]] [Δq; Δν] = −[g; Φ]  by its Schur complement J Jᵀ
        dnu = np.linalg.solve(J @ J.T, J @ g - phi)
        dq = J.T @ dnu - g
        q, nu = q + dq, nu + dnu
        step = float(np.linalg.norm(np.real(dq)))
        if step <= settings.tol * scale:
            extra += 1
            if extra >= 2:      # one iteration more: the imaginary parts of a complex-step run converge too
                break
    else:
        raise ModelError(
            f"projection onto the constraint manifold did not converge at t = {float(np.real(t)):.6g} s: "
            f"last correction ‖Δq‖ = {step:.3g} after {settings.max_iterations} iterations "
            f"(bound {settings.tol:.3g}·(1 + ‖q‖) from model.projection.tol); the step left the "
            "constraints too far, or the constraint Jacobian is (nearly) singular at this pose")
    projected = s._replace(q=q, qd=_velocity(model, q, s.qd, params, t))
    feedback = settings.mode == "state"
    return (projected if feedback else s), Projection(model, t, s, projected, nu, feedback)


def projection_map(model: "MultibodyModel", proj: Projection, partials: Any) -> ProjectionMap:
    """The derivative of the converged projection (module docstring) at design partials.params0."""
    params, t = partials.params0, proj.t
    q_raw, qd_raw, nu = proj.raw.q, proj.raw.qd, proj.nu
    n_q = q_raw.shape[0]
    q = proj.projected.q
    K = closest_point_matrix(model.eqs, q, nu, params, t)
    unit = np.zeros((K.shape[0], n_q))
    unit[:n_q] = np.eye(n_q)
    Gx = partials.of(lambda prm: closest_point_residual(model, model.eqs, q, q_raw, nu, prm, t))
    sol = np.linalg.solve(K, np.concatenate([unit, -Gx], axis=1))
    Pq, Px = sol[:n_q, :n_q], sol[:n_q, n_q:]
    J = jacobian_rows(model.eqs, q, params, t)
    Vqd = np.eye(n_q) - J.T @ np.linalg.solve(J @ J.T, J)
    Vq = _jac(lambda Q: _velocity(model, Q, qd_raw, params, t), q, True)
    Vx = partials.of(lambda prm: _velocity(model, q, qd_raw, prm, t))
    return ProjectionMap(Pq, Px, Vq, Vqd, Vx)


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
    if enabled is not True or len(problems.problems) > n0:
        return None
    return ProjectionSettings(float(tol), int(its), str(mode))


__all__ = ["Projection", "ProjectionMap", "ProjectionSettings", "project", "projection_map", "read_projection"]
