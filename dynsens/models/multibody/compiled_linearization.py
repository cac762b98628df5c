r"""Compiled linearization of the multibody kernel: the exact ∂F_R/∂(z, q, q̇, p) of
:func:`.compiled.forces_and_residual` (method.md §2), and the iteration matrix.

The rows of the products x = a·b (∂x/∂q, ∂ẋ/∂q, ∂ẍ/∂q) are formed primitive by primitive from
the kinematics of :func:`.compiled.kinematics`; the constraint rows (J_Φ and the partials of the
acceleration-level equations) weight them by the products' coefficient levels.  The inline
helpers here are shared with the sparse block writers of :mod:`.sparse`, so the dense and the
sparse linearization do the same per-element arithmetic.  Notation as in :mod:`.compiled`.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from .compiled import _G, _mm, _mv, inline, jit
from .rotational import weight_rows

rotational_weight_rows = inline(weight_rows)

Array = np.ndarray


@inline
def _add_prim_rowT(G: Array, p: int, T: int, j: int, lev: int, ABV: Array, s_: int, l_: int,
                   coef: float, C: Array, o: int, point: bool) -> None:
    """G[p, T, o:o + 7] += coef · (∂ primitive j at level lev / ∂(r, p) of its body)ᵀ v with
    v = ABV[s_, p, l_] (a level of the other side): identity on r (points, value level), 2C(L_lev)
    on p; o is the column of the body's first coordinate in G."""
    if lev == 0 and point:
        for a in range(3):
            G[p, T, o + a] += coef * ABV[s_, p, l_, a]
    for k in range(4):
        s = 0.0
        for a in range(3):
            s += C[j, a, k, lev] * ABV[s_, p, l_, a]
        G[p, T, o + 3 + k] += 2.0 * coef * s


@inline
def product_row(G: Array, p: int, C: Array, ABV: Array, is_point: Array, side_ptr: Array,
                side_prim: Array, side_coef: Array, side_col: Array) -> None:
    """G[p] += ∂x/∂q, ∂ẋ/∂q, ∂ẍ/∂q of product p, x_T = Σ RL[T, l, m] a_l·b_m (RL as
    kernel.ROW_LEVELS); side entry e's body starts at column side_col[e] of G."""
    n_prod = ABV.shape[1]
    # RL is symmetric in (l, m), so ∂x_T/∂q sums, for side a and side b alike, (∂ own side at
    # level l)·(other side at level m) over the same pairs: (0, 0) for T = 0; (0, 1), (1, 0) for
    # T = 1; (0, 2), (2, 0), 2·(1, 1) for T = 2 (unrolled: a runtime index into a tuple of them
    # costs more than the arithmetic)
    for s_ in range(2):
        o = 1 - s_
        for e in range(side_ptr[s_ * n_prod + p], side_ptr[s_ * n_prod + p + 1]):
            j, c, col, pt = side_prim[e], side_coef[e], side_col[e], is_point[side_prim[e]]
            _add_prim_rowT(G, p, 0, j, 0, ABV, o, 0, c, C, col, pt)
            _add_prim_rowT(G, p, 1, j, 0, ABV, o, 1, c, C, col, pt)
            _add_prim_rowT(G, p, 1, j, 1, ABV, o, 0, c, C, col, pt)
            _add_prim_rowT(G, p, 2, j, 0, ABV, o, 2, c, C, col, pt)
            _add_prim_rowT(G, p, 2, j, 2, ABV, o, 0, c, C, col, pt)
            _add_prim_rowT(G, p, 2, j, 1, ABV, o, 1, 2.0 * c, C, col, pt)


@jit
def product_rows(C: Array, ABV: Array, pb: Array, is_point: Array, side_ptr: Array,
                 side_prim: Array, side_coef: Array, n_q: int) -> Array:
    """G (n_prod, 3, n_q): ∂x/∂q, ∂ẋ/∂q, ∂ẍ/∂q of every product x = a·b."""
    n_prod = ABV.shape[1]
    G = np.zeros((n_prod, 3, n_q), C.dtype)
    side_col = 7 * pb[side_prim]
    for p in range(n_prod):
        product_row(G, p, C, ABV, is_point, side_ptr, side_prim, side_coef, side_col)
    return G


