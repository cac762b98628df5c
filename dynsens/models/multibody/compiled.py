r"""Compiled evaluation of the multibody kernel (the Newton hot path and the design partials).

The numpy kernel (:mod:`.kernel`, :mod:`.residual`) evaluates batches of states and parameter
sets, real or complex, with few numpy calls; for the small arrays of a mechanism its cost is the
call overhead of ~150 tiny array operations per Newton iteration, not arithmetic (BENCHMARKS.md).
This module evaluates the same quantities with loops compiled by numba, and exploits what the
dense products cannot: a side of a product involves one or two primitives, each acting on the 7
coordinates of one body.  Every function takes the dtype of its inputs (the caller casts them to
one): real runs and complex step (complex partials, complex step of the whole run) take the same
code, for one state or a batch (the design partials' parameter sets, the output gradients'
perturbed states).

Same notation as :mod:`.kernel`: primitives j (points and body-fixed directions on moving
bodies) with point tensors ``Ts4[j]`` and ``C_i = Ts·L_i`` (L_0, L_1, L_2 = p, ṗ, p̈); sides
``ABV[s, p, level, :]`` of the products ``x_p = a_p·b_p`` as sparse combinations
(``side_ptr``, ``side_prim``, ``side_coef``: CSR rows ``s·n_prod + p``) of the primitives'
levels.  The force laws are the elements' own plain-arithmetic functions (``spring_law``,
``cylinder_law``, ``rotational_law``), compiled here; the time functions (pump flow, point-force amplitudes,
constraint coefficients) stay in Python and enter as arrays.

The numpy path is kept as the reference and ``tests/test_compiled_kernel.py`` checks that both
agree to round-off.  Set the environment variable ``DYNSENS_KERNEL=numpy`` to switch the
compiled path off (side-by-side benchmarks).
"""
from __future__ import annotations


import numpy as np

# HAVE_NUMBA, KERNELS and enabled are read here by callers and tests
from ...solver._jit import HAVE_NUMBA, KERNELS, enabled, inline, jit  # noqa: F401
from .forces import spring_law
from .hydraulics import cylinder_law
from .rotational import rotational_law
from .rotations import T_G

Array = np.ndarray


# ---------------------------------------------------------------------------- kinematics
@jit
def _kinematics_one(q: Array, qd: Array, qdd: Array, pb: Array, is_point: Array, Ts4: Array,
                    side_ptr: Array, side_prim: Array, side_coef: Array, cAB: Array,
                    norm_body: Array, Lp: Array, Lr: Array, C: Array, PV: Array, ABV: Array,
                    X: Array, N: Array) -> None:
    """:func:`kinematics` of one state and parameter set, into the given output slices."""
    n_b = q.shape[0] // 7
    n_prod = cAB.shape[1]
    for b in range(n_b):
        for k in range(3):
            Lr[0, b, k] = q[7 * b + k]
            Lr[1, b, k] = qd[7 * b + k]
            Lr[2, b, k] = qdd[7 * b + k]
        for k in range(4):
            Lp[0, b, k] = q[7 * b + 3 + k]
            Lp[1, b, k] = qd[7 * b + 3 + k]
            Lp[2, b, k] = qdd[7 * b + 3 + k]
    for j in range(pb.shape[0]):
        b = pb[j]
        for a in range(3):
            for k in range(4):
                for i in range(3):
                    s = 0.0
                    for l in range(4):
                        s += Ts4[j, a, k, l] * Lp[i, b, l]
                    C[j, a, k, i] = s
            # value C(p)p, rate 2C(p)ṗ, acceleration 2C(p)p̈ + 2C(ṗ)ṗ
            v0 = 0.0
            v1 = 0.0
            v2 = 0.0
            for k in range(4):
                v0 += C[j, a, k, 0] * Lp[0, b, k]
                v1 += C[j, a, k, 0] * Lp[1, b, k]
                v2 += C[j, a, k, 0] * Lp[2, b, k] + C[j, a, k, 1] * Lp[1, b, k]
            PV[j, 0, a] = v0
            PV[j, 1, a] = 2.0 * v1
            PV[j, 2, a] = 2.0 * v2
            if is_point[j]:
                for lev in range(3):
                    PV[j, lev, a] += Lr[lev, b, a]
    for sp in range(2 * n_prod):
        s_ = sp // n_prod
        p = sp - s_ * n_prod
        for lev in range(3):
            for a in range(3):
                ABV[s_, p, lev, a] = 0.0
        for e in range(side_ptr[sp], side_ptr[sp + 1]):
            j = side_prim[e]
            c = side_coef[e]
            for lev in range(3):
                for a in range(3):
                    ABV[s_, p, lev, a] += c * PV[j, lev, a]
        for a in range(3):
            ABV[s_, p, 0, a] += cAB[s_, p, a]
    d = np.empty((3, 3), ABV.dtype)
    for p in range(n_prod):
        for l in range(3):
            for m in range(3):
                s = 0.0
                for a in range(3):
                    s += ABV[0, p, l, a] * ABV[1, p, m, a]
                d[l, m] = s
        X[p, 0] = d[0, 0]
        X[p, 1] = d[0, 1] + d[1, 0]
        X[p, 2] = d[0, 2] + d[2, 0] + 2.0 * d[1, 1]
    for e in range(norm_body.shape[0]):
        b = norm_body[e]
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for k in range(4):
            s0 += Lp[0, b, k] * Lp[0, b, k]
            s1 += Lp[0, b, k] * Lp[1, b, k]
            s2 += Lp[0, b, k] * Lp[2, b, k] + Lp[1, b, k] * Lp[1, b, k]
        N[e, 0] = s0
        N[e, 1] = 2.0 * s1
        N[e, 2] = 2.0 * s2


