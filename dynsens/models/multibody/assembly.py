r"""Consistent initial conditions and their exact design derivatives.

Position level.  The bodies' given poses form the guess q_g(x).  With the joint
equations Φ (incl. normalisation) and the case's extra assembly equations Φ_a
(``initial.hold`` coordinates and ``initial.distances``), Φ_c = [Φ; Φ_a], the initial
configuration is the point of the constraint manifold closest to the guess:

    F(q, μ; x) = [ q − q_g(x) − J_cᵀ(q) μ ;  Φ_c(q, t0; x) ] = 0

(the guess is kept in a least-squares sense; held coordinates are kept exactly).  F is
solved by Newton with the exact matrix [[I − ∂(J_cᵀμ)/∂q, −J_cᵀ], [J_c, 0]], and ∇q0
follows by implicit differentiation: ∂F/∂(q, μ) ∇(q, μ) = −∂_x F, with ∂_x F taken by the
run's design-partials method (``partials.of``).

Velocity level: q̇0 = q̇_g + Aᵀ (A Aᵀ)⁻¹ (b − A q̇_g), A = [J_Φ; J_a], b = [−Φ_t; J_a q̇_g]
(least-squares closest velocities; held coordinates keep their given rates).  q̇_g has
ṗ = ½ E(p)ᵀ ω from the given angular velocities.

Pressures: given, or ``static``: with q̈ = 0 the equations of motion
Jᵀλ − Q_other − Q_v − Σ_c (p1 A1)_c Q_unit,c = 0 are solved for λ and the piston-side
forces p1 A1 (Q_other includes the rod-side pressure p2 = given or p_T, and the damping).
λ0 and ṗ0 = h(t0) are returned as Newton guesses.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from ...errors import CaseError, ModelError
from ..base import StepState
from .bodies import Ctx, MBParams
from .rotations import ET_mul

if TYPE_CHECKING:  # pragma: no cover
    from .model import MultibodyModel

Array = np.ndarray


@dataclass
class InitialConditions:
    q0: Array
    qd0: Array
    p0: Array
    lam0: Array
    pd0: Array
    mu: Array


def _ctx(q: Array, qd: Array | None, params: MBParams, t: float) -> Ctx:
    q = q.reshape(q.shape[0], -1)
    qd = np.zeros_like(q) if qd is None else qd.reshape(q.shape)
    return Ctx(q, qd, np.zeros_like(q), params, t)


def jacobian_rows(eqs: list, q: Array, params: MBParams, t: float) -> Array:
    """J (n_eq, n_q) of the equations at q (n_q,), analytic through the terms (complex-safe);
    for a batch of k configurations q (n_q, k), J (n_eq, n_q, k) in one pass over the equations."""
    Q = q.reshape(q.shape[0], -1)
    k = Q.shape[1]
    ctx = _ctx(Q, None, params, t)
    dt = np.result_type(q, params.pv, float)
    J = np.zeros((len(eqs), Q.shape[0], k), dt)
    ones = np.ones((1, k))
    for i, eq in enumerate(eqs):
        eq.apply(ctx, ones, J[i])
    return J if q.ndim == 2 else J[:, :, 0]


def _jac(fn: Callable[[Array], Array], x: Array, real: bool) -> Array:
    """∂fn/∂x by batched complex step (real data) or central differences (complex data)."""
    n = x.shape[0]
    if real:
        h = 1e-30
        return np.imag(fn(x[:, None] + 1j * h * np.eye(n))) / h
    hs = 1e-7 * (1.0 + np.abs(np.real(x)))
    return (fn(x[:, None] + np.diag(hs)) - fn(x[:, None] - np.diag(hs))) / (2.0 * hs[None, :])


def _jvp(fn: Callable[[Array], Array], x: Array, V: Array, real: bool) -> Array:
    """(∂fn/∂x) V for the m columns of V (n, m): complex step along each column (real data),
    central differences along it otherwise; m evaluations of fn in one batch instead of the n of
    the whole Jacobian."""
    if V.shape[1] == 0:
        return np.zeros((fn(x[:, None]).shape[0], 0), np.result_type(x, V, float))
    if real and not np.iscomplexobj(x):
        if np.iscomplexobj(V):          # a linear map: the real and imaginary columns apart
            return _jvp(fn, x, V.real, real) + 1j * _jvp(fn, x, V.imag, real)
        h = 1e-30
        return np.imag(fn(x[:, None] + 1j * h * V)) / h
    size = np.max(np.abs(V), axis=0)
    hs = 1e-7 * (1.0 + np.max(np.abs(np.real(x)))) / np.where(size > 0, size, 1.0)
    return (fn(x[:, None] + V * hs) - fn(x[:, None] - V * hs)) / (2.0 * hs[None, :])


def guess(model: "MultibodyModel", params: MBParams) -> Array:
    """q_g (n_q,) from the bodies' given poses."""
    return np.concatenate([np.concatenate([bp.r0, bp.p0]) for bp in params.bodies]) \
        if params.bodies else np.zeros(0)


