r"""The multibody linearization on a sparsity pattern fixed per model (``linear_algebra: sparse``).

A product x = a·b of the kernel (:mod:`.kernel`) involves the primitives of its two sides, each
on one body; an equation is a sum of products.  So every block of ∂F_R/∂(z, q, q̇, p) lives on
few bodies:

* R1 (the equations of motion): 7×7 *body blocks* (b, b') for every body and for every pair of
  bodies that share a product (a joint's two bodies, an axial element's or a rotational
  spring-damper's two bodies): inertia, geometric stiffness Σ w_p ∂²x_p/∂q², the force
  elements' stiffness and damping;
* R2 (the constraint rows): each equation's row on the 7 columns of each of its bodies (J_Φ,
  ∂R2/∂q, ∂R2/∂q̇); J_Φᵀ in the λ columns of R1;
* R3 (first-order states) and R1_p: the owner element's bodies and the states.

:class:`SparseStructure` works these positions out once per model; the compiled
:func:`block_linearization` computes only the values, in this compact form, with the same
per-element arithmetic as the dense :func:`.compiled_linearization.linearization` (the shared
inline helpers of :mod:`.compiled_linearization`).  :class:`BlockSparseLinearization` hands the
blocks out as CSC matrices and forms the iteration matrix on their kept union pattern, so that
the solver's per-pattern plan (:mod:`dynsens.solver.banded`: ordering and symbolic analysis
once, numeric refresh per step) serves every Newton iteration of the run.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..base import Linearization
from ..sparse_assembly import on_pattern
from . import compiled as cc
from . import compiled_linearization as clin
from .kernel import Layout

Array = np.ndarray

# n_z = n_q + n_λ + n_p from which a multibody model is linearized sparse when the case leaves
# the choice to the size (``linear_algebra: auto``): the measured break-even of the per-step
# cost, dense against sparse, on the N-four-bar (scripts/bench_n_four_bar.py, BENCHMARKS.md)
SPARSE_MIN_NZ = 200


class SparseUnsupported(ValueError):
    """``linear_algebra: sparse`` for a model with elements the sparse path does not cover."""


def use_sparse(n_z: int, other_forces: list[Any], requested: bool | None) -> bool:
    """Whether a model of n_z step unknowns is linearized sparse: as ``requested`` (the case's
    ``linear_algebra``; SparseUnsupported when it cannot be), by size when None."""
    why = sparse_refusal(other_forces)
    if requested and why:
        raise SparseUnsupported(why)
    return (n_z >= SPARSE_MIN_NZ if requested is None else requested) and not why


def element_bodies(el: Any) -> list[int] | None:
    """The moving bodies a force element evaluated outside the kernel acts on (torques,
    body-frame point forces): its ``body`` and the bodies of its
    points and directions; None when it names no body at all (its Jacobian's place is unknown)."""
    bodies: list[int] = []
    named = False
    for key, v in vars(el).items():
        b = v if key == "body" else getattr(v, "body", None)
        if isinstance(b, (int, np.integer)) and not isinstance(b, bool):
            named = True
            if b >= 0 and int(b) not in bodies:       # (the ground, -1, has no coordinates)
                bodies.append(int(b))
    return bodies if named else None


def sparse_refusal(other_forces: list[Any]) -> str:
    """Why the sparse path cannot serve a model ('' when it can): a force element evaluated
    outside the kernel whose bodies are unknown (its Jacobian would have no place in the pattern)."""
    unknown = [el for el in other_forces if element_bodies(el) is None]
    if not unknown:
        return ""
    names = ", ".join(f"'{getattr(el, 'name', type(el).__name__)}'" for el in unknown)
    return (f"the force element(s) {names} act on no known moving body and have no place in the "
            "sparse pattern; use linear_algebra: dense (or auto)")


@cc.inline
def _block_geometric_stiffness(Bq: Array, w: Array, n_prod: int, C: Array, is_point: Array, side_ptr: Array,
                               side_prim: Array, side_coef: Array, side_slot: Array, prod_blk: Array) -> None:
    """Bq += Σ_p w_p ∂²x_p/∂q² on the blocks of each product's bodies."""
    for p in range(n_prod):
        wp = w[p]
        if wp == 0.0:
            continue
        for ea in range(side_ptr[p], side_ptr[p + 1]):
            Ka = clin._prim_jac0(side_prim[ea], C, is_point)
            for eb in range(side_ptr[n_prod + p], side_ptr[n_prod + p + 1]):
                Kb = clin._prim_jac0(side_prim[eb], C, is_point)
                c = wp * side_coef[ea] * side_coef[eb]
                blk = cc._mm(Ka.T, Kb)
                k1 = prod_blk[p, side_slot[ea], side_slot[eb]]
                k2 = prod_blk[p, side_slot[eb], side_slot[ea]]
                for u in range(7):
                    for v in range(7):
                        Bq[k1, u, v] += c * blk[u, v]
                        Bq[k2, v, u] += c * blk[u, v]


@cc.inline
def _block_parameter_curvature(Bq: Array, f: Array, Ts4: Array, pb: Array, body_blk: Array, lam: Array,
                               norm_eq: Array, norm_body: Array) -> None:
    """Bq += ∂²(A s̄)/∂p² · f and the normalisations' 2λ I on the bodies' diagonal blocks."""
    for j in range(pb.shape[0]):
        k0 = body_blk[pb[j]]
        for a in range(3):
            fa = f[j, a]
            if fa != 0.0:
                for k in range(4):
                    for l in range(4):
                        Bq[k0, 3 + k, 3 + l] += 2.0 * fa * Ts4[j, a, k, l]
    for i in range(norm_eq.shape[0]):
        k0 = body_blk[norm_body[i]]
        for k in range(4):
            Bq[k0, 3 + k, 3 + k] += 2.0 * lam[norm_eq[i]]


@cc.inline
def _block_inertia(Bq: Array, Bqd: Array, Bqdd: Array, Lp: Array, body_blk: Array, mass: Array, J: Array,
                   TG: Array) -> None:
    """∂(M q̈ − Q_v)/∂(q, q̇, q̈) on the bodies' diagonal blocks."""
    for b in range(Lp.shape[1]):
        Kpp, Cpp, Mpp = clin.inertia_blocks(Lp, b, J[b], TG)
        k0 = body_blk[b]
        for a in range(3):
            Bqdd[k0, a, a] += mass[b]
        for k in range(4):
            for l in range(4):
                Bq[k0, 3 + k, 3 + l] += Kpp[k, l]
                Bqd[k0, 3 + k, 3 + l] += Cpp[k, l]
                Bqdd[k0, 3 + k, 3 + l] += Mpp[k, l]


@cc.inline
def _block_axial(Bq: Array, Bqd: Array, R1p: Array, dL: Array, dLd: Array, G: Array, prod_nb: Array,
                 prod_blk: Array, ax_prod: Array, ax_law: Array, ax_Pp: Array) -> None:
    """Axial force elements on their product's bodies (as the dense ``_axial``); their ∂L/∂q,
    ∂L̇/∂q on those bodies into dL, dLd."""
    n_p = R1p.shape[2]
    for i in range(ax_prod.shape[0]):
        pp = ax_prod[i]
        jx = G[pp, 0]
        L, Ld, P, P_L, P_Ld = ax_law[i, 0], ax_law[i, 1], ax_law[i, 2], ax_law[i, 3], ax_law[i, 4]
        clin.axial_rates(jx, G[pp, 1], L, Ld, dL[i], dLd[i])
        w_L, w_Ld = clin.axial_weights(L, P, P_L, P_Ld)
        for su in range(prod_nb[pp]):
            for sv in range(prod_nb[pp]):
                kb = prod_blk[pp, su, sv]
                for u in range(7):
                    ju = jx[7 * su + u]
                    if ju != 0.0:
                        for v in range(7):
                            Bq[kb, u, v] += ju * (w_L * dL[i, 7 * sv + v] + w_Ld * dLd[i, 7 * sv + v])
                            Bqd[kb, u, v] += ju * (w_Ld * dL[i, 7 * sv + v])
        for u in range(7 * prod_nb[pp]):
            if jx[u] != 0.0:
                for k in range(n_p):
                    R1p[i, u, k] += -0.5 * ax_Pp[i, k] / L * jx[u]


@cc.inline
def _block_rotational(Bq: Array, Bqd: Array, G: Array, prod_nb: Array, prod_blk: Array, rot_prod: Array,
                      rot_law: Array) -> None:
    """Rotational spring-dampers on the bodies of their products (as the dense ``_rotational``)."""
    for i in range(rot_prod.shape[0]):
        px = rot_prod[i]
        jx, jy = G[px, 0], G[px + 1, 0]
        rx, ry, rxd, ryd = clin.rotational_weight_rows(rot_law[i], jx, jy, G[px, 1], G[px + 1, 1])
        for su in range(prod_nb[px]):
            for sv in range(prod_nb[px]):
                kb = prod_blk[px, su, sv]
                for u in range(7):
                    ju, yu = jx[7 * su + u], jy[7 * su + u]
                    if ju != 0.0 or yu != 0.0:
                        for v in range(7):
                            Bq[kb, u, v] += ju * rx[7 * sv + v] + yu * ry[7 * sv + v]
                            Bqd[kb, u, v] += ju * rxd[7 * sv + v] + yu * ryd[7 * sv + v]


@cc.jit
def block_linearization(Lp: Array, C: Array, ABV: Array, is_point: Array, Ts4: Array, pb: Array,
                        side_ptr: Array, side_prim: Array, side_coef: Array, side_slot: Array,
                        prod_nb: Array, prod_blk: Array, body_blk: Array, n_blk: int, n_cp: int,
                        prod_eq: Array, eq_slot: Array, n_eq_slots: int, cf: Array, eq_w: Array,
                        norm_w: Array, norm_eq: Array, norm_body: Array, w: Array, f: Array, lam: Array,
                        mass: Array, J: Array, TG: Array, ax_prod: Array, ax_law: Array, ax_Pp: Array,
                        p_owner: Array, h_L: Array, h_Ld: Array, rot_prod: Array, rot_law: Array
                        ) -> tuple[Array, Array, Array, Array, Array, Array, Array]:
    """The values of the exact ∂F_R/∂(z, q, q̇, p) in compact form (see :class:`SparseStructure`):

    Jc (3, n_λ, 7·n_eq_slots): rows of J_Φ, ∂R2/∂q/c_s, ∂R2/∂q̇/c_s on the equations' bodies;
    Bq, Bqd, Bqdd (n_blk, 7, 7): the body blocks of ∂R1/∂q, ∂R1/∂q̇, ∂R1/∂q̈;
    R1p (n_ax, 7·PB, n_p): ∂R1/∂p on an axial element's bodies; R3q, R3qd (n_p, 7·PB): ∂R3/∂q,
    ∂R3/∂q̇ on the owner element's bodies.  Arguments as :func:`.compiled_linearization.linearization`, plus
    side_slot (the slot of a side entry's body among its product's bodies), prod_nb (bodies per
    product), prod_blk[p, s, s'] (the block of the product's bodies s, s'), body_blk[b] (the
    diagonal block of body b) and eq_slot[p, s] (the slot of product p's body s in its equation).
    """
    n_lam = lam.shape[0]
    n_p = h_L.shape[0]
    n_prod = ABV.shape[1]
    PB = prod_blk.shape[1]
    dt = Lp.dtype
    # product rows on the products' own bodies (7 columns per slot)
    G = np.zeros((n_prod, 3, 7 * PB), dt)
    side_col = 7 * side_slot
    for p in range(n_prod):
        clin.product_row(G, p, C, ABV, is_point, side_ptr, side_prim, side_coef, side_col)
    # --- constraint rows
    Jc = np.zeros((3, n_lam, 7 * n_eq_slots), dt)
    clin.compact_constraint_rows(Jc, G, Lp, cf, eq_w, norm_w, prod_eq, prod_nb, eq_slot, norm_eq, norm_body, n_cp)
    # --- R1 body blocks: geometric stiffness, ∂²(A s̄)/∂p²·f, normalisations, inertia
    Bq = np.zeros((n_blk, 7, 7), dt)
    Bqd = np.zeros((n_blk, 7, 7), dt)
    Bqdd = np.zeros((n_blk, 7, 7), dt)
    _block_geometric_stiffness(Bq, w, n_prod, C, is_point, side_ptr, side_prim, side_coef, side_slot, prod_blk)
    _block_parameter_curvature(Bq, f, Ts4, pb, body_blk, lam, norm_eq, norm_body)
    _block_inertia(Bq, Bqd, Bqdd, Lp, body_blk, mass, J, TG)
    # --- axial force elements on their product's bodies; rotational spring-dampers on the bodies
    # of their products (both products have the same; SparseStructure checks it)
    n_ax = ax_prod.shape[0]
    R1p = np.zeros((n_ax, 7 * PB, n_p), dt)
    dL = np.zeros((n_ax, 7 * PB), dt)
    dLd = np.zeros((n_ax, 7 * PB), dt)
    _block_axial(Bq, Bqd, R1p, dL, dLd, G, prod_nb, prod_blk, ax_prod, ax_law, ax_Pp)
    _block_rotational(Bq, Bqd, G, prod_nb, prod_blk, rot_prod, rot_law)
    R3q = np.zeros((n_p, 7 * PB), dt)
    R3qd = np.zeros((n_p, 7 * PB), dt)
    clin.pressure_rows(R3q, R3qd, dL, dLd, p_owner, h_L, h_Ld)
    return Jc, Bq, Bqd, Bqdd, R1p, R3q, R3qd


class _CSCGather:
    """CSC matrices (shape) whose stored entries come, in a fixed order, from a flat vector of
    values at given (rows, cols); values at a repeated position are summed (two axial elements
    on the same bodies share their R1_p rows)."""

    def __init__(self, shape: tuple[int, int], rows: Array, cols: Array):
        key = cols.astype(np.int64) * shape[0] + rows
        uniq, self.slot = np.unique(key, return_inverse=True)
        self.order = np.argsort(key, kind="stable") if uniq.size == key.size else None
        self.shape, self.nnz = shape, uniq.size
        self.indices = (uniq % shape[0]).astype(np.int32)
        self.indptr = np.searchsorted(uniq // shape[0], np.arange(shape[1] + 1)).astype(np.int32)

    def matrix(self, values: Array) -> sp.csc_matrix:
        """The matrix with entry k of ``values`` added at (rows[k], cols[k])."""
        if self.order is not None:
            data = values[self.order]
        else:
            data = np.bincount(self.slot, values.real, self.nnz)
            if np.iscomplexobj(values):
                data = data + 1j * np.bincount(self.slot, values.imag, self.nnz)
        return sp.csc_matrix((data, self.indices, self.indptr), shape=self.shape)


class SparseStructure:
    """Where the values of :func:`block_linearization` go in R_z, R_q, R_q̇ and R_p (built once
    per model from the kernel's layout; see the module docstring)."""

    @classmethod
    def of(cls, model: Any) -> "SparseStructure":
        """The structure of a multibody model (its layout, sizes and other force elements)."""
        return cls(model.layout, model.traits.n_lam, model.traits.n_p,
                   [element_bodies(el) or [] for el in model.other_forces])

    def __init__(self, lay: Layout, n_lam: int, n_p: int, groups: list[list[int]] | None = None):
        cl = lay.compiled_arrays()
        n_b, n_prod, n_q = lay.n_b, lay.n_prod, lay.n_q
        self.n_q, self.n_lam, self.n_p = n_q, n_lam, n_p
        n_z = n_q + n_lam + n_p
        ptr, prim = cl.side_ptr, cl.side_prim
        # the bodies of each product (both sides, first seen first) and each side entry's slot
        prod_bodies: list[list[int]] = []
        side_slot = np.zeros(prim.size, np.int64)
        for p in range(n_prod):
            bodies: list[int] = []
            for s_ in range(2):
                for e in range(ptr[s_ * n_prod + p], ptr[s_ * n_prod + p + 1]):
                    b = int(cl.pb[prim[e]])
                    if b not in bodies:
                        bodies.append(b)
                    side_slot[e] = bodies.index(b)
            prod_bodies.append(bodies)
        for px in lay.rot_prod:     # a rotational spring-damper's two products: the same body slots
            assert prod_bodies[px] == prod_bodies[px + 1], "rotational products on different bodies"
        PB = max([1] + [len(b) for b in prod_bodies])
        # body blocks: every body's own block, then every pair sharing a product
        blk: dict[tuple[int, int], int] = {(b, b): b for b in range(n_b)}
        for bodies in prod_bodies + (groups or []):   # (groups: the other force elements' bodies)
            for b1 in bodies:
                for b2 in bodies:
                    blk.setdefault((b1, b2), len(blk))
        prod_blk = np.zeros((n_prod, PB, PB), np.int64)
        for p, bodies in enumerate(prod_bodies):
            for s1, b1 in enumerate(bodies):
                for s2, b2 in enumerate(bodies):
                    prod_blk[p, s1, s2] = blk[(b1, b2)]
        pairs = np.array(sorted(blk, key=blk.__getitem__), np.int64).reshape(-1, 2)
        # the equations' bodies: the union of their products' (a normalisation: its body)
        n_cp = lay.n_cp
        eq_bodies: list[list[int]] = [[] for _ in range(n_lam)]
        for e, b in zip(lay.norm_eq, lay.norm_body):
            eq_bodies[e].append(int(b))
        eq_slot = np.zeros((n_prod, PB), np.int64)
        for p in range(n_cp):
            e = int(cl.prod_eq[p])
            for s, b in enumerate(prod_bodies[p]):
                if b not in eq_bodies[e]:
                    eq_bodies[e].append(b)
                eq_slot[p, s] = eq_bodies[e].index(b)
        EB = max([1] + [len(b) for b in eq_bodies])
        self.args = (side_slot, np.array([len(b) for b in prod_bodies], np.int64), prod_blk,
                     np.arange(n_b, dtype=np.int64), len(blk), n_cp, cl.prod_eq, eq_slot, EB)
        # --- positions of the compact values
        u7 = np.arange(7)
        blk_r = (7 * pairs[:, 0, None, None] + u7[None, :, None]).repeat(7, axis=2).ravel()
        blk_c = (7 * pairs[:, 1, None, None] + u7[None, None, :]).repeat(7, axis=1).ravel()
        self.block_positions = (blk_r.reshape(-1, 7, 7), blk_c.reshape(-1, 7, 7))
        eqb = np.full((n_lam, EB), -1, np.int64)
        for e, bodies in enumerate(eq_bodies):
            eqb[e, :len(bodies)] = bodies
        ok = np.repeat(eqb >= 0, 7, axis=1).ravel()                        # (n_lam·7·EB,)
        self._j_take = np.flatnonzero(ok)
        j_row = np.repeat(np.arange(n_lam), 7 * EB)[ok]
        j_col = (7 * np.repeat(eqb, 7, axis=1) + np.tile(u7, EB)[None, :]).ravel()[ok]
        owner = cl.p_owner
        ax_bodies = np.full((max(len(lay.axial), 1), PB), -1, np.int64)
        for i, pp in enumerate(cl.ax_prod):
            ax_bodies[i, :len(prod_bodies[pp])] = prod_bodies[pp]
        axc = (7 * np.repeat(ax_bodies, 7, axis=1) + np.tile(u7, PB)[None, :])  # (n_ax, 7·PB)
        axok = np.repeat(ax_bodies >= 0, 7, axis=1)
        # R3 rows: the owner element's bodies
        r3_ok = np.zeros((n_p, 7 * PB), bool)
        r3_col = np.zeros((n_p, 7 * PB), np.int64)
        for r in range(n_p):
            if owner[r] >= 0:
                r3_ok[r], r3_col[r] = axok[owner[r]], axc[owner[r]]
        self._r3_take = np.flatnonzero(r3_ok.ravel())
        r3_row = n_q + n_lam + np.repeat(np.arange(n_p), 7 * PB)[self._r3_take]
        r3_col_f = r3_col.ravel()[self._r3_take]
        # R1_p: the axial elements' bodies × every state
        n_ax = len(lay.axial)
        r1p_ok = np.repeat(axok[:n_ax, :, None], n_p, axis=2)
        self._r1p_take = np.flatnonzero(r1p_ok.ravel())
        r1p_row = np.repeat(axc[:n_ax, :, None], n_p, axis=2).ravel()[self._r1p_take]
        r1p_col = np.broadcast_to(np.arange(n_p), r1p_ok.shape).ravel()[self._r1p_take]
        hp_row = n_q + n_lam + np.repeat(np.arange(n_p), n_p)
        hp_col = np.tile(np.arange(n_p), n_p)
        pid = n_q + n_lam + np.arange(n_p)
        # the four matrices, each from its list of compact sources (concatenated in this order)
        self.R_z = _CSCGather((n_z, n_z), np.concatenate([blk_r, j_col, n_q + j_row, pid]),
                              np.concatenate([blk_c, n_q + j_row, j_col, pid]))
        self.R_q = _CSCGather((n_z, n_q), np.concatenate([blk_r, n_q + j_row, r3_row]),
                              np.concatenate([blk_c, j_col, r3_col_f]))
        self.R_qd = self.R_q
        self.J = _CSCGather((n_lam, n_q), j_row, j_col)       # J_Φ alone (the projection's)
        self.R_p = _CSCGather((n_z, n_p), np.concatenate([r1p_row, hp_row]), np.concatenate([r1p_col, hp_col]))
        self._union: Any = None
        self._ones = np.ones(n_p)

    def linearization(self, blocks: tuple[Array, ...], h_p: Array, scale: float) -> "BlockSparseLinearization":
        """The CSC linearization from the compact values of :func:`block_linearization`."""
        Jc, Bq, Bqd, Bqdd, R1p, R3q, R3qd = blocks
        J = [Jc[o].ravel()[self._j_take] for o in range(3)]
        r3q, r3qd = R3q.ravel()[self._r3_take], R3qd.ravel()[self._r3_take]
        dt = Jc.dtype
        R_z = self.R_z.matrix(np.concatenate([Bqdd.ravel(), J[0], scale * J[0], self._ones.astype(dt)]))
        R_q = self.R_q.matrix(np.concatenate([Bq.ravel(), scale * J[1], r3q]))
        R_qd = self.R_qd.matrix(np.concatenate([Bqd.ravel(), scale * J[2], r3qd]))
        R_p = self.R_p.matrix(np.concatenate([R1p.ravel()[self._r1p_take], -h_p.ravel()])) if self.n_p else None
        return BlockSparseLinearization(R_z, R_q, R_qd, R_p, structure=self)

    def constraint_jacobians(self, Jc: Array) -> list[sp.csc_matrix]:
        """J_Φ (n_λ, n_q) as CSC of each entry of the compact rows Jc (B, n_λ, 7·EB)."""
        return [self.J.matrix(Jc[b].ravel()[self._j_take]) for b in range(Jc.shape[0])]

    def from_dense(self, lin: Linearization) -> "BlockSparseLinearization":
        """A dense linearization's entries at the pattern's positions (the numpy kernel's path)."""
        def at(A: Array | None, g: _CSCGather) -> sp.csc_matrix | None:
            if A is None:
                return None
            A = np.asarray(A)
            cols = np.repeat(np.arange(g.shape[1]), np.diff(g.indptr))
            return sp.csc_matrix((A[g.indices, cols], g.indices, g.indptr), shape=g.shape)
        return BlockSparseLinearization(at(lin.R_z, self.R_z), at(lin.R_q, self.R_q), at(lin.R_qd, self.R_qd),
                                        at(lin.R_p, self.R_p) if self.n_p else None, structure=self)

    def union(self, mats: list[sp.csc_matrix]) -> Any:
        """The kept union pattern of the iteration matrix's terms (see :class:`UnionCache`)."""
        from ..sparse_assembly import UnionCache
        if self._union is None:
            self._union = UnionCache()
        return self._union.get(mats)


@dataclass(frozen=True)
class BlockSparseLinearization(Linearization):
    """CSC blocks of a multibody linearization; the iteration matrix is summed on the kept union
    pattern of R_z, R_q, R_q̇ and R_p (explicit zeros stay: the pattern is the same every time)."""

    structure: SparseStructure | None = None

    def iteration_matrix(self, c_q: float, c_qd: float, c_p: float, n_q: int) -> Any:
        """S = R_z + [c_q R_q + c_q̇ R_q̇, 0, c_p R_p] (method.md §3) as CSC."""
        R_q, R_qd, R_p = self.R_q, self.R_qd, self.R_p
        assert self.structure is not None and R_q is not None and R_qd is not None
        n_z = self.R_z.shape[0]
        n_p = 0 if R_p is None else R_p.shape[1]
        mats = [self.R_z, _embed(R_q, n_z, 0), _embed(R_qd, n_z, 0)]
        if R_p is not None and n_p:
            mats.append(_embed(R_p, n_z, n_z - n_p))
        u = self.structure.union(mats)
        dtype = np.result_type(*(m.dtype for m in mats), float)
        S = u.place(self.R_z.data, 0, dtype)
        coupled = np.zeros(u.nnz, dtype)
        coupled[u.positions(1)] = c_q * R_q.data
        coupled[u.positions(2)] += c_qd * R_qd.data
        if R_p is not None and n_p:
            coupled[u.positions(3)] += c_p * R_p.data
        return on_pattern(u.pattern, S + coupled)


def _embed(A: sp.csc_matrix, n: int, col0: int) -> sp.csc_matrix:
    """A (n, k) CSC as columns col0 … col0 + k of an (n, n) CSC matrix (same data, no copy)."""
    indptr = np.concatenate([np.zeros(col0, A.indptr.dtype), A.indptr,
                             np.full(n - col0 - A.shape[1], A.indptr[-1], A.indptr.dtype)])
    return sp.csc_matrix((A.data, A.indices, indptr), shape=(n, n))


def sparse_linearization(model: Any, ev: Any) -> BlockSparseLinearization:
    """The linearization of the evaluation ``ev`` (:class:`.residual.Evaluation`, first batch
    entry) on the model's kept pattern: by :func:`block_linearization` on the compiled path;
    otherwise (the numpy kernel, the reference) the dense linearization's entries at the
    pattern's positions."""
    st: SparseStructure = model.sparse_structure()
    if not ev.compiled:
        return st.from_dense(ev.linearization())
    lay, kin = model.layout, ev.kin
    cl, ck = kin.arrays, kin.params
    Jc, Bq, Bqd, Bqdd, R1p, R3q, R3qd = block_linearization(
        kin.Lp[0], kin.C[0], kin.ABV[0], cl.is_point, ck.Ts4[0], cl.pb, cl.side_ptr, cl.side_prim,
        cl.side_coef, *st.args, np.ascontiguousarray(ev.cf[0], kin.dtype), model.eq_row_weights,
        model.norm_row_weights, cl.norm_eq, cl.norm_body, ev.w[0], ev.f[0],
        np.asarray(ev.lam[0], kin.dtype), ck.mass[0], ck.J[0], cc.TG, cl.ax_prod, ev._ax[0], ev._Pp[0],
        cl.p_owner, ev._hL[0], ev._hLd[0], cl.rot_prod, ev._rot[0])
    assert lay.n_cp == st.args[5]
    if model.other_forces:            # torques, body-frame forces
        from .residual import other_forces_jacobians
        Kq, Kqd = other_forces_jacobians(model, ev.t, kin.q[0], kin.qd[0], kin.kp.prms[0])
        rows, cols = st.block_positions
        Bq -= Kq[rows, cols]
        Bqd -= Kqd[rows, cols]
    return st.linearization((Jc, Bq, Bqd, Bqdd, R1p, R3q, R3qd), ev._hp[0], float(model.scale))