@jit
def kinematics(Q: Array, Qd: Array, Qdd: Array, pb: Array, is_point: Array, Ts4: Array,
               side_ptr: Array, side_prim: Array, side_coef: Array, cAB: Array,
               norm_body: Array) -> tuple[Array, Array, Array, Array, Array, Array, Array]:
    """Levels of all primitives and products for B = max(Bs, Bp) pairs of a state (Q, Q̇, Q̈
    (Bs, n_q)) and a parameter set (Ts4 (Bp, n_t, 3, 4, 4), cAB (Bp, 2, n_prod, 3)); a shorter
    batch repeats cyclically (entry b takes b mod its length): one state or one parameter set
    serves all, and a block of K states × B sets takes the B sets once.

    Returns, each with the leading axis B: Lp (3, n_b, 4) and Lr (3, n_b, 3) (levels of p and
    r), C (n_t, 3, 4, 3) (C[j, a, k, i] = Σ_l Ts4[j, a, k, l] L_i[l]), PV (n_t, 3, 3)
    (primitive levels), ABV (2, n_prod, 3, 3) (side levels), X (n_prod, 3) (x, ẋ, ẍ of the
    products) and N (n_norm, 3) (p·p and its rates).
    """
    Bs, Bp = Q.shape[0], Ts4.shape[0]
    B = max(Bs, Bp)
    n_b = Q.shape[1] // 7
    n_t = pb.shape[0]
    n_prod = cAB.shape[2]
    Lp = np.empty((B, 3, n_b, 4), Q.dtype)
    Lr = np.empty((B, 3, n_b, 3), Q.dtype)
    C = np.empty((B, n_t, 3, 4, 3), Q.dtype)
    PV = np.empty((B, n_t, 3, 3), Q.dtype)
    ABV = np.empty((B, 2, n_prod, 3, 3), Q.dtype)
    X = np.empty((B, n_prod, 3), Q.dtype)
    N = np.empty((B, norm_body.shape[0], 3), Q.dtype)
    kinematics_into(Q, Qd, Qdd, pb, is_point, Ts4, side_ptr, side_prim, side_coef, cAB, norm_body,
                    Lp, Lr, C, PV, ABV, X, N)
    return Lp, Lr, C, PV, ABV, X, N