def _all_eqs(model: "MultibodyModel") -> list:
    return model.eqs + model.assembly.equations


def _F(model: "MultibodyModel", q: Array, mu: Array, params: MBParams) -> Array:
    """The assembly residual F(q, μ) (n_q + n_c,)."""
    eqs = _all_eqs(model)
    t0 = model.assembly.t0
    ctx = _ctx(q, None, params, t0)
    phi = model.constraint_values(ctx, eqs)[0][:, 0]
    dt = np.result_type(q, mu, params.pv, float)
    JTmu = np.zeros((q.shape[0], 1), dt)
    for i, eq in enumerate(eqs):
        eq.apply(ctx, mu[i:i + 1].reshape(1, 1), JTmu)
    return np.concatenate([q - guess(model, params) - JTmu[:, 0], phi])


def _F_matrix(model: "MultibodyModel", q: Array, mu: Array, params: MBParams) -> Array:
    """∂F/∂(q, μ)."""
    eqs = _all_eqs(model)
    t0 = model.assembly.t0
    n_q = q.shape[0]
    real = not (np.iscomplexobj(q) or np.iscomplexobj(mu) or np.iscomplexobj(params.pv))

    def JTmu(qb: Array) -> Array:
        ctx = Ctx(qb, np.zeros_like(qb), np.zeros_like(qb), params, t0)
        out = np.zeros(qb.shape, np.result_type(qb, mu, params.pv, float))
        for i, eq in enumerate(eqs):
            eq.apply(ctx, mu[i:i + 1].reshape(1, 1), out)
        return out

    H = _jac(JTmu, q, real)
    Jc = jacobian_rows(eqs, q, params, t0)
    K = np.block([[np.eye(n_q) - H, -Jc.T], [Jc, np.zeros((len(eqs), len(eqs)))]])
    return K


def dependent_equations(J: Array, labels: list[str], rel_tol: float | None = None
                        ) -> tuple[int, list[str], list[str]] | None:
    """(rank, equations, joints) when J (n_eq, n_q) is rank-deficient, else None.

    Singular values ≤ rel_tol·σ_max count as zero (default: round-off, 1e3·ε·max(shape));
    the equations named are those with a visible share (> 1e-6) in the left null vectors.
    """
    if J.shape[0] == 0 or not np.all(np.isfinite(J)):   # no rank to judge
        return None
    U, sv, _ = np.linalg.svd(np.real(J), full_matrices=True)
    rel = max(J.shape) * np.finfo(float).eps * 1e3 if rel_tol is None else rel_tol
    tol = rel * (sv[0] if sv.size else 1.0)
    svf = np.concatenate([sv, np.zeros(J.shape[0] - sv.size)])
    null = np.flatnonzero(svf <= tol)
    if null.size == 0:
        return None
    involved = sorted({labels[i] for j in null for i in np.flatnonzero(np.abs(U[:, j]) > 1e-6)})
    joints = sorted({lab.split(".")[0] for lab in involved})
    return J.shape[0] - null.size, involved, joints


