r"""The step operations of a spring network, compiled: numba overloads for :class:`SpringStepData`.

:func:`dynsens.solver.newton_core.newton_iterations` compiled for a named tuple of a step's
arrays (which designs it serves, and what becomes of its results: :mod:`.step`):

* the state is the scheme's corrector (:func:`dynsens.integrators.newmark.correct_arrays`);
* F_R = M q̈ + f_int(q) − f_ext(t) + D q̇ with the spring law's forces and tangents
  (:func:`.spring_law.spring_law`, spring by spring in one pass), summed as the Python path sums them: a sparse model's
  products entry by entry in stored order, as scipy's; a dense model's through BLAS, as numpy's;
  f_ext(t) is the model's, evaluated once a step in Python;
* S is formed where it is stored ((c_q K_t + c_q̇ D) + M, the Python path's sums): on the three
  diagonals, factored by :func:`dynsens.solver.tridiagonal.gttrf` (LAPACK's dgttrf, operation for
  operation) in the band plan's order, or whole, by columns, factored and solved by LAPACK's
  dgesv (:func:`dynsens.solver.compiled_iteration.dense_solver`: dgetrf and dgetrs, the routines
  of the Python path's dense :class:`~dynsens.solver.linalg.Factor`), with the Python path's
  tests of regularity.

numba caches it on disk, keyed by the sources it inlines (:func:`_stamp`).
"""
from __future__ import annotations

import math
import sys
from typing import Any, NamedTuple

import numpy as np

from ...integrators.newmark import correct_arrays
from ...solver import newton_core as core
from ...solver import compiled_march as compiled_march_module
from ...solver.compiled_march import compiled_march, step_with, store_factor
from ...solver import tridiagonal
from ...solver._jit import inline, jit
from ...solver.compiled_iteration import (NON_FINITE_ENTRIES, REGULAR, SMALL_PIVOT, ZERO_PIVOT,
                                         LazyIteration, dense_solver, is_step_data, sources_stamp,
                                         step_kept)
from ...solver.linalg import pivot_test
from . import spring_law as law

Array = np.ndarray


class SpringStepData(NamedTuple):
    """What one step of a spring network reads: the step's arrays first, then those of the
    model and design (kept between steps).  Every array but the prediction is read-only."""

    q_pred: Array
    qd_pred: Array
    p_pred: Array            # (0,): no first-order states
    coeffs: Array            # (c_q, c_q̇, c_p)
    f_ext: Array             # (n,) loads at t
    mass: Array              # (n,) the diagonal mass
    spring_a: Array          # (n_s,) the springs' DOFs, n for ground
    spring_b: Array
    k1: Array
    k2: Array
    k3: Array
    k_pos: Array             # (4 n_s,) positions of the tangent's entries (aa, bb, ab, ba) in S's storage, −1: grounded
    G: Array                 # dense models: (n_s, n) spring forces to nodal forces, else (0, 0)
    D: Array                 # dense models: (n, n) damping, else (0, 0) and by rows below
    d_ptr: Array             # D by rows (sorted columns)
    d_col: Array
    d_val: Array
    mass_storage: Array      # M and D in S's storage: its three diagonals (3n − 2), or whole by columns (n²)
    damping_storage: Array
    dense_lu: Array          # (1,) True: S stored whole and factored by dense LU, False: tridiagonal
    perm: Array              # (n,) the band order: its row k is row perm[k] of S
    s_row: Array             # S's stored entries in the Python path's order: row, column, storage
    s_col: Array
    s_pos: Array


def _is_step_data(ops: Any) -> bool:
    return is_step_data(ops, SpringStepData)


_REGISTERED: list[bool] = []


