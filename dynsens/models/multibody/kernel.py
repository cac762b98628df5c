r"""Vectorized kinematics of all vector terms, dot products and normalisations (the hot path).

The building blocks of :mod:`.bodies` and :mod:`.joints` define the model term by term;
this module evaluates all of them at once for a state, with few numpy calls:

* *primitives*: the distinct points and body-fixed directions on moving bodies.  With
  ``Ts`` the point tensor of the body vector s̄ (:func:`.rotations.point_tensor`) and
  ``C(a) = Ts·a`` (3×4, linear in a), a primitive's value, velocity and acceleration are
  ``C(p)p (+ r)``, ``2C(p)ṗ (+ ṙ)`` and ``2C(p)p̈ + 2C(ṗ)ṗ (+ r̈)``; their Jacobians with
  respect to p are ``2C(p)``, ``2C(ṗ)``, ``2C(p̈)`` (exact: A(p)s̄ is quadratic in p);
* *sides*: every vector term (a point separation, a constant...) is a fixed linear
  combination ``M`` of primitives plus a design-dependent constant;
* *products* ``x = a·b`` of two sides, with ẋ, ẍ and the rows ∂x/∂q, ∂ẋ/∂q, ∂ẍ/∂q (the
  constraint equations' terms first, then one ``d·d`` per axial force element, then two per
  rotational spring-damper, ``u_1·u_2`` and ``v_1·u_2`` (:mod:`.rotational`)).

Arrays carry a leading batch axis B: states (B or 1) and parameter sets (B or 1)
broadcast, so perturbed designs (design partials, output gradients) take one call.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from . import compiled as cc
from .bodies import GROUND, Const, Diff, Direction, MBParams, Point, Term
from .joints import ONE, DotEq, Equation, NormEq
from .rotations import matmul_real, point_tensor, rmatmul

if TYPE_CHECKING:  # pragma: no cover
    from .kernel_compiled import CompiledParams

Array = np.ndarray

# ROW_LEVELS[T, l, m]: x, ẋ, ẍ (T = 0, 1, 2) of a product from its sides' levels l, m
# (x = a·b, ẋ = ȧ·b + a·ḃ, ẍ = ä·b + 2ȧ·ḃ + a·b̈)
ROW_LEVELS = np.zeros((3, 3, 3))
ROW_LEVELS[0, 0, 0] = 1.0
ROW_LEVELS[1, 0, 1] = ROW_LEVELS[1, 1, 0] = 1.0
ROW_LEVELS[2, 0, 2] = ROW_LEVELS[2, 2, 0] = 1.0
ROW_LEVELS[2, 1, 1] = 2.0


_LEVEL_FACTORS = np.array([1.0, 2.0, 2.0])
_ROW_LEVELS_9 = np.ascontiguousarray(ROW_LEVELS.reshape(3, 9).T)
_ROW_LEVELS_LTM = np.ascontiguousarray(ROW_LEVELS.transpose(1, 0, 2).reshape(3, 9))   # [l, (T, m)]


def _levels(V: Array) -> Array:
    """(x, ẋ, ẍ) (..., 3) of products x = a·b from the level dot products V[..., l, m] = a_l·b_m."""
    return matmul_real(V.reshape(V.shape[:-2] + (9,)), _ROW_LEVELS_9)


class Layout:
    """Index structure of the model's terms, built once per model.

    Parameters
    ----------
    n_bodies : number of moving bodies.
    eqs : the model's equations (:class:`DotEq` and :class:`NormEq`), in λ order.
    axial : the axial force elements (springs, cylinders; each with a point separation ``d``).
    points : points at which point forces act.
    rotational : the rotational spring-dampers (:class:`.rotational.RotationalSpringDamper`).
    """

    def __init__(self, n_bodies: int, eqs: list[Equation], axial: list[Any], points: list[Point],
                 rotational: list[Any] | None = None):
        self.n_b, self.n_q, self.n_eq = n_bodies, 7 * n_bodies, len(eqs)
        self.prims: list[Term] = []
        self._pid: dict[tuple[Any, ...], int] = {}
        sides: list[tuple[dict[int, float], list[tuple[str, float]]]] = []
        self.coefs: list[tuple[int, Any]] = []           # (product, coefficient) when not ONE
        self.shifts: list[tuple[int, Any]] = []          # (equation, shift)
        prod_eq: list[int] = []
        norm_eq: list[int] = []
        norm_body: list[int] = []
        for e, eq in enumerate(eqs):
            if isinstance(eq, NormEq):
                norm_eq.append(e)
                norm_body.append(eq.body)
            elif isinstance(eq, DotEq):
                for coef, a, b in eq.terms:
                    if coef is not ONE:
                        self.coefs.append((len(prod_eq), coef))
                    prod_eq.append(e)
                    sides += [self._side(a), self._side(b)]
                if eq.shift is not None:
                    self.shifts.append((e, eq.shift))
            else:  # pragma: no cover - all equations are DotEq or NormEq
                raise TypeError(f"unsupported equation {type(eq).__name__}")
        self.n_cp = len(prod_eq)
        self.axial = axial
        # every axial law known to the compiled kernel (otherwise the numpy kernel evaluates forces)
        self.compiled_laws = all(getattr(el, "law_kind", None) is not None for el in axial)
        unknown = [el for el in axial if getattr(el, "law_kind", None) not in (None, cc.SPRING, cc.CYLINDER)]
        if unknown:     # a law the compiled kernel would not know: refuse, never evaluate another law
            raise TypeError(f"axial element '{unknown[0].name}' declares law_kind "
                            f"{unknown[0].law_kind!r}; the compiled kernel knows {cc.SPRING} (spring) "
                            f"and {cc.CYLINDER} (cylinder), None selects the numpy kernel")
        for el in axial:
            sides += [self._side(el.d), self._side(el.d)]
        self.rotational = rotational or []
        # rotational spring-damper i: products rot_prod[i] (x = u1·u2) and rot_prod[i] + 1 (y = v1·u2)
        self.rot_prod = self.n_cp + len(axial) + 2 * np.arange(len(self.rotational), dtype=np.int64)
        for el in self.rotational:
            sides += [self._side(el.u1), self._side(el.u2), self._side(el.v1), self._side(el.u2)]
        point_sides = [self._side(P)[0] for P in points]
        self.point_prim = [next(iter(m)) if m else -1 for m in point_sides]
        n_t, n_p = len(self.prims), len(sides) // 2
        self.n_t, self.n_prod = n_t, n_p
        self.MAB = np.zeros((2 * n_p, n_t))                # [MA; MB]: sides from primitives
        self.MA, self.MB = self.MAB[:n_p], self.MAB[n_p:]
        for i, (lin, _) in enumerate(sides):
            M = self.MA if i % 2 == 0 else self.MB
            for j, c in lin.items():
                M[i // 2, j] += c
        self.const_keys = [(i // 2, i % 2, key, sg) for i, (_, cs) in enumerate(sides) for key, sg in cs]
        self.S = np.zeros((self.n_eq, self.n_cp))
        self.S[prod_eq, np.arange(self.n_cp)] = 1.0
        self.norm_eq, self.norm_body = np.array(norm_eq, int), np.array(norm_body, int)
        # the normalisations' rows as a slice where they are consecutive (the usual case: cheaper
        # to add to than by an index array, the same sums)
        consecutive = len(norm_eq) > 0 and norm_eq == list(range(norm_eq[0], norm_eq[0] + len(norm_eq)))
        self.norm_rows: Any = slice(norm_eq[0], norm_eq[0] + len(norm_eq)) if consecutive else self.norm_eq
        self.pb = np.array([t.body for t in self.prims], np.int_)          # type: ignore[attr-defined]
        self.is_point = np.array([isinstance(t, Point) for t in self.prims], float)
        self.point_idx = np.flatnonzero(self.is_point)
        self.point_body = self.pb[self.point_idx]
        self._scatter()

    def _side(self, term: Term) -> tuple[dict[int, float], list[tuple[str, float]]]:
        """term = Σ_j lin[j] prim_j + Σ sign·vec[key]."""
        lin: dict[int, float] = {}
        const: list[tuple[str, float]] = []

        def walk(t: Term, sign: float) -> None:
            if isinstance(t, Diff):
                walk(t.a, sign)
                walk(t.b, -sign)
            elif isinstance(t, (Point, Direction)) and t.body != GROUND:
                key = (type(t).__name__, t.body, t.key)
                if key not in self._pid:
                    self._pid[key] = len(self.prims)
                    self.prims.append(t)
                j = self._pid[key]
                lin[j] = lin.get(j, 0.0) + sign
            elif isinstance(t, (Point, Direction, Const)):
                const.append((t.key, sign))
            else:  # pragma: no cover
                raise TypeError(f"unsupported term {type(t).__name__}")
        walk(term, 1.0)
        return lin, const

    def _scatter(self) -> None:
        """Index arrays placing primitive blocks into (n_q,)-long rows."""
        n_q, n_t = self.n_q, self.n_t
        pcol = 7 * self.pb[:, None] + 3 + np.arange(4)[None, :]             # (n_t, 4)
        rcol = 7 * self.pb[:, None] + np.arange(3)[None, :]                 # (n_t, 3)
        # generalized force of primitive forces f (n_t, 3): R1 += Gf @ [f·is_point, 2C(p)ᵀf]
        self.Gf = np.zeros((n_q, n_t * 7))
        for j in range(n_t):
            if self.is_point[j]:
                self.Gf[rcol[j], 7 * j + np.arange(3)] = 1.0
            self.Gf[pcol[j], 7 * j + 3 + np.arange(4)] = 1.0
        # Jacobian rows K (n_t, 3 levels, 3, n_q): identity on r (points, level 0) and
        # the flat positions of the p-blocks
        base = np.zeros((n_t, 3, 3, n_q))
        for j in range(n_t):
            if self.is_point[j]:
                base[j, 0, np.arange(3), rcol[j]] = 1.0
        self.K_base = base
        jj, lev, a, k = np.meshgrid(np.arange(n_t), np.arange(3), np.arange(3), np.arange(4), indexing="ij")
        self.K_idx = np.ravel_multi_index((jj, lev, a, pcol[jj, k]), base.shape) if n_t else \
            np.zeros((0, 3, 3, 4), int)
        self.H_idx = (np.broadcast_to(pcol[:, :, None], (n_t, 4, 4)),
                      np.broadcast_to(pcol[:, None, :], (n_t, 4, 4)))
        bcol = 7 * self.norm_body[:, None] + 3 + np.arange(4)[None, :]       # (n_norm, 4)
        # per-body blocks of (n_q, n_q) matrices: the r diagonals and the (4, 4) p-blocks
        rdiag = (7 * np.arange(self.n_b)[:, None] + np.arange(3)).reshape(-1)
        self.r_diag = (rdiag, rdiag)
        pblk = 7 * np.arange(self.n_b)[:, None] + 3 + np.arange(4)                # (n_b, 4)
        self.p_blocks = (np.broadcast_to(pblk[:, :, None], (self.n_b, 4, 4)),
                         np.broadcast_to(pblk[:, None, :], (self.n_b, 4, 4)))
        self.norm_cols = bcol
        self._compiled: CompiledArrays | None = None

    def compiled_arrays(self) -> "CompiledArrays":
        """The index structure for :mod:`.compiled` (built on first use)."""
        if self._compiled is None:
            ptr, prim, coef = [0], [], []
            for row in self.MAB:
                nz = np.flatnonzero(row)
                prim += nz.tolist()
                coef += row[nz].tolist()
                ptr.append(len(prim))
            n_p = sum(el.n_pressures for el in self.axial)
            p_owner = np.full(n_p, -1, np.int64)
            for i, el in enumerate(self.axial):
                p_owner[el.p_index:el.p_index + el.n_pressures] = i
            self._compiled = CompiledArrays(
                self.pb.astype(np.int64), self.is_point.astype(bool), np.array(ptr, np.int64),
                np.array(prim, np.int64), np.array(coef, float), self.norm_eq.astype(np.int64),
                self.norm_body.astype(np.int64),
                np.argmax(self.S, axis=0).astype(np.int64) if self.n_cp else np.zeros(0, np.int64),
                np.array([-1 if el.law_kind is None else el.law_kind for el in self.axial], np.int64),
                np.array([el.p_index for el in self.axial], np.int64),
                np.arange(self.n_cp, self.n_cp + len(self.axial), dtype=np.int64), p_owner,
                self.rot_prod)
        return self._compiled


@dataclass
class KParamsCache:
    """What is derived from one :class:`KParams` and kept with it (the only state kept on
    kernel parameters).  The parameter sets never change, so entries that depend on them
    alone are never dropped; those that depend on time name their key.

    coefficients : ``(t, (cf, shift))``, the constraint coefficients and shifts at the last
        time t (s) asked for (:meth:`.model.MultibodyModel.coefficients`); replaced when
        another t is asked for (Newton evaluates all iterates of a step at one time).
    inputs : per dtype char, ``(t, settled, (ext, f_ext, g))``, the time inputs at the last t
        (:func:`.residual.time_inputs`); replaced at another t unless both are past
        ``settled``, the time after which the inputs no longer change.
    steady_inputs : per dtype char, what does not depend on t (:func:`.residual._steady`):
        gravity, constant point forces, the list of point forces, the settling time.
    compiled : per dtype char, the sets in the compiled kernel's form
        (:func:`.kernel_compiled.compiled_params`).
    """

    coefficients: tuple[float, tuple[Array, Array]] | None = None
    inputs: dict[str, tuple[float, float, tuple[Array, Array, Array]]] = field(default_factory=dict)
    steady_inputs: dict[str, tuple[Array, Array | None, list[Any], float]] = field(default_factory=dict)
    compiled: dict[str, "CompiledParams"] = field(default_factory=dict)


@dataclass
class KParams:
    """Design-dependent arrays of the kernel for B parameter sets (leading axis B); ``cache``:
    what is derived from them (:class:`KParamsCache`)."""

    Ts: Array              # (B, n_t, 12, 4) point tensors, rows (a, k)
    Ts4: Array             # (B, n_t, 3, 4, 4) the same
    cA: Array              # (B, n_prod, 3) constant parts of the sides
    cB: Array
    mass: Array            # (B, n_b)
    J: Array               # (B, n_b, 3, 3) inertia tensors, body axes
    pv: Array              # (B, n_pv)
    ec: list[Array]        # per axial element: its constants (B, n_c)
    prms: list[MBParams]
    rc: Array              # (B, n_rot, 3) the rotational spring-dampers' k, c, θ_0
    cache: KParamsCache = field(default_factory=KParamsCache, init=False, repr=False, compare=False)

    @property
    def B(self) -> int:
        return self.pv.shape[0]


def kernel_params(lay: Layout, prm: MBParams) -> KParams:
    """KParams (B = 1) of one parameter set for the layout ``lay``, kept in ``prm.cache``."""
    hit = prm.cache.kernels.get(lay)
    if hit is not None:
        return hit
    dt = np.result_type(prm.pv, float)
    Ts4 = np.array([point_tensor(prm.vec[t.key]) for t in lay.prims], dt).reshape(lay.n_t, 3, 4, 4)  # type: ignore[attr-defined]
    c = np.zeros((2, lay.n_prod, 3), dt)
    for p, side, key, sg in lay.const_keys:
        c[side, p] += sg * np.asarray(prm.vec[key]).reshape(3)
    bs = prm.bodies
    kp = KParams(Ts4.reshape(1, lay.n_t, 12, 4), Ts4[None], c[0][None], c[1][None],
                 np.array([b.mass for b in bs], dt)[None], np.array([b.inertia for b in bs], dt)[None],
                 np.asarray(prm.pv)[None], [np.asarray(el.constants(prm))[None] for el in lay.axial],
                 [prm], np.array([el.constants(prm.pv) for el in lay.rotational], dt).reshape(1, -1, 3))
    prm.cache.kernels[lay] = kp
    return kp


def stack_kernel_params(kps: list[KParams]) -> KParams:
    """Concatenate parameter sets along the batch axis."""
    def cat(name: str) -> Array:
        return np.concatenate([getattr(k, name) for k in kps])
    ec = [np.concatenate([k.ec[i] for k in kps]) for i in range(len(kps[0].ec))]
    return KParams(cat("Ts"), cat("Ts4"), cat("cA"), cat("cB"), cat("mass"), cat("J"), cat("pv"),
                   ec, [p for k in kps for p in k.prms], cat("rc"))


class Kin:
    """Kinematics of all primitives and products at states q, q̇, q̈ (each (Bs, n_q))."""

    def __init__(self, lay: Layout, kp: KParams, q: Array, qd: Array, qdd: Array):
        self.lay, self.kp = lay, kp
        Bs, n_t = q.shape[0], lay.n_t
        self.q, self.qd = q, qd
        Qs = np.concatenate((q, qd, qdd), axis=1).reshape(Bs, 3, lay.n_b, 7)
        self.Lp = Qs[..., 3:]                                        # (Bs, 3, n_b, 4)
        self.Lr = Qs[..., :3]                                        # (Bs, 3, n_b, 3)
        Lg = self.Lp[:, :, lay.pb]                                   # (Bs, 3, n_t, 4)
        LgT = Lg.transpose(0, 2, 3, 1)                               # (Bs, n_t, 4, 3)
        C = (kp.Ts @ LgT).reshape(max(Bs, kp.B), n_t, 3, 4, 3)                  # C_i[a, k] (B, n_t, a, k, i)
        self.C = C
        # levels of A(p)s̄ = C(p)p: value C(p)p, rate 2C(p)ṗ, acceleration 2C(p)p̈ + 2C(ṗ)ṗ
        X = C[..., 0] @ LgT                                          # C(p) [p, ṗ, p̈] (B, n_t, a, level)
        X[..., 2] += (C[..., 1] @ Lg[:, 1, :, :, None])[..., 0]      # + C(ṗ) ṗ
        X *= _LEVEL_FACTORS
        PV = X.swapaxes(-1, -2)                                      # (B, n_t, level, a)
        if lay.point_idx.size:                                       # + r, ṙ, r̈ of point primitives
            PV[:, lay.point_idx] += Qs[:, :, lay.point_body, :3].transpose(0, 2, 1, 3)
        self.PV = PV
        B = PV.shape[0]
        flat = PV.reshape(B, n_t, 9)
        self.ABV = rmatmul(lay.MAB, flat).reshape(B, 2, lay.n_prod, 3, 3)   # both sides, one matmul
        self.AV, self.BV = self.ABV[:, 0], self.ABV[:, 1]
        self.AV[:, :, 0] += kp.cA
        self.BV[:, :, 0] += kp.cB
        Vd = self.AV @ self.BV.transpose(0, 1, 3, 2)                 # A_l·B_m
        self.X = _levels(Vd)
        Pn = self.Lp[:, :, lay.norm_body].transpose(0, 2, 1, 3)      # (Bs, n_norm, level, 4)
        self.N = _levels(Pn @ Pn.swapaxes(-1, -2))                   # p·p and its rates
        self._rows: tuple[Array, ...] | None = None

    def prim_forces(self, w: Array) -> Array:
        """f (B, n_t, 3) on the primitives from weights w (B, n_prod) of the products:
        Σ_p w_p ∂x_p/∂(primitive values)."""
        # side a is pulled by w·b and side b by w·a: swap the sides, one matmul with [MA; MB]ᵀ
        fab = w[:, None, :, None] * self.ABV[:, ::-1, :, 0]
        return rmatmul(self.lay.MAB.T, fab.reshape(fab.shape[0], -1, 3))

    def generalized(self, f: Array) -> Array:
        """(B, n_q) Σ_j (∂prim_j/∂q)ᵀ f_j for primitive forces f (B, n_t, 3)."""
        Cp = self.C[..., 0]                                          # (B, n_t, 3, 4)
        g = 2.0 * (f[..., None, :] @ Cp)[..., 0, :]                  # (B, n_t, 4)
        B = max(f.shape[0], g.shape[0])
        v = np.concatenate([np.broadcast_to(f * self.lay.is_point[:, None], (B,) + f.shape[1:]),
                            np.broadcast_to(g, (B,) + g.shape[1:])], axis=-1).reshape(B, -1)
        return rmatmul(self.lay.Gf, v.T).T

    def rows(self) -> tuple[Array, Array, Array, Array, Array]:
        """(Jx, Dx, Ax, AK0, BK0) of the first batch entry: ∂x/∂q, ∂ẋ/∂q, ∂ẍ/∂q (n_prod, n_q)
        (also ∂ẋ/∂q̇ = Jx, ∂ẍ/∂q̇ = 2Dx, ∂ẍ/∂q̈ = Jx), and the sides' value Jacobians
        ∂a/∂q, ∂b/∂q (n_prod, 3, n_q)."""
        if self._rows is None:
            lay = self.lay
            K = lay.K_base.astype(np.result_type(lay.K_base, self.C))
            K.reshape(-1)[lay.K_idx] = 2.0 * self.C[0].transpose(0, 3, 1, 2)
            # both sides at once: ABK[s, p, m, a, n] = ∂(side s)_a at level m / ∂q_n
            ABK = rmatmul(lay.MAB, K.reshape(lay.n_t, 9 * lay.n_q)).reshape(2, lay.n_prod, 3, 3, lay.n_q)
            # x-level T of product p = Σ CT[T, l, m] (b_l·∂a_m + a_l·∂b_m): one batched matmul
            # over p instead of two (n_prod, 3, 3, n_q) einsums
            Vo = self.ABV[0, ::-1].transpose(1, 0, 3, 2)             # (p, s, a, l): sides swapped
            E = matmul_real(Vo, _ROW_LEVELS_LTM).reshape(lay.n_prod, 2, 3, 3, 3).transpose(0, 3, 1, 4, 2)
            E = E.reshape(lay.n_prod, 3, 18)                         # (p, T, (s, m, a))
            G = E @ ABK.transpose(1, 0, 2, 3, 4).reshape(lay.n_prod, 18, lay.n_q)
            self.xrows = G                                           # (n_prod, 3, n_q)
            self._rows = (G[:, 0], G[:, 1], G[:, 2], ABK[0, :, 0], ABK[1, :, 0])
        return self._rows  # type: ignore[return-value]

    def hessian(self, w: Array, f: Array) -> Array:
        """Σ_p w_p ∂²x_p/∂q² (n_q, n_q) for weights w (n_prod,), given f = prim_forces(w)
        (plus any constant primitive forces, whose second derivatives are included too)."""
        lay = self.lay
        _, _, _, AK0, BK0 = self.rows()
        n_q = lay.n_q
        X = (AK0 * w[:, None, None]).reshape(-1, n_q).T @ BK0.reshape(-1, n_q)
        H = X + X.T
        Hj = 2.0 * np.einsum("ja,jakl->jkl", f, self.kp.Ts4[0])
        np.add.at(H, lay.H_idx, Hj)
        return H


@dataclass
class CompiledArrays:
    """The layout's index structure in the form of the compiled kernel (built once per model)."""

    pb: Array            # (n_t,) body of each primitive
    is_point: Array      # (n_t,) bool
    side_ptr: Array      # (2 n_prod + 1,) CSR rows s·n_prod + p of [MA; MB]
    side_prim: Array
    side_coef: Array
    norm_eq: Array
    norm_body: Array
    prod_eq: Array       # (n_cp,) equation of each constraint product
    ax_kind: Array       # (n_ax,) law of each axial element (AxialElement.law_kind; -1: none)
    ax_pidx: Array       # (n_ax,) position of its first state in p
    ax_prod: Array       # (n_ax,) its product d·d
    p_owner: Array       # (n_p,) the element each state belongs to
    rot_prod: Array      # (n_rot,) the product u1·u2 of each rotational spring-damper (v1·u2: the next)
