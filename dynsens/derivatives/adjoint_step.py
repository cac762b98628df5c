r"""One step of the adjoint sweep (method.md §7), defined once for every backend.

:func:`adjoint_step` is the transpose of one direct step (:func:`.direct_step.direct_step`),
taken backwards: the scheme's advance and corrector transposed, μ = −S⁻ᵀ z̄ with the step's
factor, the pseudo load's state part transposed ((R_q, R_q̇, R_p)ᵀ μ onto the predicted state's
bars), the predictor transposed.  Like the direct step it reaches the scheme and the linear
algebra only through operations (``adj_*``):

* run as Python, they are the methods of :class:`PythonAdjointStep` (any scheme, model, matrix
  kind, real or complex; the adjoint mode transposes a step's projection before it);
* compiled, they are numba overloads for the direct step's blocks of plain-Newmark records
  (:mod:`.direct_step`): :class:`~.direct_step.DenseBlock`, dense real linearizations and LU
  factors (mechanisms, small structural models), and :class:`~.direct_step.BandBlock`, sparse
  records whose factor is a tridiagonal band (chains); :func:`adjoint_block` takes a run of such
  records, with the responses' seeds at their grid instants, without returning to the
  interpreter.  The dense block's products are the BLAS routines numpy's products call and its solve
  LAPACK getrs with TRANS = 'T', as the Python path's numpy products and
  ``Factor.solve_transposed``: the same numbers where numba's BLAS is numpy's build.  The band
  block's products are scipy's CSC sums (:func:`dynsens.solver.sparse_products.csc_transpose_times`,
  which the Python steps call too) and its solve dgttrs's arithmetic with TRANS = 'T'
  (:func:`dynsens.solver.tridiagonal.gttrs_transposed_columns`): the same numbers everywhere.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..integrators.newmark import (Aux, Newmark, Prediction, advance_transpose_arrays, corrector_coefficients,
                                   correct_transpose_arrays, predict_transpose_arrays)
from ..models.base import StepState
from ..solver._jit import inline, jit, register_jitable
from ..solver.sparse_products import transpose_times
from ..timeloop.stepping import StepRecord
from .direct_step import BandBlock, DenseBlock, band_solve, dense_solve, records_kind, stacked_block, values_of

# the scheme's transposed maps, callable from compiled code as they are
for _scheme_map in (advance_transpose_arrays, correct_transpose_arrays, predict_transpose_arrays):
    register_jitable(_scheme_map)


# ----------------------------------------------------------------------------- step operations
# Each is the method of the same name of a Python step object (``rec``: what the object needs of
# the step); the compiled block overloads them, so these bodies run in Python only.

def adj_advance_transpose(ops: Any, rec: Any, bar: tuple, aux: tuple) -> tuple[tuple, tuple]:
    """The state's bars with the scheme's advance transposed, and the bars of a_rest, b_rest."""
    return ops.advance_transpose(rec, bar, aux)


def adj_correct_transpose(ops: Any, rec: Any, s_bar: tuple) -> tuple[tuple, tuple]:
    """The bars of the predicted (q, q̇, p) and of the unknowns z = (q̈, λ, ṗ)."""
    return ops.correct_transpose(rec, s_bar)


def adj_solve(ops: Any, rec: Any, z_bar: tuple) -> np.ndarray:
    """μ = −S⁻ᵀ z̄ (n_z, r) with the step's factor."""
    return ops.solve(rec, z_bar)


def adj_state_transpose(ops: Any, rec: Any, mu: np.ndarray, pred_bar: tuple) -> tuple:
    """The predicted state's bars plus (R_q, R_q̇, R_p)ᵀ μ (new arrays)."""
    return ops.state_transpose(rec, mu, pred_bar)


def adj_predict_transpose(ops: Any, rec: Any, pred_bar: tuple, rest_bar: tuple, s_bar: tuple
                          ) -> tuple[tuple, tuple]:
    """The bars of the previous step's state and algorithmic accelerations."""
    return ops.predict_transpose(rec, pred_bar, rest_bar, s_bar)