@jit
def kinematics_into(Q: Array, Qd: Array, Qdd: Array, pb: Array, is_point: Array, Ts4: Array,
                    side_ptr: Array, side_prim: Array, side_coef: Array, cAB: Array, norm_body: Array,
                    Lp: Array, Lr: Array, C: Array, PV: Array, ABV: Array, X: Array, N: Array) -> None:
    """:func:`kinematics` into given arrays (leading axis B = max(Bs, Bp), the dtype of Q)."""
    Bs, Bp = Q.shape[0], Ts4.shape[0]
    for b in range(Lp.shape[0]):
        i, k = b % Bs, b % Bp
        _kinematics_one(Q[i], Qd[i], Qdd[i], pb, is_point, Ts4[k], side_ptr, side_prim, side_coef,
                        cAB[k], norm_body, Lp[b], Lr[b], C[b], PV[b], ABV[b], X[b], N[b])


@jit
def _prim_forces_one(w: Array, ABV: Array, side_ptr: Array, side_prim: Array, side_coef: Array,
                     f: Array) -> None:
    """f (n_t, 3) += Σ_p w_p ∂x_p/∂(primitive values): side a is pulled by w·b, side b by w·a."""
    n_prod = ABV.shape[1]
    for sp in range(2 * n_prod):
        s_ = sp // n_prod
        p = sp - s_ * n_prod
        wp = w[p]
        if wp == 0.0:
            continue
        for e in range(side_ptr[sp], side_ptr[sp + 1]):
            j = side_prim[e]
            c = side_coef[e] * wp
            for a in range(3):
                f[j, a] += c * ABV[1 - s_, p, 0, a]


# ---------------------------------------------------------------------------- residual
# Tiny products as explicit loops: numba's `@` calls BLAS, whose per-call cost exceeds the
# arithmetic of a 3×4 block many times over.
@inline
def _mm(A: Array, B: Array) -> Array:
    """A @ B for small dense blocks."""
    n, k = A.shape
    m = B.shape[1]
    out = np.zeros((n, m), A.dtype)
    for i in range(n):
        for l in range(k):
            a = A[i, l]
            for j in range(m):
                out[i, j] += a * B[l, j]
    return out


@inline
def _mv(A: Array, x: Array) -> Array:
    """A @ x for a small dense block."""
    n, k = A.shape
    out = np.zeros(n, A.dtype)
    for i in range(n):
        s = 0.0
        for l in range(k):
            s += A[i, l] * x[l]
        out[i] = s
    return out


@inline
def _G(TG: Array, a: Array) -> Array:
    """G(a) (3, 4), G(a)[i, l] = Σ_k T_G[i, k, l] a_k."""
    out = np.zeros((3, 4), a.dtype)
    for i in range(3):
        for k in range(4):
            if a[k] != 0.0:
                for l in range(4):
                    out[i, l] += TG[i, k, l] * a[k]
    return out


@jit
def residual(Lp: Array, Lr: Array, C: Array, F: Array, pb: Array, is_point: Array, mass: Array,
             J: Array, gravity: Array, lam: Array, norm_eq: Array, norm_body: Array, Phi: Array,
             scale: float, alpha: float, beta: float, pd: Array, h: Array, TG: Array) -> Array:
    """F_R (B, n_z): R1 = M q̈ − Q_v + J_Φᵀλ − Q_ext (primitive forces F carry J_Φᵀλ and the
    axial and point forces), R2 = c_s(Φ̈ + 2αΦ̇ + β²Φ), R3 = ṗ − h.

    Leading batch axes: Lp, Lr, C, F, Phi (B); mass, J, gravity (3,), lam, pd, h (B or a
    divisor of it, repeated cyclically).
    """
    B, n_b = Lp.shape[0], Lp.shape[2]
    n_q = 7 * n_b
    n_lam = Phi.shape[1]
    n_p = pd.shape[1]
    out = np.zeros((B, n_q + n_lam + n_p), Lp.dtype)
    b2 = beta * beta
    for bb in range(B):
        o = out[bb]
        f, Cb, L, R = F[bb], C[bb], Lp[bb], Lr[bb]
        ms, Js = mass[bb % mass.shape[0]], J[bb % J.shape[0]]
        g = gravity[bb % gravity.shape[0]]
        lm = lam[bb % lam.shape[0]]
        for j in range(pb.shape[0]):                    # generalized primitive forces
            b = pb[j]
            if is_point[j]:
                for a in range(3):
                    o[7 * b + a] += f[j, a]
            for k in range(4):
                s = 0.0
                for a in range(3):
                    s += f[j, a] * Cb[j, a, k, 0]
                o[7 * b + 3 + k] += 2.0 * s
        for b in range(n_b):                            # inertia
            for a in range(3):
                o[7 * b + a] += ms[b] * (R[2, b, a] - g[a])
            Gp = _G(TG, L[0, b])
            Gpd = _G(TG, L[1, b])
            w1 = _mv(Js[b], _mv(Gp, L[2, b]))
            w2 = _mv(Js[b], _mv(Gpd, L[0, b]))
            for k in range(4):
                s = 0.0
                for i in range(3):
                    s += 4.0 * Gp[i, k] * w1[i] - 8.0 * Gpd[i, k] * w2[i]
                o[7 * b + 3 + k] += s
        for e in range(norm_eq.shape[0]):
            b = norm_body[e]
            for k in range(4):
                o[7 * b + 3 + k] += 2.0 * lm[norm_eq[e]] * L[0, b, k]
        ph = Phi[bb]
        for e in range(n_lam):
            o[n_q + e] = scale * (ph[e, 2] + 2.0 * alpha * ph[e, 1] + b2 * ph[e, 0])
        pdb, hb = pd[bb % pd.shape[0]], h[bb % h.shape[0]]
        for i in range(n_p):
            o[n_q + n_lam + i] = pdb[i] - hb[i]
    return out


