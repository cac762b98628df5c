"""The factorized matrices of the constraint projection (:mod:`.projection`): J₀J₀ᵀ of its chord
iterations and M = J_Φ(q*) J₀ᵀ of its exact Newton iterations and derivatives, dense (LAPACK) or
sparse (SuperLU), factorized once per step and solved with many right-hand sides."""
from __future__ import annotations

from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

Array = np.ndarray


class _Factored:
    """A (n, n) dense or sparse, or a list of k such, factorized once: the chord and Newton
    iterations solve with the same matrix every iteration, and one matrix serves all k columns
    at once."""

    def __init__(self, A: Any):
        self.stacked = isinstance(A, list) or (isinstance(A, np.ndarray) and A.ndim == 3)
        self.lu = [_factor(a) for a in A] if self.stacked else _factor(A)

    def solve(self, res: Array) -> Array:
        """x (k, n, 1) for the right-hand sides res (k, n, 1)."""
        if self.stacked:
            return np.stack([_solve(lu, r) for lu, r in zip(self.lu, res)])
        return _solve(self.lu, res[:, :, 0].T).T[:, :, None]

    def solve_plain(self, rhs: Array) -> Array:
        """x (n, r) with A x = rhs (n, r) for the one matrix A (not stacked)."""
        return _solve(self.lu, rhs)

    def solve_transposed(self, rhs: Array) -> Array:
        """x (n, r) with Aᵀ x = rhs (n, r) for the one matrix A (not stacked)."""
        return _solve(self.lu, rhs, transposed=True)


def _factor(A: Any) -> Any:
    """LU of a dense (LAPACK) or sparse (SuperLU) square matrix."""
    return spla.splu(sp.csc_matrix(A)) if sp.issparse(A) else sla.lu_factor(A)


def _solve(lu: Any, rhs: Array, transposed: bool = False) -> Array:
    """x with A x = rhs (or Aᵀ x = rhs) ((n,) or (n, k)) for A's factor; a complex rhs of a real
    sparse factor as its real and imaginary parts."""
    if not isinstance(lu, spla.SuperLU):
        return sla.lu_solve(lu, rhs, trans=1 if transposed else 0)
    trans = "T" if transposed else "N"
    if np.iscomplexobj(rhs) and lu.U.dtype.kind != "c":
        return lu.solve(np.ascontiguousarray(rhs.real), trans=trans) + \
            1j * lu.solve(np.ascontiguousarray(rhs.imag), trans=trans)
    return lu.solve(np.ascontiguousarray(rhs, dtype=np.result_type(rhs, lu.U.dtype)), trans=trans)