@inline
def _prim_jac0(j: int, C: Array, is_point: Array) -> Array:
    """(3, 7) ∂(value of primitive j)/∂(r, p) of its body."""
    K = np.zeros((3, 7), C.dtype)
    if is_point[j]:
        for a in range(3):
            K[a, a] = 1.0
    for a in range(3):
        for k in range(4):
            K[a, 3 + k] = 2.0 * C[j, a, k, 0]
    return K


@inline
def row_weight(eq_w: Array, cf: Array, p: int, o: int, r: int) -> Any:
    """Weight of product row r (∂x, ∂ẋ, ∂ẍ/∂q) of constraint product p in output row o (J_Φ,
    ∂R2/∂q, ∂R2/∂q̇), linear in the product's coefficient levels (c, ċ, c̈)."""
    return eq_w[o, r, 0] * cf[p, 0] + eq_w[o, r, 1] * cf[p, 1] + eq_w[o, r, 2] * cf[p, 2]


@inline
def norm_row_entry(norm_w: Array, Lp: Array, b: int, o: int, k: int) -> Any:
    """Entry k of the Euler-parameter part of output row o of body b's normalisation: 2p·(levels)."""
    s = 0.0
    for l in range(3):
        s += norm_w[o, l] * Lp[l, b, k]
    return 2.0 * s


@inline
def constraint_rows(rows: Array, G: Array, Lp: Array, cf: Array, eq_w: Array, norm_w: Array,
                    prod_eq: Array, norm_eq: Array, norm_body: Array, n_cp: int) -> None:
    """rows[o] += output row o of every constraint equation for o < rows.shape[0] (J_Φ,
    ∂R2/∂q, ∂R2/∂q̇): the product rows G weighted by the coefficient levels, plus the
    normalisations' 2p·(levels) on their body's Euler parameters."""
    n_o, n_q = rows.shape[0], rows.shape[2]
    for p in range(n_cp):
        e = prod_eq[p]
        for o in range(n_o):
            for r in range(3):
                kk = row_weight(eq_w, cf, p, o, r)
                if kk != 0.0:
                    for n in range(n_q):
                        rows[o, e, n] += kk * G[p, r, n]
    for i in range(norm_eq.shape[0]):
        e = norm_eq[i]
        b = norm_body[i]
        for o in range(n_o):
            for k in range(4):
                rows[o, e, 7 * b + 3 + k] += norm_row_entry(norm_w, Lp, b, o, k)


@inline
def compact_constraint_rows(Jc: Array, G: Array, Lp: Array, cf: Array, eq_w: Array, norm_w: Array,
                            prod_eq: Array, prod_nb: Array, eq_slot: Array, norm_eq: Array,
                            norm_body: Array, n_cp: int) -> None:
    """:func:`constraint_rows` in the compact form of the sparse path (:mod:`.sparse`): Jc[o, e]
    holds equation e's row on the 7 columns of each of its bodies (slot eq_slot[p, s] of product
    p's body s), from product rows G on the products' own bodies."""
    n_o = Jc.shape[0]
    for p in range(n_cp):
        e = prod_eq[p]
        for o in range(n_o):
            for r in range(3):
                kk = row_weight(eq_w, cf, p, o, r)
                if kk != 0.0:
                    for s in range(prod_nb[p]):
                        a, b = 7 * eq_slot[p, s], 7 * s
                        for c in range(7):
                            Jc[o, e, a + c] += kk * G[p, r, b + c]
    for i in range(norm_eq.shape[0]):               # a normalisation's only body is its slot 0
        for o in range(n_o):
            for k in range(4):
                Jc[o, norm_eq[i], 3 + k] += norm_row_entry(norm_w, Lp, norm_body[i], o, k)


