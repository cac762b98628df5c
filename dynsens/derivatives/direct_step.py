r"""One step of direct differentiation (method.md §4), defined once for every backend.

:func:`direct_step` is the step: predict the sensitivity matrices with the scheme, form the
pseudo load P (the explicit design part plus R_q ∇q^pred + R_q̇ ∇q̇^pred + R_p ∇p^pred), solve
S ∇z = −P with the step's factor, correct, and move the scheme's algorithmic accelerations on.
Like Newton's iteration (:mod:`dynsens.solver.newton_core`), it reaches the scheme and the
linear algebra only through operations (``sens_*``):

* run as Python, they are the methods of :class:`PythonDirectStep` (any scheme, model, matrix
  kind, real or complex, with the derivative of a projection);
* compiled, they are numba overloads for :class:`DenseBlock`, the records of a block of steps
  of plain Newmark with dense real linearizations and LU factors (the compiled mechanisms'),
  or for :class:`BandBlock`, sparse records whose factor is a tridiagonal band (chains), and
  :func:`direct_block` takes the whole block without returning to the interpreter.  The dense
  block's products are BLAS gemm and its solve LAPACK getrs, as in the Python path, so the
  numbers are the same where numba's BLAS is numpy's build; the band block's products are
  scipy's CSC sums (:mod:`dynsens.solver.sparse_products`) and its solve dgttrs's arithmetic
  (:func:`dynsens.solver.tridiagonal.gttrs_columns`), the same numbers everywhere.
"""
from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sp

from ..integrators.newmark import (Newmark, advance_arrays, correct_arrays, corrector_coefficients,
                                   predict_arrays)
from ..models.base import StepState
from .partials import pseudo_load_with
from ..solver._jit import HAVE_NUMBA, enabled, inline, jit, register_jitable
from ..solver.linalg import Factor
from ..solver.tridiagonal import gttrs_columns, gttrs_transposed_columns
from ..timeloop.stepping import StepRecord, split_unknowns


# ----------------------------------------------------------------------------- step operations
# Each is the method of the same name of a Python step object (``rec``: what the object needs
# of the step); the compiled block overloads them, so these bodies run in Python only.

def sens_predict(ops: Any, rec: Any, ds: Any, daux: Any) -> Any:
    """The predicted sensitivities of the step from ∇s and the scheme's ∇a, ∇b."""
    return ops.predict(rec, ds, daux)


def sens_pseudo_load(ops: Any, rec: Any, design_part: np.ndarray, dpred: Any) -> np.ndarray:
    """P (n_z, m): the explicit design part plus the state part at the predicted sensitivities."""
    return ops.pseudo_load(rec, design_part, dpred)


def sens_solve(ops: Any, rec: Any, P: np.ndarray) -> np.ndarray:
    """∇z (n_z, m) from S ∇z = −P with the step's factor."""
    return ops.solve(rec, P)


def sens_correct(ops: Any, rec: Any, dpred: Any, dz: np.ndarray) -> Any:
    """∇s of the step from the prediction and ∇z (the scheme's corrector)."""
    return ops.correct(rec, dpred, dz)


def sens_advance(ops: Any, rec: Any, dpred: Any, ds: Any) -> Any:
    """The scheme's ∇a, ∇b after the step."""
    return ops.advance(rec, dpred, ds)


@register_jitable
def direct_step(ops: Any, rec: Any, ds: Any, daux: Any, design_part: np.ndarray) -> tuple[Any, Any]:
    """One sensitivity step (method.md §4): (∇s, ∇aux) after the step ``rec``."""
    dpred = sens_predict(ops, rec, ds, daux)
    P = sens_pseudo_load(ops, rec, design_part, dpred)
    dz = sens_solve(ops, rec, P)
    ds = sens_correct(ops, rec, dpred, dz)
    return ds, sens_advance(ops, rec, dpred, ds)