_spring = jit(spring_law)
_cylinder = jit(cylinder_law)
_rotational = jit(rotational_law)
SPRING, CYLINDER = 0, 1          # AxialElement.law_kind


@jit
def forces_and_residual(Lp: Array, Lr: Array, C: Array, ABV: Array, X: Array, N: Array, pb: Array,
                        is_point: Array, side_ptr: Array, side_prim: Array, side_coef: Array,
                        prod_eq: Array, cf: Array, shift: Array, norm_eq: Array, norm_body: Array,
                        ax_kind: Array, ax_pidx: Array, ax_c: Array, ax_ext: Array, f_ext: Array,
                        mass: Array, J: Array, gravity: Array, lam: Array, p: Array, pd: Array,
                        scale: float, alpha: float, beta: float, TG: Array, rot_prod: Array,
                        rot_c: Array) -> tuple:
    """Constraint levels, force-element laws, primitive forces and F_R for B evaluations (the
    kinematics' batch), one call.

    cf (·, n_cp, 3), shift (·, n_eq, 3): time coefficients (c, ċ, c̈) of the constraint products
    and shifts of the equations; axial element i acts through product n_cp + i with the law
    ax_kind[i] (SPRING, CYLINDER), constants ax_c (·, n_ax, n_c), time input ax_ext (·, n_ax)
    and states from p[ax_pidx[i]]; f_ext (·, n_t, 3): applied point forces on the primitives
    (negative: they enter R1 with −Q_ext); rotational spring-damper i acts through products
    rot_prod[i] (x = u1·u2) and rot_prod[i] + 1 (y = v1·u2) with constants rot_c (·, n_rot, 3)
    = (k, c, θ_0).  A shorter leading axis repeats cyclically (as in :func:`kinematics`).

    Returns F_R (B, n_z), Φ (B, n_eq, 3), weights W (B, n_prod), primitive forces F (B, n_t, 3),
    and the laws: AX (B, n_ax, 5) = (L, L̇, P, ∂P/∂L, ∂P/∂L̇), ∂P/∂p (B, n_ax, n_p),
    h, ∂h/∂L, ∂h/∂L̇ (B, n_p), ∂h/∂p (B, n_p, n_p) and the rotational laws RT (B, n_rot, 13)
    (:func:`.rotational.rotational_law`'s entries).
    """
    B, n_prod, n_t = Lp.shape[0], ABV.shape[2], pb.shape[0]
    n_cp = prod_eq.shape[0]
    n_eq, n_p, n_ax = shift.shape[1], p.shape[1], ax_kind.shape[0]
    Phi = np.empty((B, n_eq, 3), Lp.dtype)
    W = np.zeros((B, n_prod), Lp.dtype)
    F = np.zeros((B, n_t, 3), Lp.dtype)
    AX = np.empty((B, n_ax, 5), Lp.dtype)
    Pp = np.zeros((B, n_ax, n_p), Lp.dtype)
    H = np.zeros((B, n_p), Lp.dtype)
    HL = np.zeros((B, n_p), Lp.dtype)
    HLd = np.zeros((B, n_p), Lp.dtype)
    Hp = np.zeros((B, n_p, n_p), Lp.dtype)
    n_rot = rot_prod.shape[0]
    RT = np.empty((B, n_rot, 13), Lp.dtype)
    for b in range(B):
        cfb, shb = cf[b % cf.shape[0]], shift[b % shift.shape[0]]
        lm, pb_ = lam[b % lam.shape[0]], p[b % p.shape[0]]
        for e in range(n_eq):
            for lev in range(3):
                Phi[b, e, lev] = -shb[e, lev]
        for q_ in range(n_cp):                          # Φ = Σ c x, and its rates
            c, cd, cdd = cfb[q_, 0], cfb[q_, 1], cfb[q_, 2]
            x, xd, xdd = X[b, q_, 0], X[b, q_, 1], X[b, q_, 2]
            e = prod_eq[q_]
            Phi[b, e, 0] += c * x
            Phi[b, e, 1] += cd * x + c * xd
            Phi[b, e, 2] += cdd * x + 2.0 * cd * xd + c * xdd
            W[b, q_] = c * lm[e]
        for i in range(norm_eq.shape[0]):
            for lev in range(3):
                Phi[b, norm_eq[i], lev] += N[b, i, lev]
        cb, eb = ax_c[b % ax_c.shape[0]], ax_ext[b % ax_ext.shape[0]]
        for i in range(n_ax):                           # axial elements: x = d·d, L = √x
            L = np.sqrt(X[b, n_cp + i, 0])
            Ld = X[b, n_cp + i, 1] / (2.0 * L)
            c = cb[i]
            j = ax_pidx[i]
            if ax_kind[i] == SPRING:
                P, P_L, P_Ld = _spring(L, Ld, c[0], c[1], c[2], c[3])
            elif ax_kind[i] != CYLINDER:            # never another element's law (Layout refuses them)
                raise ValueError("axial element of an unknown law kind")
            else:
                P, P_Ld, P_p1, P_p2, h1, h2, h1_L, h2_L, h1_Ld, h2_Ld, h2_p2 = _cylinder(
                    L, Ld, pb_[j], pb_[j + 1], eb[i], c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7],
                    c[8], c[9])
                P_L = 0.0
                Pp[b, i, j], Pp[b, i, j + 1] = P_p1, P_p2
                H[b, j], H[b, j + 1] = h1, h2
                HL[b, j], HL[b, j + 1] = h1_L, h2_L
                HLd[b, j], HLd[b, j + 1] = h1_Ld, h2_Ld
                Hp[b, j + 1, j + 1] = h2_p2
            AX[b, i, 0], AX[b, i, 1], AX[b, i, 2], AX[b, i, 3], AX[b, i, 4] = L, Ld, P, P_L, P_Ld
            W[b, n_cp + i] = -0.5 * P / L
        rc = rot_c[b % rot_c.shape[0]]
        for i in range(n_rot):                          # rotational: x = u1·u2, y = v1·u2
            px = rot_prod[i]
            law = _rotational(X[b, px, 0], X[b, px + 1, 0], X[b, px, 1], X[b, px + 1, 1], rc[i, 0], rc[i, 1],
                              rc[i, 2])
            for k in range(13):
                RT[b, i, k] = law[k]
            W[b, px], W[b, px + 1] = law[3], law[4]
        _prim_forces_one(W[b], ABV[b], side_ptr, side_prim, side_coef, F[b])
        F[b] += f_ext[b % f_ext.shape[0]]
    R = residual(Lp, Lr, C, F, pb, is_point, mass, J, gravity, lam, norm_eq, norm_body, Phi,
                 scale, alpha, beta, pd, H, TG)
    return R, Phi, W, F, AX, Pp, H, HL, HLd, Hp, RT


TG = np.ascontiguousarray(T_G, dtype=float)