@jit
def compact_constraint_jacobians(C: Array, ABV: Array, Lp: Array, cf: Array, is_point: Array,
                                 side_ptr: Array, side_prim: Array, side_coef: Array, side_slot: Array,
                                 prod_nb: Array, n_cp: int, prod_eq: Array, eq_slot: Array,
                                 n_eq_slots: int, eq_w: Array, norm_w: Array, norm_eq: Array,
                                 norm_body: Array, n_lam: int) -> Array:
    """J_Φ of each of the B entries of the kinematics in the compact form of the sparse path:
    (B, n_λ, 7·n_eq_slots), the first output row of :func:`compact_constraint_rows`."""
    B, PB = C.shape[0], eq_slot.shape[1]
    Jc = np.zeros((B, 1, n_lam, 7 * n_eq_slots), C.dtype)
    side_col = 7 * side_slot
    for b in range(B):
        G = np.zeros((n_cp, 3, 7 * PB), C.dtype)     # the constraint products' rows only
        for p in range(n_cp):
            product_row(G, p, C[b], ABV[b], is_point, side_ptr, side_prim, side_coef, side_col)
        compact_constraint_rows(Jc[b], G, Lp[b], cf[min(b, cf.shape[0] - 1)], eq_w, norm_w, prod_eq,
                                prod_nb, eq_slot, norm_eq, norm_body, n_cp)
    return Jc[:, 0]


@jit
def constraint_jacobians(C: Array, ABV: Array, Lp: Array, cf: Array, pb: Array, is_point: Array,
                         side_ptr: Array, side_prim: Array, side_coef: Array, n_cp: int,
                         prod_eq: Array, eq_w: Array, norm_w: Array, norm_eq: Array,
                         norm_body: Array, n_eq: int) -> Array:
    """J_Φ (B, n_eq, n_q) at each of the B entries of the kinematics (C, ABV, Lp with leading
    axis B; the coefficient levels cf (1 or B, n_cp, 3)): the first output row of
    :func:`constraint_rows`, the same arithmetic as the linearization's."""
    B, n_q = C.shape[0], 7 * Lp.shape[2]
    J = np.zeros((B, 1, n_eq, n_q), C.dtype)
    for b in range(B):
        G = product_rows(C[b], ABV[b], pb, is_point, side_ptr, side_prim, side_coef, n_q)
        constraint_rows(J[b], G, Lp[b], cf[min(b, cf.shape[0] - 1)], eq_w, norm_w, prod_eq, norm_eq,
                        norm_body, n_cp)
    return J[:, 0]


@inline
def axial_rates(jx: Array, dx: Array, L: Any, Ld: Any, dL: Array, dLd: Array) -> None:
    """∂L/∂q and ∂L̇/∂q into dL, dLd from the rows ∂x/∂q (jx), ∂ẋ/∂q (dx) of x = d·d, L = √x."""
    for n in range(jx.shape[0]):
        dL[n] = jx[n] / (2.0 * L)
        dLd[n] = dx[n] / (2.0 * L) - (Ld / L) * dL[n]


@inline
def axial_weights(L: Any, P: Any, P_L: Any, P_Ld: Any) -> tuple[Any, Any]:
    """∂w/∂L, ∂w/∂L̇ of the product weight w = −½ P/L of an axial element."""
    return -0.5 * (P_L / L - P / (L * L)), -0.5 * P_Ld / L


@inline
def inertia_blocks(Lp: Array, b: int, Jb: Array, TG: Array) -> tuple[Array, Array, Array]:
    """∂(4GᵀJ'G p̈ − 8 G(ṗ)ᵀJ'G(ṗ) p)/∂(p, ṗ, p̈) of body b: (K_pp, C_pp, M_pp), each (4, 4)."""
    p, pd_, pdd = Lp[0, b], Lp[1, b], Lp[2, b]
    Gp = _G(TG, p)
    Gpd = _G(TG, pd_)
    w1 = _mv(Jb, _mv(Gp, pdd))
    w2 = _mv(Jb, _mv(Gpd, p))
    # ∂(G(a) b)/∂a = Σ_l T_G[:, :, l] b_l and ∂(G(a)ᵀ v)/∂a [l, k] = Σ_i v_i T_G[i, k, l]
    Gb_pdd = np.zeros((3, 4), Lp.dtype)
    Gb_p = np.zeros((3, 4), Lp.dtype)
    GTv1 = np.zeros((4, 4), Lp.dtype)
    GTv2 = np.zeros((4, 4), Lp.dtype)
    for i in range(3):
        for k in range(4):
            for l in range(4):
                t = TG[i, k, l]
                if t != 0.0:
                    Gb_pdd[i, k] += t * pdd[l]
                    Gb_p[i, k] += t * p[l]
                    GTv1[l, k] += t * w1[i]
                    GTv2[l, k] += t * w2[i]
    Mpp = 4.0 * _mm(Gp.T, _mm(Jb, Gp))
    Kpp = 4.0 * (GTv1 + _mm(Gp.T, _mm(Jb, Gb_pdd))) - 8.0 * _mm(Gpd.T, _mm(Jb, Gpd))
    Cpp = -8.0 * (GTv2 + _mm(Gpd.T, _mm(Jb, Gb_p)))
    return Kpp, Cpp, Mpp