class PythonDirectStep:
    """The step operations as Python, for a step ``rec`` = (lin, factor, h, projection)."""

    def __init__(self, scheme: Newmark, solve: Any, n_q: int, n_lam: int, project: Any):
        self.scheme, self._solve, self.n_q, self.n_lam = scheme, solve, n_q, n_lam
        self._project = project         # (projection, ∇s) -> ∇s, for a projection fed back

    def predict(self, rec: tuple, ds: StepState, daux: Any) -> Any:
        return self.scheme.predict(ds, daux, rec[2])

    def pseudo_load(self, rec: tuple, design_part: np.ndarray, dpred: Any) -> np.ndarray:
        return pseudo_load_with(design_part, rec[0], dpred.q, dpred.qd, dpred.p)

    def solve(self, rec: tuple, P: np.ndarray) -> np.ndarray:
        return self._solve(rec[1], P)

    def correct(self, rec: tuple, dpred: Any, dz: np.ndarray) -> StepState:
        ds = self.scheme.correct(dpred, *split_unknowns(dz, self.n_q, self.n_lam), rec[2])
        projection = rec[3]
        if projection is not None and projection.feedback:
            ds = self._project(projection, ds)
        return ds

    def advance(self, rec: tuple, dpred: Any, ds: StepState) -> Any:
        return self.scheme.advance(dpred, ds)


# ----------------------------------------------------------------------------- the compiled block
_F64 = np.dtype(np.float64)


class DenseBlock(NamedTuple):
    """The records of a block of steps for the compiled :func:`direct_block`, stacked (K, ...)."""

    R_q: np.ndarray       # (K, n_z, n_q)
    R_qd: np.ndarray      # (K, n_z, n_q)
    R_p: np.ndarray       # (K, n_z, n_p)
    lu: np.ndarray        # (K, n_z, n_z): getrf's LU, each in column-major order
    piv: np.ndarray       # (K, n_z) getrf's 1-based pivots (int32)
    h: np.ndarray         # (K,) step sizes (s)
    scheme: np.ndarray    # (β, γ, c_a)
    sizes: np.ndarray     # (n_q, n_lam)


class BandBlock(NamedTuple):
    """The records of a block of sparse steps whose S the Python path factored as a tridiagonal
    band (gttrf, after the plan's reordering ``perm``), for the compiled :func:`direct_block`:
    R_q and R_q̇ (n, n) on one CSC pattern each, their values stacked (K, nnz)."""

    R_q_values: np.ndarray     # (K, nnz), or (1, nnz) when all records share one matrix
    R_q_indptr: np.ndarray     # (n + 1,) column pointers
    R_q_indices: np.ndarray    # (nnz,) row indices
    R_qd_values: np.ndarray
    R_qd_indptr: np.ndarray
    R_qd_indices: np.ndarray
    dl: np.ndarray        # (K, n − 1) gttrf's multipliers
    d: np.ndarray         # (K, n) U's diagonal
    du: np.ndarray        # (K, n − 1) U's first super-diagonal
    du2: np.ndarray       # (K, max(n − 2, 0)) U's second super-diagonal
    ipiv: np.ndarray      # (K, n) gttrf's 1-based interchanges (int32)
    perm: np.ndarray      # (n,) row i of the reordered system is row perm[i] of S
    h: np.ndarray
    scheme: np.ndarray
    sizes: np.ndarray     # (n_q, 0)


def dense_real(rec: StepRecord) -> bool:
    """Whether the compiled dense block serves a record: a dense real linearization (R_q, R_q̇
    and R_p or none) and a dense real LU factor, no projection."""
    lin, factor = rec.lin, rec.factor
    if rec.projection is not None or type(factor) is not Factor or factor.dense_real_lu is None or lin is None:
        return False
    return _dense_real(lin.R_q) and _dense_real(lin.R_qd) and (lin.R_p is None or _dense_real(lin.R_p))


def band_real(rec: StepRecord) -> bool:
    """Whether the compiled band block serves a record: a real tridiagonal factor of S (n, n)
    with z = q̈ (no multipliers, no first-order states), R_q and R_q̇ real CSC, no projection.
    (A dense R_q beside a tridiagonal factor, a dense model of 48 or more unknowns, is left to
    the Python steps: copying its n² entries into the block cost more than the steps saved,
    and a banded product would not sum as numpy's BLAS does.)"""
    lin, factor = rec.lin, rec.factor
    if rec.projection is not None or type(factor) is not Factor or factor.tridiagonal_real is None \
            or lin is None or lin.R_p is not None:
        return False
    return all(_csc_real(a) and a.shape == (factor.n, factor.n) for a in (lin.R_q, lin.R_qd))