@register_jitable
def adjoint_step(ops: Any, rec: Any, bar: tuple, aux: tuple) -> tuple[tuple, tuple, np.ndarray]:
    """Transpose of one direct step: the bars (q, q̇, q̈, λ, p, ṗ) and (a, b) of the step ``rec``
    become those of the step before it; returns them and μ of the step."""
    s_bar, rest_bar = adj_advance_transpose(ops, rec, bar, aux)
    pred_bar, z_bar = adj_correct_transpose(ops, rec, s_bar)
    mu = adj_solve(ops, rec, z_bar)
    pred_bar = adj_state_transpose(ops, rec, mu, pred_bar)
    bar, aux = adj_predict_transpose(ops, rec, pred_bar, rest_bar, s_bar)
    return bar, aux, mu


class PythonAdjointStep:
    """The step operations as Python, for a step record ``rec``: the scheme's transposed maps
    are its methods (which call the array functions the compiled block calls)."""

    def __init__(self, scheme: Newmark, solve: Any):
        self.scheme, self._solve = scheme, solve     # solve(rec, z̄) -> μ

    def advance_transpose(self, rec: StepRecord, bar: tuple, aux: tuple) -> tuple[tuple, tuple]:
        return self.scheme.advance_transpose(Aux(*aux), StepState(*bar))

    def correct_transpose(self, rec: StepRecord, s_bar: tuple) -> tuple[tuple, tuple]:
        return self.scheme.correct_transpose(StepState(*s_bar), rec.h)

    def solve(self, rec: StepRecord, z_bar: tuple) -> np.ndarray:
        return self._solve(rec, np.concatenate(z_bar))

    def state_transpose(self, rec: StepRecord, mu: np.ndarray, pred_bar: tuple) -> tuple:
        out = [b.copy() for b in pred_bar]
        for block, target in zip((rec.lin.R_q, rec.lin.R_qd, rec.lin.R_p), out):
            if block is not None and target.shape[0]:
                target += transpose_times(block, mu)
        return tuple(out)

    def predict_transpose(self, rec: StepRecord, pred_bar: tuple, rest_bar: tuple, s_bar: tuple
                          ) -> tuple[tuple, tuple]:
        pq, pqd, pp = pred_bar
        return self.scheme.predict_transpose(Prediction(pq, pqd, pp, rest_bar[0], rest_bar[1]), rec.h,
                                             np.zeros_like(s_bar[3]))


# ----------------------------------------------------------------------------- the compiled block
def block_kind(scheme: Newmark, records: list[StepRecord], bar: list[np.ndarray]) -> str | None:
    """``dense`` or ``band``, the compiled block that takes these records (in the sweep's order),
    or None (the Python steps): a block may run (:func:`.direct_step.compiled_plain`: compiled
    code, plain Newmark, real arrays), and every record is :func:`.direct_step.dense_real`, or
    every record a tridiagonal band's on the first one's patterns (:func:`.direct_step.band_trail`)."""
    return records_kind(scheme, records, bar)


def serves(scheme: Newmark, records: list[StepRecord], bar: list[np.ndarray]) -> bool:
    """Whether :func:`run_block` takes these records (:func:`block_kind`)."""
    return block_kind(scheme, records, bar) is not None


def run_block(scheme: Newmark, records: list[StepRecord], bar: list[np.ndarray], aux: list[np.ndarray],
              seeds: np.ndarray, seeded: np.ndarray, n_q: int, kind: str | None = None
              ) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray], bool]:
    """The adjoint steps of ``records`` (which :func:`serves`; ``kind``: their
    :func:`block_kind` when known), in the sweep's order, from the bars ``bar`` (six leaves
    (·, r)) and ``aux`` (two); before record k's step, where ``seeded[k]``, the seed seeds[k]
    (n_x, r) on the state's bars.  Returns the bars after the last step, every step's μ (n_z, r)
    as the Python steps leave them, and whether all of them are finite (one sum: False may also
    be an overflowing sum of finite entries)."""
    kind = kind or block_kind(scheme, records, bar)
    block = stacked_block(kind, records, scheme, n_q, bar[3].shape[0])
    out = _block()(block, tuple(np.ascontiguousarray(b) for b in bar), tuple(np.ascontiguousarray(a) for a in aux),
                   np.ascontiguousarray(seeds, np.float64), seeded)
    # each μ in the layout of the Python steps' (LAPACK's solve returns Fortran-ordered columns):
    # the design term's sums over a block follow memory order
    return list(out[0]), list(out[1]), [np.asfortranarray(mu) for mu in out[2]], \
        bool(np.isfinite(np.sum(out[2])))