@inline
def _geometric_stiffness(R1_q: Array, w: Array, n_prod: int, C: Array, is_point: Array, pb: Array,
                         side_ptr: Array, side_prim: Array, side_coef: Array) -> None:
    """R1_q += Σ_p w_p ∂²x_p/∂q² over the n_prod products (the sides' value Jacobians are per body)."""
    for p in range(n_prod):
        wp = w[p]
        if wp == 0.0:
            continue
        for ea in range(side_ptr[p], side_ptr[p + 1]):
            ja = side_prim[ea]
            Ka = _prim_jac0(ja, C, is_point)
            ba = 7 * pb[ja]
            for eb in range(side_ptr[n_prod + p], side_ptr[n_prod + p + 1]):
                jb = side_prim[eb]
                Kb = _prim_jac0(jb, C, is_point)
                bb = 7 * pb[jb]
                c = wp * side_coef[ea] * side_coef[eb]
                blk = _mm(Ka.T, Kb)           # c·blk: ∂²(a·b)/∂q_a∂q_b of the two primitives
                for u in range(7):
                    for v in range(7):
                        R1_q[ba + u, bb + v] += c * blk[u, v]
                        R1_q[bb + v, ba + u] += c * blk[u, v]


@inline
def _parameter_curvature(R1_q: Array, f: Array, Ts4: Array, pb: Array, lam: Array, norm_eq: Array,
                         norm_body: Array) -> None:
    """R1_q += ∂²(A s̄)/∂p² · f (2 Σ_a f_a Ts4[a]) and the Euler-parameter normalisations' 2λ I."""
    for j in range(pb.shape[0]):
        o = 7 * pb[j] + 3
        for a in range(3):
            fa = f[j, a]
            if fa != 0.0:
                for k in range(4):
                    for l in range(4):
                        R1_q[o + k, o + l] += 2.0 * fa * Ts4[j, a, k, l]
    for i in range(norm_eq.shape[0]):
        o = 7 * norm_body[i] + 3
        for k in range(4):
            R1_q[o + k, o + k] += 2.0 * lam[norm_eq[i]]


@inline
def _inertia(R1_q: Array, R1_qd: Array, R1_qdd: Array, Lp: Array, mass: Array, J: Array, TG: Array) -> None:
    """∂(M q̈ − Q_v)/∂(q, q̇, q̈), block diagonal per body."""
    for b in range(Lp.shape[1]):
        Kpp, Cpp, Mpp = inertia_blocks(Lp, b, J[b], TG)
        o = 7 * b
        for a in range(3):
            R1_qdd[o + a, o + a] += mass[b]
        for k in range(4):
            for l in range(4):
                R1_q[o + 3 + k, o + 3 + l] += Kpp[k, l]
                R1_qd[o + 3 + k, o + 3 + l] += Cpp[k, l]
                R1_qdd[o + 3 + k, o + 3 + l] += Mpp[k, l]