def _rank_check(model: "MultibodyModel", J: Array, labels: list[str], where: str) -> None:
    """CaseError naming the equations (joints) involved when J (n_eq, n_q) is rank-deficient."""
    if not np.all(np.isfinite(J)):
        raise CaseError(f"{where}: expected a finite constraint Jacobian at the initial pose, found NaN or "
                        "infinite entries: a body position, joint point or axis is too large or not finite")
    dep = dependent_equations(J, labels)
    if dep is None:
        return
    rank, involved, joints = dep
    n_red = J.shape[0] - rank
    raise CaseError(
        f"{where}: the constraint Jacobian has rank {rank} < {J.shape[0]} "
        f"({n_red} redundant equation{'s' if n_red > 1 else ''}); linearly dependent "
        f"equations: {', '.join(involved)} (joints/conditions: {', '.join(joints)}). "
        "Redundant joint equations are left out when the case is loaded, if they are redundant "
        "and hold at the case's initial design (docs/multibody.md, 'redundant joints'); these are not (another "
        "design, holds/distances that repeat a joint, or a model built outside a case): drop a "
        "hold/distance, or give a joint fewer equations (e.g. a revolute as a planar_pin).")


def assemble(model: "MultibodyModel", params: MBParams) -> tuple[Array, Array]:
    """q0 (n_q,) and the assembly multipliers μ by Newton on F (module docstring)."""
    a = model.assembly
    eqs = _all_eqs(model)
    labels = model.eq_owner + a.labels
    q = guess(model, params).astype(np.result_type(params.pv, float))
    n_q = q.shape[0]
    Jg = jacobian_rows(eqs, q, params, a.t0)
    _rank_check(model, Jg[:model.traits.n_lam], model.eq_owner, "assembly (at the given poses)")
    if len(eqs) > n_q:
        raise CaseError(f"assembly: {len(eqs)} equations (joints, normalisations, holds, "
                        f"distances) for {n_q} coordinates: drop some initial.hold/distances")
    _rank_check(model, Jg, labels, "assembly (joints with the initial holds/distances)")
    mu = np.zeros(len(eqs), q.dtype)
    extra = 0
    scale = 1.0 + np.linalg.norm(np.real(q))

    def fnorm(qq: Array, mm: Array) -> float:
        return float(np.linalg.norm(np.real(_F(model, qq, mm, params))))

    best = (np.inf, q)
    for it in range(1, a.max_iterations + 1):
        F = _F(model, q, mu, params)
        f0 = float(np.linalg.norm(np.real(F)))
        phin = float(np.linalg.norm(np.real(F[n_q:])))
        if phin < best[0]:
            best = (phin, q)
        K = _F_matrix(model, q, mu, params)
        try:
            dx = np.linalg.solve(K, -F)
        except np.linalg.LinAlgError:
            _rank_check(model, jacobian_rows(eqs, q, params, a.t0), labels, "assembly")
            raise ModelError(f"assembly failed: the assembly matrix is singular at Newton iteration {it} "
                             "(the joints' equations are dependent at this pose, or a body's mass or "
                             "inertia leaves it undetermined): check the initial poses, joints and holds") \
                from None
        # backtracking on ‖F‖ (decided on real parts) keeps far-off guesses from diverging
        step = 1.0
        while step > 1e-3 and fnorm(q + step * dx[:n_q], mu + step * dx[n_q:]) > f0 and f0 > 1e-14 * scale:
            step *= 0.5
        q = q + step * dx[:n_q]
        mu = mu + step * dx[n_q:]
        if step == 1.0 and np.linalg.norm(np.real(dx[:n_q])) <= a.tol * scale:
            extra += 1
            if extra >= 2:   # two more iterations so complex parts converge too
                break
    phi = model.constraint_values(_ctx(q, None, params, a.t0), eqs)[0][:, 0]
    res = np.abs(np.real(phi))
    if not np.all(np.isfinite(res)) or extra == 0 or np.max(res, initial=0.0) > 1e-8 * scale:
        qb = best[1]
        res = np.abs(np.real(model.constraint_values(_ctx(qb, None, params, a.t0), eqs)[0][:, 0]))
        joint_rows = [i for i, lab in enumerate(labels) if not lab.endswith(".normalization")]
        worst = max(joint_rows or range(len(res)), key=lambda i: res[i])
        raise ModelError(
            f"assembly failed: ‖Φ‖ = {np.linalg.norm(res):.3e} at the best of {a.max_iterations} "
            f"Newton iterations; largest joint residual {res[worst]:.3e} in '{labels[worst]}'. "
            "Check the joint points/axes, markers and distances, and give initial poses closer "
            "to an assembled configuration")
    _rank_check(model, jacobian_rows(model.eqs, q, params, a.t0), model.eq_owner,
                "assembly (at the assembled pose)")
    return q, mu