def _dense_real(a: Any) -> bool:
    return type(a) is np.ndarray and a.dtype == _F64


def _csc_real(a: Any) -> bool:
    return isinstance(a, sp.csc_matrix) and a.dtype == _F64


def block_kind(scheme: Newmark, trail: list[StepRecord], ds: StepState, design_part: np.ndarray) -> str | None:
    """``dense`` or ``band``, the compiled block that takes this block of records, or None (the
    Python steps): compiled code enabled, plain Newmark, real sensitivities and design partials,
    every record :func:`dense_real`, or every record :func:`band_real` with its R_q and R_q̇ on
    the first record's patterns and its band plan's reordering."""
    return records_kind(scheme, trail, [design_part, *ds])


def records_kind(scheme: Newmark, records: list[StepRecord], arrays: list[np.ndarray]) -> str | None:
    """``dense`` or ``band``, the kind of compiled block (the direct or the adjoint one) that
    takes these records, or None: a block may run (:func:`compiled_plain` with the mode's
    ``arrays``), and every record is :func:`dense_real`, or :func:`band_trail` holds them."""
    if not (records and compiled_plain(scheme, arrays)):
        return None
    if all(dense_real(r) for r in records):
        return "dense"
    return "band" if band_trail(records) else None


def compiled_plain(scheme: Newmark, arrays: list[np.ndarray]) -> bool:
    """Whether a compiled block may run: compiled code enabled, plain Newmark, real arrays."""
    return HAVE_NUMBA and enabled() and scheme.alpha_m == 0.0 and scheme.alpha_f == 0.0 and \
        all(a.dtype == _F64 for a in arrays)


@register_jitable
def band_solve(block: Any, k: int, rhs: np.ndarray, transposed: bool) -> np.ndarray:
    """x (n, m) with S x = −rhs, or Sᵀ x = −rhs when ``transposed``, for record k of a
    :class:`BandBlock`: TridiagonalFactor's solve (the rows reordered, dgttrs's arithmetic for each
    column, the same for one right-hand side or several, with TRANS = 'T' when transposed, the rows
    put back)."""
    n, m = rhs.shape
    perm = block.perm
    B = np.empty((n, m))
    for i in range(n):
        for j in range(m):
            B[i, j] = -rhs[perm[i], j]
    if transposed:
        gttrs_transposed_columns(block.dl[k], block.d[k], block.du[k], block.du2[k], block.ipiv[k], B)
    else:
        gttrs_columns(block.dl[k], block.d[k], block.du[k], block.du2[k], block.ipiv[k], B)
    x = np.empty((n, m))
    for i in range(n):
        for j in range(m):
            x[perm[i], j] = B[i, j]
    return x


def dense_solve(block: Any, k: int, rhs: np.ndarray, transposed: bool) -> np.ndarray:
    """x (n, m) with S x = −rhs, or Sᵀ x = −rhs when ``transposed``, for record k of a
    :class:`DenseBlock`: LAPACK getrs (TRANS = 'N' or 'T') on the record's getrf LU, as
    ``Factor.solve`` / ``Factor.solve_transposed`` call it; x in column-major order, as LAPACK
    returns it.  Compiled only (an overload); as Python it is never called."""
    raise NotImplementedError("dense_solve runs compiled only")


def band_trail(trail: list[StepRecord]) -> bool:
    """Whether a :class:`BandBlock` holds these records: every record :func:`band_real`, with its
    R_q and R_q̇ on the first record's patterns and its band plan's reordering."""
    return all(band_real(r) for r in trail) and all(
        _same_layout(trail[0].lin.R_q, r.lin.R_q) and _same_layout(trail[0].lin.R_qd, r.lin.R_qd)
        and _same_reordering(trail[0].factor.tridiagonal_real.plan.perm, r.factor.tridiagonal_real.plan.perm)
        for r in trail[1:])