@inline
def _axial(R1_q: Array, R1_qd: Array, R1_p: Array, dL: Array, dLd: Array, G: Array, ax_prod: Array,
           ax_law: Array, ax_Pp: Array) -> None:
    """Axial force elements: x = d·d, L = √x, L̇ = ẋ/(2L), generalized force ½ P/L ∂x/∂q; their
    ∂L/∂q, ∂L̇/∂q into dL, dLd."""
    n_q = R1_q.shape[0]
    n_p = R1_p.shape[1]
    for i in range(ax_prod.shape[0]):
        jx = G[ax_prod[i], 0]
        dx = G[ax_prod[i], 1]
        L, Ld, P, P_L, P_Ld = ax_law[i, 0], ax_law[i, 1], ax_law[i, 2], ax_law[i, 3], ax_law[i, 4]
        axial_rates(jx, dx, L, Ld, dL[i], dLd[i])
        w_L, w_Ld = axial_weights(L, P, P_L, P_Ld)
        for u in range(n_q):
            if jx[u] != 0.0:
                for v in range(n_q):
                    R1_q[u, v] += jx[u] * (w_L * dL[i, v] + w_Ld * dLd[i, v])
                    R1_qd[u, v] += jx[u] * (w_Ld * dL[i, v])
                for k in range(n_p):
                    R1_p[u, k] += -0.5 * ax_Pp[i, k] / L * jx[u]


@inline
def pressure_rows(R3_q: Array, R3_qd: Array, dL: Array, dLd: Array, p_owner: Array, h_L: Array,
                  h_Ld: Array) -> None:
    """∂R3/∂q, ∂R3/∂q̇ of the pressure rows from their owner elements' ∂L/∂q, ∂L̇/∂q (dL, dLd);
    the columns those of dL (all coordinates, or the owner's bodies in the sparse form)."""
    for r in range(h_L.shape[0]):
        i = p_owner[r]
        if i >= 0:
            for n in range(R3_q.shape[1]):
                R3_q[r, n] -= h_L[r] * dL[i, n] + h_Ld[r] * dLd[i, n]
                R3_qd[r, n] -= h_Ld[r] * dL[i, n]


@inline
def _rotational(R1_q: Array, R1_qd: Array, G: Array, rot_prod: Array, rot_law: Array) -> None:
    """Rotational spring-dampers: weights w_x, w_y of x = u1·u2, y = v1·u2 (their second
    derivatives are in the geometric stiffness)."""
    n_q = R1_q.shape[0]
    for i in range(rot_prod.shape[0]):
        px = rot_prod[i]
        jx, jy = G[px, 0], G[px + 1, 0]
        rx, ry, rxd, ryd = rotational_weight_rows(rot_law[i], jx, jy, G[px, 1], G[px + 1, 1])
        for u in range(n_q):
            if jx[u] != 0.0 or jy[u] != 0.0:
                for v in range(n_q):
                    R1_q[u, v] += jx[u] * rx[v] + jy[u] * ry[v]
                    R1_qd[u, v] += jx[u] * rxd[v] + jy[u] * ryd[v]