def velocities(model: "MultibodyModel", q: Array, params: MBParams) -> Array:
    """q̇0 (n_q,) by the least-squares projection of the module docstring (complex-safe); for a
    batch of k configurations q (n_q, k), the k projections (n_q, k) in one pass."""
    t0 = model.assembly.t0
    Q = q.reshape(q.shape[0], -1)
    k = Q.shape[1]
    parts = []
    for i, bp in enumerate(params.bodies):
        p = Q[7 * i + 3:7 * i + 7]
        parts += [np.broadcast_to(bp.v0.reshape(3, 1), (3, k)), 0.5 * ET_mul(p, bp.w0.reshape(3, 1))]
    qdg = np.concatenate(parts) if parts else np.zeros((0, k))
    J = jacobian_rows(model.eqs, Q, params, t0)
    Ja = jacobian_rows(model.assembly.equations, Q, params, t0)
    phi_t = model.constraint_values(_ctx(Q, None, params, t0))[1]
    A = np.concatenate([J, Ja]).transpose(2, 0, 1)                  # (k, n_eq + n_a, n_q)
    qdg_k = qdg.T[:, :, None]                                        # (k, n_q, 1)
    b = np.concatenate([-phi_t.T[:, :, None], Ja.transpose(2, 0, 1) @ qdg_k], axis=1)
    y = np.linalg.solve(A @ A.transpose(0, 2, 1), b - A @ qdg_k)
    qd = (qdg_k + A.transpose(0, 2, 1) @ y)[:, :, 0].T
    return qd if q.ndim == 2 else qd[:, 0]


def static_forces(model: "MultibodyModel", q: Array, qd: Array, p_given: Array,
                  params: MBParams) -> tuple[Array, Array]:
    """(λ0, p0) with the static cylinders' p1 from equilibrium at q̈ = 0 (complex-safe); for a
    batch of k configurations q, qd (n_q, k), the k solutions ((n_λ, k), (n_p, k)) in one pass."""
    t0 = model.assembly.t0
    static = [c for c in model.cylinders if c.initial == "static"]
    batched = q.ndim == 2
    Q = q.reshape(q.shape[0], -1)
    k = Q.shape[1]
    QD = np.broadcast_to(qd.reshape(qd.shape[0], -1), Q.shape)
    n_q, n_lam = Q.shape[0], model.traits.n_lam
    if not static:
        lam0 = np.zeros((n_lam, k))
        return (lam0, np.repeat(p_given.reshape(-1, 1), k, axis=1)) if batched else (lam0[:, 0], p_given)
    ctx = _ctx(Q, np.ascontiguousarray(QD), params, t0)
    dt = np.result_type(Q, QD, p_given, params.pv, float)
    # everything but the unknown cylinder forces, at q̈ = 0, λ = 0
    p_tmp = p_given.astype(dt)
    for c in static:
        # the piston-side pressure force p1 A1 of a static cylinder is the unknown
        p_tmp[c.p_index] = 0.0
    zeros = (np.zeros(n_q), np.zeros(n_lam), np.zeros(p_tmp.shape[0]))
    states = [StepState(Q[:, j], QD[:, j], zeros[0], zeros[1], p_tmp, zeros[2]) for j in range(k)]
    R1 = model.residual_batch_steps(np.full(k, t0), states, [params])[:, :n_q, 0]        # (k, n_q)
    cols = [jacobian_rows(model.eqs, Q, params, t0).transpose(2, 1, 0)]                    # (k, n_q, n_λ)
    for c in static:
        _, _, e = c.kinematics(ctx)
        Qu = np.zeros((n_q, k), dt)
        c.d.apply(ctx, e, Qu)
        cols.append(-Qu.T[:, :, None])
    A = np.concatenate(cols, axis=2)                                                       # (k, n_q, n_y)
    rhs = -R1[:, :, None]
    if A.shape[2] == n_q:
        y = np.linalg.solve(A, rhs)
    else:
        cs = 1.0 / np.sqrt(np.sum(np.real(A) ** 2, axis=1, keepdims=True))
        As = A * cs
        AsT = As.transpose(0, 2, 1)
        y = np.linalg.solve(AsT @ As, AsT @ rhs) * cs.transpose(0, 2, 1)
    resid = np.linalg.norm(np.real(A @ y + R1[:, :, None])[:, :, 0], axis=1)
    bound = 1e-6 * (1.0 + np.linalg.norm(np.real(R1), axis=1))
    if np.any(resid > bound):
        worst = float(np.max(resid))
        raise CaseError(
            f"initial pressures 'static': no static equilibrium at the initial pose (residual "
            f"{worst:.3e}); the cylinders with static initial pressures "
            "must hold all degrees of freedom, or give the pressures explicitly")
    y = y[:, :, 0].T                                                                       # (n_y, k)
    lam0 = y[:n_lam]
    p0 = np.repeat(p_given.astype(dt).reshape(-1, 1), k, axis=1)
    for j, c in enumerate(static):
        p0[c.p_index] = y[n_lam + j] / c.areas(params)[0]
    return (lam0, p0) if batched else (lam0[:, 0], p0[:, 0])


