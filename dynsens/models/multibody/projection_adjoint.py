r"""The derivative of a step's projection (:mod:`.projection`) and its transpose, applied
without forming the map.

The converged projection of the solved state v = (q, q̇) is the solution u = (q*, ν, q̇*, κ) of

    G₁ = q* − q − J(q)ᵀν = 0,        G₂ = Φ(q*) = 0,
    G₃ = q̇* − q̇ + J(q)ᵀκ = 0,        G₄ = Φ̇(q*, q̇*) = J(q*) q̇* + Φ_t(q*) = 0

(J = J_Φ).  By the implicit-function theorem, bars ȳ = (q̄*, q̇̄*) of the projected state go
back to the solved one as v̄ = −G_vᵀ w with G_uᵀ w = (q̄*, 0, q̇̄*, 0).  With J* = J(q*),
J₀ = J(q), M = J* J₀ᵀ (the projection's own Newton matrix, already factorized) and
Φ̇_q = ∂Φ̇/∂q at (q*, q̇*), the block structure of G_u gives

    w₄ = M⁻ᵀ J₀ q̇̄*,   w₃ = q̇̄* − J*ᵀ w₄,
    w₂ = M⁻ᵀ J₀ (q̄* − Φ̇_qᵀ w₄),   w₁ = q̄* − Φ̇_qᵀ w₄ − J*ᵀ w₂,
    q̄ = w₁ + H_ν w₁ − H_κ w₃,   q̇̄ = w₃,

where H_ν = ∂(J(q)ᵀν)/∂q = Σᵢ νᵢ ∇²Φᵢ(q) is symmetric, so H_ν w = N_wᵀ ν with N_w = ∂(J(q) w)/∂q.
Φ̇_q and N_w are constraint rows of the compiled kernel with other weights of the product
rows (∂x, ∂ẋ, ∂ẍ by q, weighted by the coefficient levels c, ċ, c̈): Φ̇_q = ċ ∂x + c ∂ẋ at
(q*, q̇*), N_w = c ∂ẋ at (q, q̇ = w) — the sides of a product do not depend on time, so ∂ẋ/∂q
at velocity w is the Hessian of x applied to w.  A step's transpose then costs 1 + 2r
constraint-row evaluations and two transposed solves with M, against 2 n_q projected columns
for the whole map.  The design part (B_xᵀ ȳ) is unchanged.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from .projection import level_rows

if TYPE_CHECKING:  # pragma: no cover
    from .projection import Projection

Array = np.ndarray


def _weights(product_rows: list[list[float]], norm: list[float]) -> tuple[Array, Array]:
    """Output row 0 of eq_w[o, r, i] (product row r ∈ ∂x, ∂ẋ, ∂ẍ times coefficient level i ∈
    c, ċ, c̈) and of norm_w[o, l] (normalisation 2p·level l), the other rows zero."""
    eq_w, norm_w = np.zeros((3, 3, 3)), np.zeros((3, 3))
    eq_w[0] = product_rows
    norm_w[0] = norm
    return eq_w, norm_w


# ∂Φ̇/∂q = ċ ∂x/∂q + c ∂ẋ/∂q, normalisations ∂(2p·ṗ)/∂p = 2ṗ
PHI_DOT_Q = _weights([[0, 1, 0], [1, 0, 0], [0, 0, 0]], [0, 1, 0])
# ∂(J(q) w)/∂q at q̇ = w: c ∂ẋ/∂q, normalisations 2 w_p
J_TIMES_W_Q = _weights([[0, 0, 0], [1, 0, 0], [0, 0, 0]], [0, 1, 0])


def _pieces(proj: "Projection", params: Any) -> tuple[Any, Any, Any, Any, Array, Array] | None:
    """(M factorized, J*, J₀, Φ̇_q, ν, κ) of the converged projection; None without compiled kinematics
    or with the mass metric (its W(q) adds terms these equations leave out: the projection's own
    complex step serves it)."""
    if proj.settings.metric != "euclidean":
        return None
    q_star, qd_star = proj.projected.q[:, None], proj.projected.qd[:, None]
    dphi = level_rows(proj.model, proj.t, q_star, qd_star, params, *PHI_DOT_Q)
    if dphi is None:
        return None
    nu, kappa, M = proj._start(params)
    J_star, J0 = proj.jacobians(params)
    return M, J_star, J0, dphi.at(0), nu[0, :, 0], kappa[0, :, 0]


def _hessian_products(proj: "Projection", params: Any, W: Array, weights: Array) -> Array:
    """Columns j of Σ_e weights[e, j] ∇²Φ_e(q) W[:, j] at the solved q (n_q, k): N_wᵀ weights
    with N_w = ∂(J(q) w)/∂q, every column in one evaluation (``weights`` (n_eq, k))."""
    k = W.shape[1]
    N = level_rows(proj.model, proj.t, np.repeat(proj.raw.q[:, None], k, axis=1), W, params, *J_TIMES_W_Q)
    assert N is not None
    return np.stack([N.at(j).T @ weights[:, j] for j in range(k)], axis=1)


def _both(nu: Array, kappa: Array, k: int) -> Array:
    """(n_eq, 2k): k columns of ν, then k of κ (the weights of :func:`_hessian_products`)."""
    return np.concatenate([np.repeat(nu[:, None], k, axis=1), np.repeat(kappa[:, None], k, axis=1)], axis=1)


def apply_state(proj: "Projection", dq: Array, dqd: Array, params: Any) -> tuple[Array, Array] | None:
    """The derivative (dq*, dq̇*) (n_q, m each) of the projected state along the directions
    (dq, dq̇) of the solved one, from the same linearized equations as :func:`transpose_state`:
    dν = −M⁻¹ J*(I + H_ν) dq, dq* = (I + H_ν) dq + J₀ᵀ dν,
    dκ = M⁻¹ (Φ̇_q dq* + J*(dq̇ − H_κ dq)), dq̇* = dq̇ − H_κ dq − J₀ᵀ dκ; None without compiled
    kinematics."""
    pieces = _pieces(proj, params)
    if pieces is None:
        return None
    M, J_star, J0, Phi_dot_q, nu, kappa = pieces
    m = dq.shape[1]
    H = _hessian_products(proj, params, np.concatenate([dq, dq], axis=1), _both(nu, kappa, m))
    y = dq + H[:, :m]
    dq_star = y - J0.T @ M.solve_plain(J_star @ y)
    v = dqd - H[:, m:]
    dqd_star = v - J0.T @ M.solve_plain(Phi_dot_q @ dq_star + J_star @ v)
    return dq_star, dqd_star


def transpose_state(proj: "Projection", q_bar: Array, qd_bar: Array, params: Any
                    ) -> tuple[Array, Array] | None:
    """Bars (n_q, r) of the solved q, q̇ from bars q_bar, qd_bar (n_q, r) of the projected
    state (module docstring); None when the model's kinematics are not compiled."""
    pieces = _pieces(proj, params)
    if pieces is None:
        return None
    M, J_star, J0, Phi_dot_q, nu, kappa = pieces
    w4 = M.solve_transposed(J0 @ qd_bar)
    w3 = qd_bar - J_star.T @ w4
    y1 = q_bar - Phi_dot_q.T @ w4
    w2 = M.solve_transposed(J0 @ y1)
    w1 = y1 - J_star.T @ w2
    # H_ν w₁ and H_κ w₃ for every column, all 2r in one evaluation
    r = q_bar.shape[1]
    H = _hessian_products(proj, params, np.concatenate([w1, w3], axis=1), _both(nu, kappa, r))
    return w1 + H[:, :r] - H[:, r:], w3