@jit
def linearization(Lp: Array, C: Array, ABV: Array, G: Array, pb: Array, is_point: Array,
                  Ts4: Array, side_ptr: Array, side_prim: Array, side_coef: Array, n_cp: int,
                  prod_eq: Array, cf: Array, eq_w: Array, norm_w: Array, norm_eq: Array,
                  norm_body: Array, scale: float, w: Array, f: Array, lam: Array, mass: Array,
                  J: Array, TG: Array, ax_prod: Array, ax_law: Array, ax_Pp: Array,
                  p_owner: Array, h_L: Array, h_Ld: Array, h_p: Array, rot_prod: Array,
                  rot_law: Array) -> tuple[Array, Array, Array, Array]:
    """Exact ∂F_R/∂(z, q, q̇, p): (R_z (n_z, n_z), R_q (n_z, n_q), R_qd (n_z, n_q), R_p (n_z, n_p)).

    Axial elements i act through product ax_prod[i] with ax_law[i] = (L, L̇, P, P_L, P_L̇),
    ax_Pp[i, :] = ∂P/∂p; pressure row r belongs to element p_owner[r] with ∂h_r/∂L = h_L[r],
    ∂h_r/∂L̇ = h_Ld[r] and ∂h/∂p = h_p (n_p, n_p).  Rotational spring-damper i acts through
    products rot_prod[i], rot_prod[i] + 1 with its law rot_law[i] (:func:`.rotational.rotational_law`).
    """
    n_q = 7 * Lp.shape[1]
    n_lam = lam.shape[0]
    n_p = h_L.shape[0]
    n_ax = ax_prod.shape[0]
    # --- constraint rows: J_Φ, ∂R2/∂q, ∂R2/∂q̇ (o = 0, 1, 2) from the product rows
    rows = np.zeros((3, n_lam, n_q), Lp.dtype)
    constraint_rows(rows, G, Lp, cf, eq_w, norm_w, prod_eq, norm_eq, norm_body, n_cp)
    # --- R1: the products' curvature, inertia, axial and rotational force elements; R3
    R1_q = np.zeros((n_q, n_q), Lp.dtype)
    R1_qd = np.zeros((n_q, n_q), Lp.dtype)
    R1_qdd = np.zeros((n_q, n_q), Lp.dtype)
    R1_p = np.zeros((n_q, n_p), Lp.dtype)
    R3_q = np.zeros((n_p, n_q), Lp.dtype)
    R3_qd = np.zeros((n_p, n_q), Lp.dtype)
    dL = np.empty((n_ax, n_q), Lp.dtype)
    dLd = np.empty((n_ax, n_q), Lp.dtype)
    _geometric_stiffness(R1_q, w, ABV.shape[1], C, is_point, pb, side_ptr, side_prim, side_coef)
    _parameter_curvature(R1_q, f, Ts4, pb, lam, norm_eq, norm_body)
    _inertia(R1_q, R1_qd, R1_qdd, Lp, mass, J, TG)
    _axial(R1_q, R1_qd, R1_p, dL, dLd, G, ax_prod, ax_law, ax_Pp)
    pressure_rows(R3_q, R3_qd, dL, dLd, p_owner, h_L, h_Ld)
    _rotational(R1_q, R1_qd, G, rot_prod, rot_law)
    return _assemble(rows, R1_q, R1_qd, R1_qdd, R1_p, R3_q, R3_qd, h_p, scale)


@inline
def _assemble(rows: Array, R1_q: Array, R1_qd: Array, R1_qdd: Array, R1_p: Array, R3_q: Array,
              R3_qd: Array, h_p: Array, scale: float) -> tuple[Array, Array, Array, Array]:
    """(R_z, R_q, R_qd, R_p) from the blocks of R1 (motion), R2 (constraint rows) and R3 (pressures)."""
    n_q = R1_q.shape[0]
    n_lam = rows.shape[1]
    n_p = R1_p.shape[1]
    n_z = n_q + n_lam + n_p
    R_z = np.zeros((n_z, n_z), R1_q.dtype)
    R_q = np.zeros((n_z, n_q), R1_q.dtype)
    R_qd = np.zeros((n_z, n_q), R1_q.dtype)
    R_p = np.zeros((n_z, n_p), R1_q.dtype)
    R_z[:n_q, :n_q] = R1_qdd
    R_z[:n_q, n_q:n_q + n_lam] = rows[0].T
    R_z[n_q:n_q + n_lam, :n_q] = scale * rows[0]
    for i in range(n_p):
        R_z[n_q + n_lam + i, n_q + n_lam + i] = 1.0
    R_q[:n_q] = R1_q
    R_q[n_q:n_q + n_lam] = scale * rows[1]
    R_q[n_q + n_lam:] = R3_q
    R_qd[:n_q] = R1_qd
    R_qd[n_q:n_q + n_lam] = scale * rows[2]
    R_qd[n_q + n_lam:] = R3_qd
    R_p[:n_q] = R1_p
    R_p[n_q + n_lam:] = -h_p
    return R_z, R_q, R_qd, R_p


@jit
def iteration_matrix(R_z: Array, R_q: Array, R_qd: Array, R_p: Array, c_q: float, c_qd: float,
                     c_p: float) -> Array:
    """S = R_z + [c_q R_q + c_qd R_qd, 0, c_p R_p] (method.md §3), in the order of
    :meth:`.base.Linearization.iteration_matrix`'s arithmetic."""
    n_z, n_q, n_p = R_z.shape[0], R_q.shape[1], R_p.shape[1]
    S = R_z.copy()
    for i in range(n_z):
        for j in range(n_q):
            S[i, j] += c_q * R_q[i, j] + c_qd * R_qd[i, j]
        for k in range(n_p):
            S[i, n_z - n_p + k] += c_p * R_p[i, k]
    return S
