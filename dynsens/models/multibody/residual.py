r"""The residual F_R and its exact linearization from the kernel's kinematics.

Blocks (see :mod:`.model`): R1 = M q̈ − Q_v + J_Φᵀλ − Q_ext, R2 = c_s(Φ̈ + 2αΦ̇ + β²Φ),
R3 = ṗ − h.  Every constraint row is a sum of products ``c_k(t) x_k`` (:mod:`.kernel`) or an
Euler-parameter normalisation; axial force elements (springs, cylinders) act through the
product ``x = d·d`` of their point separation, ``L = √x``, ``L̇ = ẋ/(2L)``, so that
``Q_ext = J_dᵀ d P/L = ½ P/L ∂x/∂q`` with the push force P(L, L̇, p, t) of the element's
``law``; rotational spring-dampers act through their products x = u1·u2, y = v1·u2 with the
weights of :func:`.rotational.rotational_law`.  J_Φᵀλ, the force elements and point forces are all
*primitive forces* f
(:meth:`.kernel.Kin.prim_forces`), whose second derivatives give the geometric stiffness.

Inertia (per body, Euler parameters): R1_r = m r̈,
R1_p = 4 G(p)ᵀJ'G(p) p̈ − 8 G(ṗ)ᵀJ'G(ṗ) p, with G(a)b = T_G[:, k, l] a_k b_l bilinear, so
∂(G(a)ᵀv)/∂a = Σ_i v_i T_G[i]ᵀ and ∂(G(a)b)/∂a = T_G·b are constant tensors.

Force elements without a law here (body-frame point forces, torques) are evaluated through
:mod:`.forces`: torques in closed form with their exact Jacobian, the others per state and
differentiated by complex step (central differences for complex data).
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from ..base import Linearization
from .bodies import Ctx
from .kernel import Kin
from .rotational import rotational_law, weight_rows
from .rotations import T_G, rmatmul

if TYPE_CHECKING:  # pragma: no cover
    from .model import MultibodyModel

Array = np.ndarray


# The bilinear G as plain matrices, so that each evaluation is one matmul (faster than einsum
# for these tiny operands): G(a) = a @ _TG_A, ∂(G(a)b)/∂a = b @ _TG_B, ∂(G(a)ᵀv)/∂a = v @ _TG_V
_TG_A = np.ascontiguousarray(T_G.transpose(1, 0, 2).reshape(4, 12))     # [k, (i, l)]
_TG_B = np.ascontiguousarray(T_G.transpose(2, 0, 1).reshape(4, 12))     # [l, (i, k)]
_TG_V = np.ascontiguousarray(T_G.transpose(0, 2, 1).reshape(3, 16))     # [i, (l, k)]


def _G(a: Array) -> Array:
    """G(a) (..., 3, 4) for quaternions a (..., 4)."""
    return (a @ _TG_A).reshape(a.shape[:-1] + (3, 4))


def _Gb(b: Array) -> Array:
    """∂(G(a) b)/∂a (..., 3, 4) for b (..., 4)."""
    return (b @ _TG_B).reshape(b.shape[:-1] + (3, 4))


def _GTv(v: Array) -> Array:
    """∂(G(a)ᵀ v)/∂a (..., 4, 4) for v (..., 3)."""
    return (v @ _TG_V).reshape(v.shape[:-1] + (4, 4))


def point_force(pf: Any, t: float, pv: Array) -> Array:
    """Global point force F·φ(t) (B, 3) of a PointForce element for parameter vectors pv (B, n)."""
    val = np.asarray(pf.fn.value(t, pv))
    return pv[:, list(pf.idx)] * (val[..., None] if val.ndim else val)


def time_inputs(model: "MultibodyModel", kp: Any, t: float, dtype: Any) -> tuple[Array, Array, Array]:
    """Element inputs (B, n_ax), applied point forces on the primitives (·, n_t, 3) and gravity
    (·, 3) of the parameter sets kp at time t (s), in dtype; kept on kp for the last t (Newton
    evaluates all iterates of a step at one time; the arrays are read-only), and from then on
    once the time functions have settled (their ``settled_from``)."""
    dt = np.dtype(dtype)
    cache = kp.cache.inputs
    hit = cache.get(dt.char)
    if hit is not None and (hit[0] == t or (t > hit[1] and hit[0] > hit[1])):
        return hit[2]
    out = time_inputs_steps(model, kp, np.array([t]), dt)
    cache[dt.char] = (t, _steady(model, kp, dt)[3], out)
    return out


def time_inputs_steps(model: "MultibodyModel", kp: Any, ts: Array, dtype: Any) -> tuple[Array, Array, Array]:
    """The inputs of :func:`time_inputs` at the K times ts (s), entry k·B + j for step k and
    parameter set j: element inputs (K·B, n_ax), point forces (K·B, n_t, 3) — (B, n_t, 3) when
    they are constant in time, (1, n_t, 3) without any; the compiled kernel repeats leading
    entries cyclically — and gravity (B or 1, 3).  Once the time functions have settled (all
    ts past their ``settled_from``), the inputs at the first time stand for all (B entries)."""
    lay = model.layout
    dt = np.dtype(dtype)
    K, B = len(ts), kp.B
    g, f_ext, forces, settled = _steady(model, kp, dt)
    if K > 1 and ts[0] > settled and np.all(ts > settled):
        ts, K = ts[:1], 1
    ext = np.zeros((K, B, len(lay.axial)), dt)
    for i, el in enumerate(lay.axial):
        for k, t in enumerate(ts):
            ext[k, :, i] = el.external(t, kp.pv)
    if f_ext is None:
        f_ext = np.zeros((B * K, lay.n_t, 3), dt)
        for pf, j in forces:
            for k, t in enumerate(ts):
                f_ext[k * B:(k + 1) * B, j] -= point_force(pf, t, kp.pv)
    return ext.reshape(K * B, -1), f_ext, g


def _steady(model: "MultibodyModel", kp: Any, dt: np.dtype) -> tuple[Array, Array | None, list, float]:
    """What does not depend on t, formed once per parameter sets and dtype: gravity, the point
    forces when all of them are constant in time (else None, with the list of them), and the
    time after which nothing changes.  The arrays are never written to: the kernel reads them,
    and numba would compile another specialization for read-only arrays."""
    kept = kp.cache.steady_inputs.get(dt.char)
    if kept is not None:
        return kept
    lay, B = model.layout, kp.B
    forces = [(pf, j) for pf, j in zip(model.point_forces, lay.point_prim) if j >= 0]
    g = np.ascontiguousarray(kp.pv[:, list(model.gravity.idx)], dt) if model.gravity is not None \
        else np.zeros((1, 3), dt)
    f0 = None
    if all(pf.fn.kind == "constant" for pf, _ in forces):
        f0 = np.zeros((B if forces else 1, lay.n_t, 3), dt)
        for pf, j in forces:
            f0[:, j] -= point_force(pf, 0.0, kp.pv)
    settled = max([el.settled_from(kp.pv) for el in lay.axial] + [pf.fn.settled_from(kp.pv) for pf, _ in forces],
                  default=-np.inf)
    kept = kp.cache.steady_inputs[dt.char] = (g, f0, forces, float(settled))
    return kept


class Evaluation(ABC):
    """Residual pieces at one (batched) state; :meth:`residual` and :meth:`linearization`.

    Two backends, chosen once per evaluation by :func:`.residual_compiled.evaluate`: the numpy
    expressions of :class:`NumpyEvaluation` (the reference) and the compiled kernel's
    :class:`.residual_compiled.CompiledEvaluation`.  Both leave the same pieces for the sparse
    linearization and the outputs: constraint levels ``Phi`` and coefficients ``cf``, product
    weights ``w`` and primitive forces ``f``.

    Parameters
    ----------
    model : the multibody model (layout, settings, force elements).
    kin : kinematics at (q, q̇, q̈) for the parameter sets kp.
    t : time (s); lam (Bs, n_λ), p (Bs, n_p), pd (Bs, n_p): multipliers, pressures, rates.
    """

    #: whether the compiled kernel evaluates (the sparse linearization reads its arrays then)
    compiled: ClassVar[bool]
    Phi: Array
    cf: Array
    w: Array
    f: Array

    def __init__(self, model: "MultibodyModel", kin: Kin, t: float, lam: Array, p: Array, pd: Array):
        self.model, self.kin, self.kp, self.t = model, kin, kin.kp, t
        self.lam, self.p, self.pd = lam, p, pd

    @abstractmethod
    def residual(self) -> Array:
        """F_R (B, n_z)."""

    @abstractmethod
    def linearization(self) -> Linearization:
        """Exact ∂F_R/∂(z, q, q̇, p) of the first batch entry."""


class NumpyEvaluation(Evaluation):
    """The numpy expressions of the residual and its linearization: the reference of the
    compiled kernel (:mod:`.compiled`), and the path of data it does not take."""

    compiled = False

    def __init__(self, model: "MultibodyModel", kin: Kin, t: float, lam: Array, p: Array, pd: Array):
        super().__init__(model, kin, t, lam, p, pd)
        lay = model.layout
        kp = self.kp
        self.Phi, cf = model.constraint_levels(t, kin)
        self.cf = cf
        c = cf[..., 0]
        lam_r = rmatmul(lay.S.T, lam.T).T
        B = kin.X.shape[0]
        w = np.zeros((B, lay.n_prod), np.result_type(kin.X, lam, p, float))
        w[:, :lay.n_cp] = c * lam_r
        self.laws = []
        for i, el in enumerate(lay.axial):
            xi = kin.X[:, lay.n_cp + i]
            L = np.sqrt(xi[..., 0])
            Ld = xi[..., 1] / (2.0 * L)
            j = el.p_index
            law = el.law(L, Ld, p[..., j:j + el.n_pressures], t, kp.pv, kp.ec[i])
            self.laws.append((L, Ld, law))
            w[:, lay.n_cp + i] = -0.5 * law[0] / L
        X = kin.X
        self.rot_laws = []
        for i, px in enumerate(lay.rot_prod):
            rc = kp.rc[:, i]
            rot = rotational_law(X[:, px, 0], X[:, px + 1, 0], X[:, px, 1], X[:, px + 1, 1], rc[:, 0], rc[:, 1],
                                 rc[:, 2])
            self.rot_laws.append(rot)
            w[:, px], w[:, px + 1] = rot[3], rot[4]
        self.w = w
        f = kin.prim_forces(w)
        for pf, j in zip(model.point_forces, lay.point_prim):
            if j >= 0:
                f[:, j] -= point_force(pf, self.t, kp.pv)
        self.f = f


    def residual(self) -> Array:
        """F_R (B, n_z)."""
        m, kin, kp, lay = self.model, self.kin, self.kp, self.model.layout
        Lp = kin.Lp
        p, pd_, pdd = Lp[:, 0], Lp[:, 1], Lp[:, 2]
        J = kp.J
        Gp, Gpd = _G(p), _G(pd_)
        w1 = J @ (Gp @ pdd[..., None])                              # J'G(p)p̈, (..., 3, 1)
        w2 = J @ (Gpd @ p[..., None])
        Rp = 4.0 * (np.swapaxes(Gp, -1, -2) @ w1)[..., 0] - 8.0 * (np.swapaxes(Gpd, -1, -2) @ w2)[..., 0]
        Rr = kp.mass[..., None] * kin.Lr[:, 2]
        if m.gravity is not None:
            g = kp.pv[:, list(m.gravity.idx)]
            Rr = Rr - kp.mass[..., None] * g[:, None, :]
        Phi = self.Phi
        Q = kin.generalized(self.f)                                  # (B, n_q)
        B, tr = Q.shape[0], m.traits
        out = np.zeros((B, tr.n_z), np.result_type(Q, Rr, Rp, self.lam, Phi, self.pd))
        R1 = out[:, :lay.n_q]
        R1 += Q
        R1v = R1.reshape(B, lay.n_b, 7)
        R1v[..., :3] += Rr
        R1v[..., 3:] += Rp
        R1v[:, lay.norm_body, 3:] += 2.0 * self.lam[..., lay.norm_eq, None] * p[:, lay.norm_body]
        if m.other_forces:
            R1 -= other_forces_q(m, self.t, kin.q, kin.qd, kp.prms)
        out[:, lay.n_q:lay.n_q + tr.n_lam] = m.scale * (Phi[..., 2] + 2.0 * m.alpha * Phi[..., 1]
                                                         + m.beta ** 2 * Phi[..., 0])
        R3 = out[:, lay.n_q + tr.n_lam:]
        R3 += self.pd
        for el, (_, _, law) in zip(lay.axial, self.laws):
            for i, h in enumerate(law[4]):
                R3[:, el.p_index + i] -= h
        return out

    def linearization(self) -> Linearization:
        """Exact ∂F_R/∂(z, q, q̇, p) of the first batch entry."""
        m, kin, lay = self.model, self.kin, self.model.layout
        tr = m.traits
        n_q, n_lam, n_p = tr.n_q, tr.n_lam, tr.n_p
        dt = np.result_type(kin.PV, self.lam, self.p, self.f)
        Jx, Dx, Ax, _, _ = kin.rows()
        # rows of J_Φ, ∂R2/∂q, ∂R2/∂q̇ (o = 0, 1, 2) from the product rows (r = Jx, Dx, Ax):
        # weights linear in the coefficients (c, ċ, c̈), one matmul each for all equations
        kk = m.eq_row_weights @ self.cf[0].T                         # (o, r, n_cp)
        M = (kk.transpose(2, 0, 1) @ kin.xrows[:lay.n_cp]).transpose(1, 0, 2)   # (o, n_cp, n_q)
        rows = rmatmul(lay.S, M).astype(dt, copy=False)
        Lp = kin.Lp[0][:, lay.norm_body].reshape(3, -1)              # normalisations: 2 p·(levels)
        blk = (2.0 * m.norm_row_weights @ Lp).reshape(3, -1, 4)
        rows[:, lay.norm_eq[:, None], lay.norm_cols] += blk
        JPhi, R2_q, R2_qd = rows[0], m.scale * rows[1], m.scale * rows[2]
        # R1
        H = kin.hessian(self.w[0], self.f[0])
        lam_n = self.lam[0, lay.norm_eq]
        for col, ln in zip(lay.norm_cols, lam_n):
            H[col, col] += 2.0 * ln
        R1_q, R1_qd, R1_qdd = self._inertia_blocks(dt)
        R1_q = R1_q + H
        R3_q = np.zeros((n_p, n_q), dt)
        R3_qd = np.zeros((n_p, n_q), dt)
        R1_p = np.zeros((n_q, n_p), dt)
        R3_p = np.zeros((n_p, n_p), dt)
        for i, (el, (L, Ld, law)) in enumerate(zip(lay.axial, self.laws)):
            L, Ld = L[0], Ld[0]
            P, P_L, P_Ld, P_p, h, h_L, h_Ld, h_p = law
            jx, dx = Jx[lay.n_cp + i], Dx[lay.n_cp + i]
            dL = jx / (2.0 * L)
            dLd = dx / (2.0 * L) - (Ld / L) * dL
            w_L = -0.5 * (P_L[0] / L - P[0] / (L * L))
            w_Ld = -0.5 * P_Ld[0] / L
            R1_q += np.outer(jx, w_L * dL + w_Ld * dLd)
            R1_qd += np.outer(jx, w_Ld * dL)
            j = el.p_index
            for k, Pk in enumerate(P_p):
                R1_p[:, j + k] += -0.5 * Pk[0] / L * jx
            for r in range(len(h)):
                R3_q[j + r] -= h_L[r][0] * dL + h_Ld[r][0] * dLd
                R3_qd[j + r] -= h_Ld[r][0] * dL
                for k in range(len(h_p[r])):
                    R3_p[j + r, j + k] -= h_p[r][k][0]
        for px, law in zip(lay.rot_prod, self.rot_laws):
            jx, jy = Jx[px], Jx[px + 1]
            rx, ry, rxd, ryd = weight_rows([v[0] for v in law], jx, jy, Dx[px], Dx[px + 1])
            R1_q += np.outer(jx, rx) + np.outer(jy, ry)
            R1_qd += np.outer(jx, rxd) + np.outer(jy, ryd)
        if m.other_forces:
            Kq, Kqd = other_forces_jacobians(m, self.t, kin.q[0], kin.qd[0], kin.kp.prms[0])
            R1_q -= Kq
            R1_qd -= Kqd
        n_z = tr.n_z
        R_z = np.zeros((n_z, n_z), dt)
        R_z[:n_q, :n_q] = R1_qdd
        R_z[:n_q, n_q:n_q + n_lam] = JPhi.T
        R_z[n_q:n_q + n_lam, :n_q] = m.scale * JPhi
        R_z[n_q + n_lam:, n_q + n_lam:] = np.eye(n_p)
        return Linearization(R_z, np.concatenate([R1_q, R2_q, R3_q]),
                             np.concatenate([R1_qd, R2_qd, R3_qd]),
                             np.concatenate([R1_p, np.zeros((n_lam, n_p)), R3_p]) if n_p else None)

    def _inertia_blocks(self, dt: Any) -> tuple[Array, Array, Array]:
        """∂(Mq̈ − Q_v)/∂(q, q̇, q̈) (each (n_q, n_q)), block diagonal per body."""
        kin, kp, lay = self.kin, self.kp, self.model.layout
        n_q = lay.n_q
        p, pd_, pdd = kin.Lp[0, 0], kin.Lp[0, 1], kin.Lp[0, 2]          # (n_b, 4)
        J = kp.J[0]
        Gp, Gpd = _G(p), _G(pd_)
        w1 = (J @ (Gp @ pdd[..., None]))[..., 0]
        w2 = (J @ (Gpd @ p[..., None]))[..., 0]
        GpT, GpdT = np.swapaxes(Gp, 1, 2), np.swapaxes(Gpd, 1, 2)
        JGp, JGpd = J @ Gp, J @ Gpd
        Mpp = 4.0 * GpT @ JGp
        Kpp = 4.0 * (_GTv(w1) + GpT @ J @ _Gb(pdd)) - 8.0 * GpdT @ JGpd
        Cpp = -8.0 * (_GTv(w2) + GpdT @ J @ _Gb(p))
        # scatter the per-body blocks with precomputed indices (no per-body Python loop)
        out = np.zeros((3, n_q, n_q), dt)
        out[2][lay.r_diag] = np.repeat(kp.mass[0], 3)
        out[:, lay.p_blocks[0], lay.p_blocks[1]] = np.stack([Kpp, Cpp, Mpp])
        return out[0], out[1], out[2]


def other_forces_q(model: "MultibodyModel", t: float, q: Array, qd: Array, prms: list[Any],
                   elements: list[Any] | None = None) -> Array:
    """Q_ext (B, n_q) of the elements without a law here (default: all of model.other_forces)
    for q, qd (B or 1, n_q): closed-form elements for the whole batch at once; the others with
    the states of one parameter set as the columns of one Ctx, otherwise one Ctx per entry."""
    elements = model.other_forces if elements is None else elements
    B = max(q.shape[0], qd.shape[0], len(prms))
    dt = np.result_type(q, qd, *(p.pv for p in prms), float)
    n_q = model.traits.n_q
    out = np.zeros((B, n_q), dt)
    closed = [el for el in elements if el.closed_form]
    if closed:
        pv = np.stack([p.pv for p in prms])
        qb = np.broadcast_to(q, (B, n_q))
        for el in closed:
            el.add_batch(t, qb, pv, out)
    rest = [el for el in elements if not el.closed_form]
    if not rest:
        return out
    if len(prms) == 1:
        Q, Qd = (np.broadcast_to(v, (B, n_q)).T for v in (q, qd))
        o = np.zeros((n_q, B), dt)
        ctx = Ctx(Q, Qd, np.zeros((n_q, B)), prms[0], t)     # (B columns: elements may read Point kinematics)
        for el in rest:
            el.add(ctx, o)
        return out + o.T
    for b in range(B):
        qb, qdb = q[min(b, q.shape[0] - 1)], qd[min(b, qd.shape[0] - 1)]
        ctx = Ctx(qb[:, None], qdb[:, None], np.zeros((qb.shape[0], 1)), prms[min(b, len(prms) - 1)], t)
        o = out[b][:, None].copy()
        for el in rest:
            el.add(ctx, o)
        out[b] = o[:, 0]
    return out


def other_forces_jacobians(model: "MultibodyModel", t: float, q: Array, qd: Array, prm: Any
                           ) -> tuple[Array, Array]:
    """∂Q_ext/∂q and ∂Q_ext/∂q̇ (n_q, n_q) of the elements without a law here: exact for the
    closed-form elements and those with exact Jacobians, by complex step (central differences
    for complex data) for the rest."""
    from .assembly import _jac
    n_q = model.traits.n_q
    dt = np.result_type(q, qd, prm.pv, float)
    Kq, Kqd = np.zeros((n_q, n_q), dt), np.zeros((n_q, n_q), dt)
    rest = [el for el in model.other_forces if not (el.closed_form or el.exact_jacobians)]
    for el in model.other_forces:
        if el.closed_form:
            el.add_jacobian(t, q, prm.pv, Kq)
        elif el.exact_jacobians:
            el.add_jacobians(t, q, qd, prm, Kq, Kqd)
    if rest:
        real = not (np.iscomplexobj(q) or np.iscomplexobj(qd) or np.iscomplexobj(prm.pv))
        Kq += _jac(lambda qb: other_forces_q(model, t, qb.T, qd[None], [prm], rest).T, q, real)
        Kqd += _jac(lambda qb: other_forces_q(model, t, q[None], qb.T, [prm], rest).T, qd, real)
    return Kq, Kqd
