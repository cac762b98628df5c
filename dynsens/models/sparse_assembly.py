"""Sparse assembly on patterns fixed once per model: only the values are computed per call.

A structural model's tangent, damping and iteration matrices keep their sparsity pattern for
the whole run (the element connectivity does not change).  Building them through scipy's
COO → CSC conversion and sparse additions costs milliseconds a Newton iteration at 1 000 DOFs,
almost all of it index work that is the same every time.  Here the index work is done once:

* :class:`PatternAssembly` — the CSC pattern of a set of (row, column) entries and, for each
  entry, its slot; a matrix is then one ``bincount`` of the values (repeated positions are
  summed in the order of the entries, as the conversion sums them);
* :class:`UnionCache` — sums of matrices on the kept union of their patterns (the
  state-dependent terms a block gathers: follower loads, nonlinear dampers, a turning mass);
* :class:`SparseLinearization` — the iteration matrix S = M + (c_q K + c_q̇ D) on the union
  pattern of M, K and D, entry by entry the same sums as the sparse additions (an entry that
  cancels to zero stays in the pattern as an explicit zero);
* :class:`RightProduct` — x @ G for a fixed element-to-node map G with the transpose kept.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from .base import Linearization


class RightProduct:
    """x ↦ x @ G for x (..., a) and a fixed (a, b) matrix G, dense or sparse (element values to
    nodal forces, nodal values to element values).  scipy forms a sparse x @ G as (Gᵀ @ xᵀ)ᵀ and
    builds the transposed matrix object on every call, which costs more than the product at a
    thousand entries; here Gᵀ is made once from the same arrays, so the sums are the same, in the
    same order.  Leading axes of x are folded into one (scipy's products take two)."""

    def __init__(self, G: Any):
        self.G = G
        self.GT = G.T if sp.issparse(G) else None

    @property
    def shape(self) -> tuple[int, int]:
        """(a, b): the shape of G."""
        return self.G.shape

    def transposed(self) -> "RightProduct":
        """The product with Gᵀ (nodal values to element values for a scatter map G)."""
        return RightProduct(self.G.T)

    def columns(self, cols: np.ndarray) -> "RightProduct":
        """The product with the columns ``cols`` of G."""
        return RightProduct(self.G[:, cols])

    def __call__(self, x: np.ndarray) -> np.ndarray:
        if self.GT is None:
            return x @ self.G
        if x.ndim == 1:
            return self.GT @ x
        y = self.GT @ x.reshape(-1, x.shape[-1]).T
        return y.T.reshape(x.shape[:-1] + (self.G.shape[1],))


def _pattern(n: int, uniq: np.ndarray) -> sp.csc_matrix:
    """The (n, n) CSC matrix with entries at the sorted unique keys column · n + row (zeros)."""
    indices = (uniq % n).astype(np.int32)
    indptr = np.searchsorted(uniq // n, np.arange(n + 1)).astype(np.int32)
    A = sp.csc_matrix((np.zeros(uniq.size), indices, indptr), shape=(n, n))
    assert A.has_canonical_format      # sorted and unique by construction; the flag is kept
    return A


def on_pattern(pattern: sp.csc_matrix, data: np.ndarray) -> sp.csc_matrix:
    """The matrix of ``pattern`` (a canonical CSC matrix made once) with the entries ``data``: a
    shallow copy sharing its index arrays, without the format checks of scipy's constructor
    (which cost more than the values of a step at a thousand unknowns).  The copy is made as
    ``copy.copy`` makes it, without its generic dispatch (a quarter of the time)."""
    A: Any = object.__new__(type(pattern))       # what cls.__new__(cls) is for scipy's matrices
    A.__dict__.update(pattern.__dict__)
    A.data = data
    return A


class PatternAssembly:
    """(n, n) CSC matrices whose entries sit at fixed (rows, cols); duplicates are summed."""

    def __init__(self, n: int, rows: np.ndarray, cols: np.ndarray):
        self.n = n
        key = cols.astype(np.int64) * n + rows
        uniq, self.slot = np.unique(key, return_inverse=True)
        self.nnz = uniq.size
        self.pattern = _pattern(n, uniq)

    def matrix(self, values: np.ndarray, dtype: Any) -> sp.csc_matrix:
        """The matrix with entry k of ``values`` added at its slot."""
        data = np.bincount(self.slot, values.real, self.nnz)
        if np.iscomplexobj(values) or np.dtype(dtype).kind == "c":
            data = data + 1j * np.bincount(self.slot, values.imag, self.nnz)
        return on_pattern(self.pattern, data)


class _Union:
    """Union pattern of some CSC matrices and the slots of each one's entries in it (None for a
    matrix whose pattern is the union itself: its entries are the union's, in order)."""

    def __init__(self, mats: list[sp.csc_matrix]):
        n = mats[0].shape[0]
        keys = [np.repeat(np.arange(n, dtype=np.int64), np.diff(A.indptr)) * n + A.indices for A in mats]
        uniq = np.unique(np.concatenate(keys))
        slots = [np.searchsorted(uniq, k) for k in keys]
        self.slots = [None if s.size == uniq.size else s for s in slots]   # unique keys: all, in order
        self.nnz, self.n = uniq.size, n
        self.pattern = _pattern(n, uniq)
        self.patterns = [(A.indptr.copy(), A.indices.copy()) for A in mats]
        # the pattern arrays themselves: a model's assembly hands the same (never modified)
        # arrays with every matrix, recognised without comparing them entry by entry
        self._seen = [(A.indptr, A.indices) for A in mats]

    def fits(self, mats: list[sp.csc_matrix]) -> bool:
        """Whether the matrices have exactly the patterns this union was made of."""
        if len(mats) != len(self.patterns):
            return False
        if all(A.indptr is s[0] and A.indices is s[1] for A, s in zip(mats, self._seen)):
            return True
        if not all(np.array_equal(A.indptr, p) and np.array_equal(A.indices, i)
                   for A, (p, i) in zip(mats, self.patterns)):
            return False
        # the same patterns in new arrays (the next run of the same model): recognise these
        self._seen = [(A.indptr, A.indices) for A in mats]
        return True

    def place(self, values: np.ndarray, k: int, dtype: Any) -> np.ndarray:
        """The entries ``values`` of matrix k on the union pattern (zero where it has none)."""
        if self.slots[k] is None and values.dtype == dtype:
            return values
        out = np.zeros(self.nnz, dtype)
        out[self.positions(k)] = values
        return out

    def positions(self, k: int) -> Any:
        """Where matrix k's entries sit in the union (an index array, or all of it)."""
        s = self.slots[k]
        return slice(None) if s is None else s


class UnionCache:
    """The union pattern of the last matrices seen (a run's matrices keep their patterns)."""

    def __init__(self) -> None:
        self._last: _Union | None = None
        self._kept: dict[str, tuple[Any, ...]] = {}
        self._dtypes: dict[tuple[Any, ...], Any] = {}

    def constant(self, tag: str, source: np.ndarray, extra: Any, make: Any) -> np.ndarray:
        """``make()``, kept while ``source`` is the same read-only array and ``extra`` the same
        (the mass and damping entries of a run, which only the design changes): a writable
        source is never trusted to be unchanged, and is computed again."""
        if source.flags.writeable:
            return make()
        kept = self._kept.get(tag)
        if kept is None or kept[0] is not source or kept[1] != extra:
            kept = self._kept[tag] = (source, extra, make())
        return kept[2]

    def sum_dtype(self, mats: list[Any]) -> Any:
        """The dtype of a sum of the matrices (at least float), looked up once per dtype set."""
        key = tuple(m.dtype for m in mats)
        dt = self._dtypes.get(key)
        if dt is None:
            dt = self._dtypes[key] = np.result_type(*key, float)
        return dt

    def get(self, mats: list[sp.csc_matrix]) -> _Union:
        last = self._last               # read once: never another caller's union
        if last is None or not last.fits(mats):
            last = self._last = _Union(mats)
        return last

    def add(self, mats: list[Any]) -> sp.csc_matrix:
        """mats[0] + mats[1] + … (sparse, square) on their union pattern, summed in this order
        entry by entry as the sparse additions sum them; an entry that cancels to zero stays in
        the pattern as an explicit zero (the sparse additions would drop it)."""
        mats = [A if A.format == "csc" and A.has_canonical_format else sp.csc_matrix(A) for A in mats]
        u = self.get(mats)
        total = np.zeros(u.nnz, np.result_type(*(A.dtype for A in mats), float))
        for k, A in enumerate(mats):
            total[u.positions(k)] += A.data    # a canonical matrix has each position once
        return on_pattern(u.pattern, total)


@dataclass(frozen=True)
class SparseLinearization(Linearization):
    """A linearization of CSC blocks with R_z = M (n_z = n_q, no first-order states) whose
    iteration matrix is summed on a kept union pattern."""

    unions: UnionCache | None = None

    def iteration_matrix(self, c_q: float, c_qd: float, c_p: float, n_q: int) -> Any:
        K = self.R_q if c_q != 0.0 else None
        D = self.R_qd if c_qd != 0.0 else None
        if self.unions is None or (K is None and D is None) or self.R_p is not None:
            return super().iteration_matrix(c_q, c_qd, c_p, n_q)
        M = self.R_z
        mats = [m for m in (M, K, D) if m is not None]
        unions = self.unions
        u = unions.get(mats)
        dtype = unions.sum_dtype(mats)
        # coupled = c_q K + c_q̇ D on the union, S = M + coupled: the sums of the sparse additions
        if K is not None and D is not None and u.slots[1] is None and u.slots[2] is None:
            # both on the union pattern itself; c_q̇ D is the same every iteration of a run
            D_data = D.data
            coupled = c_q * K.data + unions.constant("c_qd D", D_data, (c_qd, u),
                                                     lambda: c_qd * D_data)
        else:
            coupled = np.zeros(u.nnz, dtype)
            k = 1
            if K is not None:
                coupled[u.positions(k)] = c_q * K.data
                k += 1
            if D is not None:
                coupled[u.positions(k)] = coupled[u.positions(k)] + c_qd * D.data
        M_data = M.data
        S = unions.constant("M", M_data, (u, dtype), lambda: u.place(M_data, 0, dtype))
        return on_pattern(u.pattern, S + coupled)