def serves(scheme: Newmark, trail: list[StepRecord], ds: StepState, design_part: np.ndarray) -> bool:
    """Whether :func:`run_block` takes this block (:func:`block_kind`)."""
    return block_kind(scheme, trail, ds, design_part) is not None


def _same_layout(a: Any, b: Any) -> bool:
    """Whether two sparse matrices store the same positions, in the same order."""
    return (a.indptr is b.indptr or np.array_equal(a.indptr, b.indptr)) and \
        (a.indices is b.indices or np.array_equal(a.indices, b.indices))


def _same_reordering(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    """Whether two band plans reorder the unknowns alike (one plan per pattern: mostly the same
    object)."""
    return a is b or (a is not None and b is not None and np.array_equal(a, b))


def run_block(scheme: Newmark, trail: list[StepRecord], ds: StepState, daux: Any, design_part: np.ndarray,
              n_q: int, n_lam: int, kind: str | None = None) -> tuple[list[StepState], StepState, Any]:
    """The sensitivities of the records of ``trail`` (which :func:`serves`; ``kind``: its
    :func:`block_kind` when known), from ∇s and ∇aux before the first; design_part (K, n_z, m).
    Returns (∇s of each record, ∇s, ∇aux after the last)."""
    K = len(trail)
    kind = kind or block_kind(scheme, trail, ds, design_part)
    block = stacked_block(kind, trail, scheme, n_q, n_lam)
    # (leaves in one layout: the compiled block is typed by its arguments)
    out = _block()(block, tuple(np.ascontiguousarray(v) for v in ds), tuple(np.ascontiguousarray(v) for v in daux),
                   np.ascontiguousarray(design_part, np.float64))
    states = list(map(StepState._make, zip(*out[:6])))
    return states, states[-1], type(daux)(out[6][K - 1], out[7][K - 1])


def stacked_block(kind: str | None, records: list[StepRecord], scheme: Newmark, n_q: int, n_lam: int
                  ) -> "DenseBlock | BandBlock":
    """The records (of :func:`records_kind` ``kind``) stacked for a compiled block, with their
    step sizes, the scheme's (β, γ, c_a) and the sizes (n_q, n_λ)."""
    return (band_block if kind == "band" else dense_block)(
        records, np.array([r.h for r in records], float), np.array([scheme.beta, scheme.gamma, scheme.c_a]),
        np.array([n_q, n_lam]))


def dense_block(trail: list[StepRecord], h: np.ndarray, scheme: np.ndarray, sizes: np.ndarray) -> DenseBlock:
    """The records of ``trail`` (each :func:`dense_real`) stacked for a compiled block."""
    zeros = np.zeros((trail[0].factor.n, 0))
    return DenseBlock(
        np.array([r.lin.R_q for r in trail]), np.array([r.lin.R_qd for r in trail]),
        np.array([r.lin.R_p if r.lin.R_p is not None else zeros for r in trail]),
        np.array([r.factor.compiled_lu[0] for r in trail]), np.array([r.factor.compiled_lu[1] for r in trail]),
        h, scheme, sizes)


def band_block(trail: list[StepRecord], h: np.ndarray, scheme: np.ndarray, sizes: np.ndarray) -> BandBlock:
    """The records of ``trail`` (which :func:`band_trail` holds) stacked for a compiled block."""
    lus = [r.factor.tridiagonal_real for r in trail]
    perm = lus[0].plan.perm        # (one for the block: :func:`block_kind`)

    def stack(name: str) -> np.ndarray:
        return np.array([getattr(lu, name) for lu in lus])
    return BandBlock(
        *_stacked([r.lin.R_q for r in trail]), *_stacked([r.lin.R_qd for r in trail]),
        stack("dl"), stack("d"), stack("du"), stack("du2"), stack("ipiv").astype(np.int32),
        np.arange(lus[0].plan.n, dtype=np.intp) if perm is None else np.asarray(perm, np.intp), h, scheme, sizes)


def _stacked(mats: list[Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(values (K, nnz), indptr, indices) of a block's sparse matrices on one pattern; values
    (1, nnz) when every record holds the same matrix (a spring network's damping matrix), read
    by :func:`values_of` for each record."""
    first = mats[0]
    values = first.data[None] if all(a is first for a in mats) else np.array([a.data for a in mats])
    return values, first.indptr.astype(np.intp), first.indices.astype(np.intp)


@register_jitable
def values_of(values: np.ndarray, k: int) -> np.ndarray:
    """Record k's CSC values in a :class:`BandBlock`'s stack (one row: shared by every record)."""
    return values[k] if values.shape[0] > 1 else values[0]


def _make_block(stamp: str) -> Any:
    def block(ops, ds, daux, design_part):  # type: ignore[no-untyped-def]
        stamp       # noqa: B018 - a closure variable: part of numba's cache key
        return direct_block(ops, ds, daux, design_part)
    return jit(block)


@register_jitable
def direct_block(ops: Any, ds: Any, daux: Any, design_part: np.ndarray) -> tuple:
    """:func:`direct_step` for each record k of the block; every record's ∇s and ∇aux, stacked
    (K, n, m) per leaf."""
    K = design_part.shape[0]
    out = tuple_of_stacks(ds, daux, K)
    for k in range(K):
        ds, daux = direct_step(ops, k, ds, daux, design_part[k])
        store(out, k, ds, daux)
    return out


_COMPILED: list[Any] = []
GETRS_SYMBOL = "dynsens_dgetrs"


def _block() -> Any:
    """The compiled :func:`direct_block` (the overloads registered first)."""
    if not _COMPILED:
        import sys

        from ..solver import sparse_products, tridiagonal
        from ..solver.compiled_iteration import sources_stamp
        register_overloads()
        _COMPILED.append(_make_block(sources_stamp((sys.modules[__name__], tridiagonal, sparse_products))))
    return _COMPILED[0]


_REGISTERED: list[bool] = []


def register_overloads() -> None:
    """Register the overloads of this module (once: the adjoint's block uses :func:`dense_solve`)."""
    if not _REGISTERED:
        _register()
        _REGISTERED.append(True)


@register_jitable
def tuple_of_stacks(ds: Any, daux: Any, K: int) -> tuple:
    """Empty (K, n, m) arrays for each leaf of ∇s and ∇aux."""
    return (np.empty((K,) + ds[0].shape), np.empty((K,) + ds[1].shape), np.empty((K,) + ds[2].shape),
            np.empty((K,) + ds[3].shape), np.empty((K,) + ds[4].shape), np.empty((K,) + ds[5].shape),
            np.empty((K,) + daux[0].shape), np.empty((K,) + daux[1].shape))


@register_jitable
def store(out: tuple, k: int, ds: Any, daux: Any) -> None:
    """Record k's ∇s and ∇aux into the stacks of :func:`tuple_of_stacks`."""
    for i in range(6):
        out[i][k] = ds[i]
    out[6][k] = daux[0]
    out[7][k] = daux[1]


def _register() -> None:
    """The overloads of the step operations for :class:`DenseBlock` and :class:`BandBlock`
    (numba only).  The two differ in the pseudo load's products and in the solve."""
    import llvmlite.binding as ll
    from numba import types
    from numba.extending import get_cython_function_address, overload

    from ..solver.compiled_iteration import is_step_data
    from ..solver.sparse_products import csc_times

    # LAPACK's dgetrs as scipy exports it (the routine scipy.linalg.lapack's getrs calls), by a
    # symbol name: a compiled function that calls a ctypes pointer could not be cached
    ll.add_symbol(GETRS_SYMBOL, get_cython_function_address("scipy.linalg.cython_lapack", "dgetrs"))
    vp = types.voidptr
    getrs = types.ExternalFunction(GETRS_SYMBOL, types.void(vp, vp, vp, vp, vp, vp, vp, vp, vp))
    predict, correct = inline(predict_arrays), inline(correct_arrays)
    advance, coefficients = inline(advance_arrays), inline(corrector_coefficients)
    times = inline(csc_times)

    def dense(ops: Any) -> bool:
        return is_step_data(ops, DenseBlock)

    def band(ops: Any) -> bool:
        return is_step_data(ops, BandBlock)

    @overload(sens_predict)
    def _predict(ops, rec, ds, daux):  # type: ignore[no-untyped-def]
        if dense(ops) or band(ops):
            return lambda ops, rec, ds, daux: predict(ds[0], ds[1], ds[4], daux[0], daux[1], ops.h[rec],
                                                      ops.scheme[0], ops.scheme[1])

    @overload(sens_pseudo_load)
    def _pseudo_load(ops, rec, design_part, dpred):  # type: ignore[no-untyped-def]
        if dense(ops):
            def impl(ops, rec, design_part, dpred):  # type: ignore[no-untyped-def]
                # pseudo_load_with's sums (Linearization.state_product's), in its order
                out = ops.R_q[rec] @ dpred[0]
                out = out + ops.R_qd[rec] @ dpred[1]
                if dpred[2].shape[0] and ops.R_p.shape[2]:     # (no columns: the record had no R_p)
                    out = out + ops.R_p[rec] @ dpred[2]
                return design_part + out
            return impl
        if band(ops):
            def band_impl(ops, rec, design_part, dpred):  # type: ignore[no-untyped-def]
                # Linearization.state_product's sums: R_q ∇q, then + R_q̇ ∇q̇ (scipy's products)
                out = times(values_of(ops.R_q_values, rec), ops.R_q_indptr, ops.R_q_indices, dpred[0])
                out = out + times(values_of(ops.R_qd_values, rec), ops.R_qd_indptr, ops.R_qd_indices, dpred[1])
                return design_part + out
            return band_impl
        return None

    @overload(dense_solve)
    def _dense_solve(block, k, rhs, transposed):  # type: ignore[no-untyped-def]
        def impl(block, k, rhs, transposed):  # type: ignore[no-untyped-def]
            n, m = rhs.shape
            x = np.empty((m, n))            # −rhs in column-major order, as LAPACK takes it
            for i in range(n):
                for j in range(m):
                    x[j, i] = -rhs[i, j]
            trans = np.array([ord("T") if transposed else ord("N")], np.uint8)
            ints = np.array([n, m, n, n, 0], np.int32)      # n, nrhs, lda, ldb, info
            lu = block.lu[k]
            piv = block.piv[k]
            getrs(trans.ctypes, ints[0:].ctypes, ints[1:].ctypes, lu.ctypes, ints[2:].ctypes, piv.ctypes,
                  x.ctypes, ints[3:].ctypes, ints[4:].ctypes)
            return x.T
        return impl

    @overload(sens_solve)
    def _solve(ops, rec, P):  # type: ignore[no-untyped-def]
        if dense(ops):
            return lambda ops, rec, P: dense_solve(ops, rec, P, False)
        if band(ops):
            return lambda ops, rec, P: band_solve(ops, rec, P, False)
        return None

    @overload(sens_correct)
    def _correct(ops, rec, dpred, dz):  # type: ignore[no-untyped-def]
        if not (dense(ops) or band(ops)):
            return None

        def impl(ops, rec, dpred, dz):  # type: ignore[no-untyped-def]
            n_q, n_lam = ops.sizes[0], ops.sizes[1]
            c_q, c_qd, c_p = coefficients(ops.h[rec], ops.scheme[0], ops.scheme[1], ops.scheme[2])
            qdd, lam, pd = dz[:n_q], dz[n_q:n_q + n_lam], dz[n_q + n_lam:]
            q, qd, p = correct(dpred[0], dpred[1], dpred[2], c_q, c_qd, c_p, qdd, pd)
            return (np.ascontiguousarray(q), np.ascontiguousarray(qd), np.ascontiguousarray(qdd),
                    np.ascontiguousarray(lam), np.ascontiguousarray(p), np.ascontiguousarray(pd))
        return impl

    @overload(sens_advance)
    def _advance(ops, rec, dpred, ds):  # type: ignore[no-untyped-def]
        if dense(ops) or band(ops):
            return lambda ops, rec, dpred, ds: advance(0.0, 0.0, ds[2], ds[5], ops.scheme[2])
