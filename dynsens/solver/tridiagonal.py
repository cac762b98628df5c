"""LU of a tridiagonal matrix with partial pivoting, for a compiled step: LAPACK's dgttrf and
dgttrs (one right-hand side, no transpose) operation for operation, so that a factor made here
equals, bit for bit, the one scipy's LAPACK makes of the same matrix (tests/test_structural_step.py,
test_tridiagonal_lu_equals_lapack_bit_for_bit),
and the Python path's :class:`~dynsens.solver.banded.TridiagonalFactor` can solve with it.

numba exposes no tridiagonal LAPACK routine, and a call through a ctypes pointer would keep the
step out of numba's cache; the factorization is a handful of loops, latency-bound either way
(BENCHMARKS.md: the same time as LAPACK's at n = 1000).  Plain Python where numba is missing;
compiled into the callers that use it.
"""
from __future__ import annotations

import numpy as np

from ._jit import register_jitable


@register_jitable
def gttrf(dl: np.ndarray, d: np.ndarray, du: np.ndarray, du2: np.ndarray, ipiv: np.ndarray) -> int:
    """Factor the tridiagonal matrix with sub-, main and super-diagonal dl (n−1), d (n), du (n−1)
    in place as P L U (dgttrf): dl the multipliers, d and du U's diagonal and first
    super-diagonal, du2 (n−2) its second (fill from row interchanges), ipiv (n) the 1-based row
    interchanges.  Returns info: 0, or the 1-based index of the first exactly zero pivot."""
    n = d.shape[0]
    for i in range(n):
        ipiv[i] = i + 1
    for i in range(n - 2):
        du2[i] = 0.0
    for i in range(n - 1):
        if abs(d[i]) >= abs(dl[i]):
            # no interchange: eliminate dl[i]
            if d[i] != 0.0:
                fact = dl[i] / d[i]
                dl[i] = fact
                d[i + 1] = d[i + 1] - fact * du[i]
        else:
            # interchange rows i and i + 1, then eliminate
            fact = d[i] / dl[i]
            d[i] = dl[i]
            dl[i] = fact
            temp = du[i]
            du[i] = d[i + 1]
            d[i + 1] = temp - fact * d[i + 1]
            if i < n - 2:
                du2[i] = du[i + 1]
                du[i + 1] = -fact * du[i + 1]
            ipiv[i] = i + 2
    for i in range(n):
        if d[i] == 0.0:
            return i + 1
    return 0


@register_jitable
def gttrs_columns(dl: np.ndarray, d: np.ndarray, du: np.ndarray, du2: np.ndarray, ipiv: np.ndarray,
                  B: np.ndarray) -> None:
    """Solve A X = B in place for the m right-hand sides of B (n, m), row-major, with the
    factor of :func:`gttrf`: each column's operations are dgttrs's (via dgtts2, the same for one
    right-hand side or several), taken for all columns at once, so that the columns' division
    chains overlap (a column alone waits for each division in turn; BENCHMARKS.md, issue 35)."""
    n, m = B.shape
    # L X = B
    for i in range(n - 1):
        ip = ipiv[i] - 1
        other = i + 1 - ip + i
        for v in range(m):
            temp = B[other, v] - dl[i] * B[ip, v]
            B[i, v] = B[ip, v]
            B[i + 1, v] = temp
    # U X = B
    for v in range(m):
        B[n - 1, v] = B[n - 1, v] / d[n - 1]
    if n > 1:
        for v in range(m):
            B[n - 2, v] = (B[n - 2, v] - du[n - 2] * B[n - 1, v]) / d[n - 2]
    for i in range(n - 3, -1, -1):
        for v in range(m):
            B[i, v] = (B[i, v] - du[i] * B[i + 1, v] - du2[i] * B[i + 2, v]) / d[i]


@register_jitable
def gttrs(dl: np.ndarray, d: np.ndarray, du: np.ndarray, du2: np.ndarray, ipiv: np.ndarray,
          b: np.ndarray) -> None:
    """Solve A x = b in place with the factor of :func:`gttrf` for one right-hand side b (n,),
    contiguous: :func:`gttrs_columns` of b as a single column."""
    gttrs_columns(dl, d, du, du2, ipiv, b.reshape((b.shape[0], 1)))


@register_jitable
def gttrs_transposed_columns(dl: np.ndarray, d: np.ndarray, du: np.ndarray, du2: np.ndarray, ipiv: np.ndarray,
                             B: np.ndarray) -> None:
    """Solve Aᵀ X = B in place for the m right-hand sides of B (n, m), row-major, with the
    factor of :func:`gttrf`: each column's operations are dgttrs's with TRANS = 'T' (dgtts2),
    taken for all columns at once (the adjoint's transposed solves)."""
    n, m = B.shape
    # Uᵀ X = B
    for v in range(m):
        B[0, v] = B[0, v] / d[0]
    if n > 1:
        for v in range(m):
            B[1, v] = (B[1, v] - du[0] * B[0, v]) / d[1]
    for i in range(2, n):
        for v in range(m):
            B[i, v] = (B[i, v] - du[i - 1] * B[i - 1, v] - du2[i - 2] * B[i - 2, v]) / d[i]
    # Lᵀ X = B
    for i in range(n - 2, -1, -1):
        ip = ipiv[i] - 1
        for v in range(m):
            temp = B[i, v] - dl[i] * B[i + 1, v]
            B[i, v] = B[ip, v]
            B[ip, v] = temp