def _register() -> None:
    """The overloads of the step operations for SpringStepData (numba only; once, for the
    iteration and the blocks of steps both)."""
    if _REGISTERED:
        return
    _REGISTERED.append(True)
    from numba.extending import overload

    correct = inline(correct_arrays)
    dense_factor_solve = dense_solver()

    @overload(core.step_correct)
    def _correct(ops, z):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops, z):  # type: ignore[no-untyped-def]
            n = ops.mass.shape[0]
            c = ops.coeffs
            q, qd, p = correct(ops.q_pred, ops.qd_pred, ops.p_pred, c[0], c[1], c[2], z[:n], z[n:])
            return q, qd, z[:n], z[n:], p, z[n:]
        return impl

    @overload(core.step_residual)
    def _residual(ops, s):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops, s):  # type: ignore[no-untyped-def]
            q, qd, qdd = s[0], s[1], s[2]
            n = q.shape[0]
            a, b = ops.spring_a, ops.spring_b
            n_s = a.shape[0]
            dense = ops.G.shape[0] > 0
            # one pass over the springs: each spring's law (scalars: the same operations as the
            # numpy model's arrays) and, for a sparse model, its forces added in stored order
            f, kt, f_int = np.empty(n_s), np.empty(n_s), np.zeros(n)
            for e in range(n_s):
                delta = (q[a[e]] if a[e] < n else 0.0) - (q[b[e]] if b[e] < n else 0.0)
                f[e], kt[e] = law.spring_law(delta, ops.k1[e], ops.k2[e], ops.k3[e])
                if not dense:           # scipy's sparse products: entries in stored order
                    if a[e] < n:
                        f_int[a[e]] += f[e]
                    if b[e] < n:
                        f_int[b[e]] -= f[e]
            if dense:                   # the dense model's products: BLAS's, as numpy calls them
                R = ((ops.mass * qdd + np.dot(f, ops.G)) - ops.f_ext) + np.dot(ops.D, qd)
                return R, kt
            R = np.empty(n)
            for i in range(n):
                acc = 0.0
                for k in range(ops.d_ptr[i], ops.d_ptr[i + 1]):
                    acc += ops.d_val[k] * qd[ops.d_col[k]]
                R[i] = ((ops.mass[i] * qdd[i] + f_int[i]) - ops.f_ext[i]) + acc
            return R, kt
        return impl

    @overload(core.step_no_factor)
    def _no_factor(ops):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops):  # type: ignore[no-untyped-def]
            e = np.zeros(0)
            return e, e, e, e, e, e, e, np.zeros(0, np.int32), np.zeros(3)
        return impl

    @overload(core.step_factor_solve)
    def _factor_solve(ops, s, evaluation, rhs):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops, s, evaluation, rhs):  # type: ignore[no-untyped-def]
            kt = evaluation
            n = rhs.shape[0]
            n_s = kt.shape[0]
            K = np.zeros(ops.mass_storage.shape[0])
            for block in range(4):          # the assembly's order: (a, a), (b, b), (a, b), (b, a)
                sign = 1.0 if block < 2 else -1.0
                for e in range(n_s):
                    pos = ops.k_pos[block * n_s + e]
                    if pos >= 0:
                        K[pos] += sign * kt[e]
            c = ops.coeffs
            S, lu = np.empty(K.shape[0]), np.empty(K.shape[0])
            finite = True                   # all_finite(S), entry by entry in the same pass
            for i in range(K.shape[0]):     # S, and the copy its factor overwrites, in one pass
                S[i] = ops.mass_storage[i] + (c[0] * K[i] + c[1] * ops.damping_storage[i])
                lu[i] = S[i]
                finite = finite and math.isfinite(S[i])
            q, qd, qdd = s[0], s[1], s[2]
            du2 = np.zeros(max(n - 2, 0))
            if ops.dense_lu[0]:             # S by columns: getrf's LU of S, and x = S⁻¹ rhs
                piv = np.zeros(n, np.int32)
                x = rhs.copy()
                test = dense_factor_solve(lu.reshape(n, n), piv, x)
                return test[0] == REGULAR, (K, q, qd, qdd.copy(), S, lu, du2, piv, test), x
            piv = np.zeros(n, np.int32)
            x = np.zeros(n)
            test = np.zeros(3)              # (code, column of a zero pivot, pivot ratio)
            if not finite:
                test[0] = NON_FINITE_ENTRIES
            else:
                dl, d, du = lu[:n - 1], lu[n - 1:2 * n - 1], lu[2 * n - 1:]
                info = tridiagonal.gttrf(dl, d, du, du2, piv)
                if info > 0:
                    test[0], test[1] = ZERO_PIVOT, info
                else:
                    regular, ratio = pivot_test(d)
                    if not regular:
                        test[0], test[2] = SMALL_PIVOT, ratio
                    else:
                        for k in range(n):
                            x[k] = rhs[ops.perm[k]]
                        tridiagonal.gttrs(dl, d, du, du2, piv, x)
            step = np.empty(n)
            for k in range(n):
                step[ops.perm[k]] = x[k]
            return test[0] == REGULAR, (K, q, qd, qdd.copy(), S, lu, du2, piv, test), step
        return impl

    @overload(core.step_at_roundoff)
    def _at_roundoff(ops, lf, R, z, rnorm):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops, lf, R, z, rnorm):  # type: ignore[no-untyped-def]
            S = lf[4]
            if S.size == 0:
                return False
            n = R.shape[0]
            if ops.dense_lu[0]:             # S by columns: the Python path's S is its transpose's rows
                return core.dense_at_roundoff(np.ascontiguousarray(S.reshape(n, n).T), R, z, rnorm)
            entries = S[ops.s_pos]          # S's stored entries, in the Python path's order
            if ops.G.shape[0] > 0:          # a dense model: the Python path's dense S and product
                Sd = np.zeros((n, n))
                for k in range(entries.shape[0]):
                    Sd[ops.s_row[k], ops.s_col[k]] = entries[k]
                return core.dense_at_roundoff(Sd, R, z, rnorm)
            if core.above_roundoff_bound(rnorm, entries, z):
                return False
            terms = np.zeros(n)
            for k in range(entries.shape[0]):
                terms[ops.s_row[k]] += abs(entries[k]) * abs(z[ops.s_col[k]])
            return core.within_roundoff(R, terms)
        return impl

    @overload(step_kept)
    def _kept(ops, s):  # type: ignore[no-untyped-def]
        if _is_step_data(ops):
            return lambda ops, s: None       # nothing: the structural checks read the state only

    @overload(step_with)
    def _with(ops, q_pred, qd_pred, p_pred, coeffs, f_ext):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops, q_pred, qd_pred, p_pred, coeffs, f_ext):  # type: ignore[no-untyped-def]
            return SpringStepData(q_pred, qd_pred, p_pred, coeffs, f_ext, ops.mass, ops.spring_a, ops.spring_b,
                                  ops.k1, ops.k2, ops.k3, ops.k_pos, ops.G, ops.D, ops.d_ptr, ops.d_col, ops.d_val,
                                  ops.mass_storage, ops.damping_storage, ops.dense_lu, ops.perm, ops.s_row,
                                  ops.s_col, ops.s_pos)
        return impl

    @overload(store_factor)
    def _store(ops, lf, factors, k):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops, lf, factors, k):  # type: ignore[no-untyped-def]
            # S itself is not kept: the sensitivities read its factor, and K_t for the linearization
            K, q, qd, qdd, S, lu, du2, piv, test = lf
            factors[0][k], factors[1][k], factors[2][k], factors[3][k] = K, q, qd, qdd
            factors[5][k], factors[6][k], factors[7][k], factors[8][k] = lu, du2, piv, test
        return impl

    @overload(core.step_block_norms)
    def _block_norms(ops, z, dz):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops, z, dz):  # type: ignore[no-untyped-def]
            zn, dzn = np.empty(1), np.empty(1)
            zn[0], dzn[0] = core.real_norm(z), core.real_norm(dz)
            return zn, dzn
        return impl


