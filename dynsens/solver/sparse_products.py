"""Products of a CSC matrix with a block of vectors, compiled, summed as scipy sums them.

scipy multiplies a CSC matrix A by x (n, m) column by column (``csc_matvecs``): each stored
entry's products are added to its row, in the order stored.  Aᵀ x is the CSR product on the
same arrays (``csr_matvecs``): each column of A sums its stored entries times x, in the order
stored.  The functions here take those very sums, so their results equal scipy's bit for bit
(no BLAS on either side), without scipy's per-call cost of building the transposed matrix and
checking its format (about 36 µs a call, more than the product of a 1 000-unknown chain).
They are compiled into the compiled sensitivity steps (:mod:`dynsens.derivatives.direct_step`)
and serve the adjoint's Python steps through :func:`transpose_times`.
"""
from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from ._jit import enabled, jit, register_jitable


@register_jitable
def csc_times(values: np.ndarray, indptr: np.ndarray, indices: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A x for the square CSC matrix A = (values, indptr, indices) and x (n, m)."""
    n, m = x.shape
    y = np.zeros((n, m))
    for j in range(indptr.shape[0] - 1):
        for k in range(indptr[j], indptr[j + 1]):
            i = indices[k]
            a = values[k]
            for v in range(m):
                y[i, v] += a * x[j, v]
    return y


@register_jitable
def csc_transpose_times(values: np.ndarray, indptr: np.ndarray, indices: np.ndarray,
                        x: np.ndarray) -> np.ndarray:
    """Aᵀ x for the CSC matrix A = (values, indptr, indices) with n_rows rows and x (n_rows, m):
    (n_cols, m)."""
    m = x.shape[1]
    y = np.empty((indptr.shape[0] - 1, m))
    for j in range(indptr.shape[0] - 1):
        for v in range(m):
            acc = 0.0               # scipy's sum: from zero, the stored entries in order
            for k in range(indptr[j], indptr[j + 1]):
                acc += values[k] * x[indices[k], v]
            y[j, v] = acc
    return y


_TRANSPOSED: list[Any] = []     # the compiled csc_transpose_times, made on first use


def transpose_times(A: Any, x: np.ndarray) -> np.ndarray:
    """Aᵀ x for a matrix A (dense or sparse) and x (n, m): compiled for a real CSC A and a real
    x where compiled code is enabled (the same numbers as scipy's), else ``A.T @ x``."""
    # (the cheap tests first: a dense model's two products per step pay only for them)
    if not (type(A) is sp.csc_matrix and A.dtype == np.float64 and x.ndim == 2 and x.dtype == np.float64
            and enabled()):
        return A.T @ x
    if not _TRANSPOSED:
        _TRANSPOSED.append(jit(csc_transpose_times))
    return _TRANSPOSED[0](A.data, A.indptr, A.indices, np.ascontiguousarray(x))