def _make_block(stamp: str) -> Any:
    def block(ops, bar, aux, seeds, seeded):  # type: ignore[no-untyped-def]
        stamp       # noqa: B018 - a closure variable: part of numba's cache key
        return adjoint_block(ops, bar, aux, seeds, seeded)
    return jit(block)


@register_jitable
def adjoint_block(ops: Any, bar: tuple, aux: tuple, seeds: np.ndarray, seeded: np.ndarray) -> tuple:
    """:func:`adjoint_step` for each record k of the block, record k's seed added first; the bars
    after the last and every μ (K, n_z, r)."""
    K = ops.h.shape[0]
    r = bar[0].shape[1]
    mus = np.empty((K, bar[2].shape[0] + bar[3].shape[0] + bar[5].shape[0], r))
    for k in range(K):
        if seeded[k]:
            bar = add_seed(bar, seeds[k])
        bar, aux, mu = adjoint_step(ops, k, bar, aux)
        mus[k] = mu
    return bar, aux, mus


@register_jitable
def add_seed(bar: tuple, seed: np.ndarray) -> tuple:
    """The bars (q, q̇, q̈, λ, p, ṗ) plus the seed (n_x, r) on the flat state, leaf by leaf."""
    out = []
    start = 0
    for i in range(6):
        n = bar[i].shape[0]
        out.append(bar[i] + seed[start:start + n])
        start += n
    return (out[0], out[1], out[2], out[3], out[4], out[5])


_COMPILED: list[Any] = []


def _block() -> Any:
    """The compiled :func:`adjoint_block` (the overloads registered first)."""
    if not _COMPILED:
        import sys

        from ..solver import sparse_products, tridiagonal
        from ..solver.compiled_iteration import sources_stamp
        from . import direct_step
        _register()
        _COMPILED.append(_make_block(sources_stamp((sys.modules[__name__], direct_step, tridiagonal,
                                                    sparse_products))))
    return _COMPILED[0]