def pressures_given(model: "MultibodyModel", params: MBParams) -> Array:
    """p0 as given (static cylinders: p1 = 0 placeholder, p2 given or tank pressure)."""
    pv = params.pv
    p = np.zeros(model.traits.n_p, np.result_type(pv, float))
    for c in model.cylinders:
        p[c.p_index + 1] = pv[c.initial_p2]
        if c.initial != "static":
            p[c.p_index] = pv[c.initial]
    return p


def initial_conditions(model: "MultibodyModel", params: MBParams) -> InitialConditions:
    """Assembly, velocities, pressures and Newton guesses (λ0, ṗ0)."""
    q0, mu = assemble(model, params)
    qd0 = velocities(model, q0, params)
    p0 = pressures_given(model, params)
    lam0, p0 = static_forces(model, q0, qd0, p0, params)
    pd0 = np.zeros_like(p0)
    if model.cylinders:
        ctx = _ctx(q0, qd0, params, model.assembly.t0)
        for c in model.cylinders:
            h1, h2 = c.rates(ctx, p0.reshape(-1, 1))
            pd0[c.p_index], pd0[c.p_index + 1] = h1[0, 0], h2[0, 0]
    return InitialConditions(q0, qd0, p0, lam0, pd0, mu)


def initial_gradient(model: "MultibodyModel", params0: MBParams, partials: Any,
                     ic: InitialConditions | None = None) -> tuple[Array, Array, Array]:
    """∇q0, ∇q̇0, ∇p0 (each (n, m)) by implicit differentiation (module docstring), at the
    initial conditions ``ic`` of params0 (assembled here when not given)."""
    if ic is None:
        ic = initial_conditions(model, params0)
    q0, mu, qd0 = ic.q0, ic.mu, ic.qd0
    n_q = q0.shape[0]
    K = _F_matrix(model, q0, mu, params0)
    Fx = partials.of(lambda prm: _F(model, q0, mu, prm))
    dqmu = np.linalg.solve(K, -Fx)
    dq = dqmu[:n_q]
    # the velocities' derivative along the m columns of ∇q0 (not the n_q columns of ∂q̇0/∂q0)
    dqd = _jvp(lambda qb: velocities(model, qb, params0), q0, dq, True) + \
        partials.of(lambda prm: velocities(model, q0, prm))

    def P(qq: Array, qqd: Array, prm: MBParams) -> Array:
        return static_forces(model, qq, qqd, pressures_given(model, prm), prm)[1]

    if model.traits.n_p == 0:
        return dq, dqd, np.zeros((0, dq.shape[1]))
    dp = _jvp(lambda qb: P(qb, qd0, params0), q0, dq, True) + \
        _jvp(lambda qb: P(np.repeat(q0[:, None], qb.shape[1], axis=1), qb, params0), qd0, dqd, True) + \
        partials.of(lambda prm: P(q0, qd0, prm))
    return dq, dqd, dp