def _stamp() -> str:
    """The cache key of the compiled iteration and blocks: the sources they inline (the overloads
    here, the spring law, the tridiagonal LU, the block's loop)."""
    return sources_stamp((law, tridiagonal, compiled_march_module, sys.modules[__name__]))


# the compiled iteration and blocks of steps (the overloads registered first)
iteration = LazyIteration(_register, _stamp)
march = LazyIteration(_register, _stamp, compiled_march)


def _compiled_residuals(stamp: str) -> Any:
    """F_R of a spring network at K states for B parameter sets, compiled, its cache entries
    keyed by ``stamp`` as the iteration's."""

    def residuals(template, sets, q, qd, qdd, f_ext):  # type: ignore[no-untyped-def]
        stamp          # noqa: B018 - a closure variable: part of numba's cache key
        mass, k1, k2, k3, d_ptr, d_col, d_val = sets
        K, B, n = f_ext.shape
        out = np.empty((K, B, n))
        empty = np.zeros(0)
        t = template
        for b in range(B):
            for k in range(K):
                ops = SpringStepData(q[k], qd[k], empty, t.coeffs, f_ext[k, b], mass[b], t.spring_a, t.spring_b,
                                     k1[b], k2[b], k3[b], t.k_pos, t.G, t.D, d_ptr[b], d_col[b], d_val[b],
                                     t.mass_storage, t.damping_storage, t.dense_lu, t.perm, t.s_row, t.s_col,
                                     t.s_pos)
                out[k, b] = core.step_residual(ops, (q[k], qd[k], qdd[k], empty, empty, empty))[0]
        return out
    return jit(residuals)


_RESIDUALS: Any = None


def compiled_residuals(template: SpringStepData, sets: tuple[np.ndarray, ...], q: np.ndarray, qd: np.ndarray,
                       qdd: np.ndarray, f_ext: np.ndarray) -> np.ndarray:
    """F_R (K, B, n) as the compiled iteration forms it, at the K states (q, q̇, q̈) (K, n) each,
    for B designs of one spring network with the loads f_ext (K, B, n): the network's arrays are
    ``template``'s, the designs' are ``sets`` = (mass (B, n), k₁, k₂, k₃ (B, n_s), damping by
    rows: pointers (B, n + 1), columns and values (B, ≥ nnz)).  The design partials' residuals
    of a sparse spring network (:meth:`.StructuralModel.residual_batch_steps`), bit for bit
    the model's (tests/test_structural_step.py); one compiled function for any B."""
    global _RESIDUALS
    if _RESIDUALS is None:
        iteration()                 # the overloads first
        _RESIDUALS = _compiled_residuals(_stamp())
    return _RESIDUALS(template, sets, q, qd, qdd, f_ext)  # type: ignore[no-any-return]