def _register() -> None:
    """The overloads of the step operations for :class:`~.direct_step.DenseBlock` and
    :class:`~.direct_step.BandBlock` (numba only).  The two differ in the solve and the products."""
    from numba.extending import overload

    from ..solver.compiled_iteration import is_step_data
    from ..solver.sparse_products import csc_transpose_times
    from .direct_step import register_overloads

    register_overloads()        # the direct step's dense_solve
    coefficients = inline(corrector_coefficients)
    transposed = inline(csc_transpose_times)

    def band(ops: Any) -> bool:
        return is_step_data(ops, BandBlock)

    def dense(ops: Any) -> bool:
        return is_step_data(ops, DenseBlock)

    def either(ops: Any) -> bool:
        return band(ops) or dense(ops)

    # The scheme's maps act entry by entry: they take the bars (n, r) flattened, which compiled
    # loops run three times faster than over rows of one column (the same numbers)
    @overload(adj_advance_transpose)
    def _advance(ops, rec, bar, aux):  # type: ignore[no-untyped-def]
        if either(ops):
            def impl(ops, rec, bar, aux):  # type: ignore[no-untyped-def]
                r = bar[0].shape[1]
                s, rest = advance_transpose_arrays(flat6(bar), (aux[0].ravel(), aux[1].ravel()), ops.scheme[2])
                return shaped6(s, r), (shaped(rest[0], r), shaped(rest[1], r))
            return impl

    @overload(adj_correct_transpose)
    def _correct(ops, rec, s_bar):  # type: ignore[no-untyped-def]
        if either(ops):
            def impl(ops, rec, s_bar):  # type: ignore[no-untyped-def]
                r = s_bar[0].shape[1]
                c_q, c_qd, c_p = coefficients(ops.h[rec], ops.scheme[0], ops.scheme[1], ops.scheme[2])
                pred, z = correct_transpose_arrays(flat6(s_bar), c_q, c_qd, c_p)
                return ((shaped(pred[0], r), shaped(pred[1], r), shaped(pred[2], r)),
                        (shaped(z[0], r), shaped(z[1], r), shaped(z[2], r)))
            return impl

    @overload(adj_solve)
    def _solve(ops, rec, z_bar):  # type: ignore[no-untyped-def]
        if band(ops):
            # Factor.solve_transposed(−z̄) of a tridiagonal factor (z = q̈: no λ, no ṗ)
            return lambda ops, rec, z_bar: band_solve(ops, rec, z_bar[0], True)
        if dense(ops):
            # Factor.solve_transposed(−z̄) with z̄ = (q̈, λ, ṗ)'s bars stacked
            return lambda ops, rec, z_bar: dense_solve(ops, rec, np.concatenate(z_bar), True)

    @overload(adj_state_transpose)
    def _state(ops, rec, mu, pred_bar):  # type: ignore[no-untyped-def]
        if band(ops):
            def impl(ops, rec, mu, pred_bar):  # type: ignore[no-untyped-def]
                r = mu.shape[1]
                pq = pred_bar[0].ravel() + transposed(values_of(ops.R_q_values, rec), ops.R_q_indptr,
                                                      ops.R_q_indices, mu).ravel()
                pqd = pred_bar[1].ravel() + transposed(values_of(ops.R_qd_values, rec), ops.R_qd_indptr,
                                                       ops.R_qd_indices, mu).ravel()
                return shaped(pq, r), shaped(pqd, r), pred_bar[2].copy()
            return impl
        if dense(ops):
            def dense_impl(ops, rec, mu, pred_bar):  # type: ignore[no-untyped-def]
                # (R_p without columns: the record had none, and the Python step skips it too)
                pp = pred_bar[2] + product_transposed(ops.R_p[rec], mu) \
                    if pred_bar[2].shape[0] and ops.R_p.shape[2] else pred_bar[2].copy()
                return (pred_bar[0] + product_transposed(ops.R_q[rec], mu),
                        pred_bar[1] + product_transposed(ops.R_qd[rec], mu), pp)
            return dense_impl

    @overload(adj_predict_transpose)
    def _predict(ops, rec, pred_bar, rest_bar, s_bar):  # type: ignore[no-untyped-def]
        if either(ops):
            def impl(ops, rec, pred_bar, rest_bar, s_bar):  # type: ignore[no-untyped-def]
                r = pred_bar[0].shape[1]
                s, aux = predict_transpose_arrays(pred_bar[0].ravel(), pred_bar[1].ravel(), pred_bar[2].ravel(),
                                                  rest_bar[0].ravel(), rest_bar[1].ravel(),
                                                  np.zeros(s_bar[3].size), ops.h[rec], ops.scheme[0],
                                                  ops.scheme[1], 0.0, 0.0)
                return shaped6(s, r), (shaped(aux[0], r), shaped(aux[1], r))
            return impl


@register_jitable
def product_transposed(A: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Aᵀ μ (n, r) for a dense A (n_z, n) and μ (n_z, r) by the BLAS routine numpy's ``A.T @ μ``
    takes for these shapes: dot for one entry, gemv for one column or one row, else gemm."""
    n, r = A.shape[1], mu.shape[1]
    if n == 1 and r == 1:
        out = np.empty((1, 1))
        out[0, 0] = np.dot(np.ascontiguousarray(A[:, 0]), np.ascontiguousarray(mu[:, 0]))
        return out
    if r == 1:
        return (A.T @ np.ascontiguousarray(mu[:, 0])).reshape((n, 1))
    if n == 1:
        return (np.ascontiguousarray(A[:, 0]) @ mu).reshape((1, r))
    return A.T @ mu


@register_jitable
def shaped(v: np.ndarray, r: int) -> np.ndarray:
    """A flattened bar (n r,) back as (n, r)."""
    return v.reshape((v.size // r, r))


@register_jitable
def flat6(bar: tuple) -> tuple:
    """The six bars (q, q̇, q̈, λ, p, ṗ), each (n, r), flattened."""
    return (bar[0].ravel(), bar[1].ravel(), bar[2].ravel(), bar[3].ravel(), bar[4].ravel(), bar[5].ravel())


@register_jitable
def shaped6(bar: tuple, r: int) -> tuple:
    """The six flattened bars back as (n, r) each."""
    return (shaped(bar[0], r), shaped(bar[1], r), shaped(bar[2], r), shaped(bar[3], r), shaped(bar[4], r),
            shaped(bar[5], r))
