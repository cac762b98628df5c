"""Structure of an iteration matrix, analysed once per pattern: band plans and kept orderings.

The iteration matrix of a run keeps its sparsity pattern from step to step and from Newton
iteration to Newton iteration; only its values change.  What depends on the pattern alone is
worked out once and kept, keyed by the pattern itself (compared exactly, so a plan is never
applied to a matrix it was not made for):

* :class:`BandPlan` — a symmetric permutation (reverse Cuthill–McKee for sparse matrices, the
  identity for dense ones) and the positions of the entries in LAPACK's band storage, for
  gbtrf / gbtrs when the bandwidth after reordering is small, or in the three diagonals of
  gttrf / gttrs when the matrix is tridiagonal (O(n) loops without gbtrf's BLAS call per column);
* :class:`OrderedSparsePlan` — SuperLU's column ordering of the first factorization, applied to
  the values of later ones (only the numeric factorization is repeated).

Which factorization pays is decided from break-even points measured by
``scripts/bench_linalg.py`` (constants below), not from the size alone.
"""
from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.linalg import lapack
from scipy.sparse.csgraph import reverse_cuthill_mckee

# Measured break-even points (scripts/bench_linalg.py, BENCHMARKS.md "Linear algebra that costs
# what the matrix needs"): a dense matrix is factorized as a band from DENSE_BAND_MIN_N
# unknowns on when its band (kl + ku + 1) is at most DENSE_BAND_FRACTION of n (band and dense
# LU break even near n = 48 for a tridiagonal matrix, n = 64 for a band of 9, n ≈ 200 for 129);
# a sparse one whenever its band after reordering is at most SPARSE_BAND_MAX wide (band LU
# was faster than SuperLU in every measured case up to that width, n = 8 … 10 000).
DENSE_BAND_MIN_N = 48
DENSE_BAND_FRACTION = 1 / 6
SPARSE_BAND_MAX = 129

_LAPACK: dict[tuple[str, Any], tuple[Any, Any]] = {}


def _lapack_pair(kind: str, dtype: Any) -> tuple[Any, Any]:
    """(``kind``trf, ``kind``trs) for a dtype, kind "gb" or "gt" (looked up once)."""
    key = (kind, dtype)
    if key not in _LAPACK:
        _LAPACK[key] = tuple(lapack.get_lapack_funcs((kind + "trf", kind + "trs"), dtype=dtype))
    return _LAPACK[key]


class BandPlan:
    """Band storage of a matrix with rows/columns reordered by ``perm`` (None: as they are).

    ``rows``, ``cols``: where each stored entry (CSC data order, or the row-major positions
    ``src`` of a dense matrix) goes in the (2 kl + ku + 1, n) band array; ``positions``: where it
    goes in the storage the factorization reads (the band array read flat, or the three
    diagonals of a tridiagonal matrix one after the other).
    """

    def __init__(self, n: int, i: np.ndarray, j: np.ndarray, perm: np.ndarray | None,
                 src: np.ndarray | None = None):
        self.n, self.perm, self.src = n, perm, src
        self.within: np.ndarray | None = None    # a model's pattern this band holds (dense plans)
        self.inverse: np.ndarray | None = None   # perm's inverse: row k of S is row inverse[k] here
        if perm is not None:
            self.inverse = np.empty(n, dtype=np.intp)
            self.inverse[perm] = np.arange(n)
            i, j = self.inverse[i], self.inverse[j]
        self.kl = int(max(np.max(i - j, initial=0), 0))
        self.ku = int(max(np.max(j - i, initial=0), 0))
        self.rows = self.kl + self.ku + i - j
        self.cols = j
        self.positions = self._positions(self.rows, j)

    def _positions(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Where the band entries (rows, cols) of the reordered matrix go in the storage the
        factorization reads."""
        n = self.n
        if self.tridiagonal:
            # band rows 3, 2, 1 (A[j+1, j], A[j, j], A[j−1, j]) as [sub (n−1) | main (n) | super (n−1)]
            return np.where(rows == 3, cols, np.where(rows == 2, n - 1 + cols, 2 * n - 2 + cols))
        return rows + (2 * self.kl + self.ku + 1) * cols     # the Fortran-ordered band array, read flat

    def storage_positions(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Where the entries (i, j) of S (its own order) go in the factorization's storage, as
        for the entries the plan was made of; ValueError for an entry outside the band."""
        if self.inverse is not None:
            i, j = self.inverse[i], self.inverse[j]
        if np.any(i - j > self.kl) or np.any(j - i > self.ku):
            raise ValueError("an entry outside the band")
        return self._positions(self.kl + self.ku + i - j, j)

    @property
    def width(self) -> int:
        """kl + ku + 1: the number of stored diagonals."""
        return self.kl + self.ku + 1

    @property
    def tridiagonal(self) -> bool:
        """One diagonal on each side of the main one (and more than one row)."""
        return self.kl == 1 and self.ku == 1 and self.n > 1

    def entries(self, values: np.ndarray) -> np.ndarray:
        """The stored entries, in the order of ``rows``/``cols``, of a matrix whose CSC data
        (or, with ``src``, dense array) is ``values``."""
        return values if self.src is None else values.ravel()[self.src]

    def factor(self, entries: np.ndarray) -> "BandFactor | TridiagonalFactor":
        """Factorize the matrix with the stored ``entries`` (see :meth:`entries`)."""
        if self.tridiagonal:
            return TridiagonalFactor(self, entries)
        rows = 2 * self.kl + self.ku + 1
        flat = np.zeros(rows * self.n, dtype=entries.dtype)
        flat[self.positions] = entries
        ab = flat.reshape(self.n, rows).T              # the (rows, n) band array, Fortran-ordered
        gbtrf, gbtrs = _lapack_pair("gb", ab.dtype)
        lu, piv, info = gbtrf(ab, self.kl, self.ku, overwrite_ab=1)
        return BandFactor(self, lu, piv, info, gbtrs)


class BandFactor:
    """LU of a band matrix (gbtrf); ``solve`` for real or complex (n,) or (n, k) right-hand sides,
    with S or its transpose Sᵀ (not the conjugate transpose)."""

    def __init__(self, plan: BandPlan, lu: np.ndarray, piv: np.ndarray, info: int, gbtrs: Any):
        self.plan, self.lu, self.piv, self.info, self._gbtrs = plan, lu, piv, info, gbtrs
        self.complex = lu.dtype.kind == "c"

    @property
    def nbytes(self) -> int:
        """Memory held by the factor (bytes)."""
        return int(self.lu.nbytes + self.piv.nbytes)

    def u_diagonal(self) -> np.ndarray:
        """Diagonal of U (the pivots), for the singularity test."""
        p = self.plan
        return self.lu[p.kl + p.ku]

    def solve(self, rhs: np.ndarray, transposed: bool = False) -> np.ndarray:
        """x with S x = rhs, or Sᵀ x = rhs when ``transposed``."""
        p = self.plan
        return _permuted_solve(self, rhs, transposed, lambda b: self._gbtrs(
            self.lu, p.kl, p.ku, b, self.piv, trans=int(transposed))[0])


class TridiagonalFactor:
    """LU of a tridiagonal matrix with partial pivoting (gttrf: the sub-, main and super-diagonal
    and the second super-diagonal of U that pivoting fills); the interface of :class:`BandFactor`."""

    def __init__(self, plan: BandPlan, entries: np.ndarray):
        self.plan = plan
        n = plan.n
        diagonals = np.zeros(3 * n - 2, dtype=entries.dtype)
        diagonals[plan.positions] = entries
        gttrf, self._gttrs = _lapack_pair("gt", diagonals.dtype)
        dl, d, du = diagonals[:n - 1], diagonals[n - 1:2 * n - 1], diagonals[2 * n - 1:]
        self.dl, self.d, self.du, self.du2, self.ipiv, self.info = gttrf(
            dl, d, du, overwrite_dl=1, overwrite_d=1, overwrite_du=1)
        self.complex = diagonals.dtype.kind == "c"

    @classmethod
    def from_lu(cls, plan: BandPlan, diagonals: np.ndarray, du2: np.ndarray,
                ipiv: np.ndarray) -> "TridiagonalFactor":
        """The factor of a real matrix made elsewhere by gttrf's operations (a compiled step,
        :mod:`.tridiagonal`): diagonals [dl | d | du] (3n − 2) and du2, ipiv as gttrf leaves them."""
        self = cls.__new__(cls)
        n = plan.n
        self.plan, self.info, self.complex = plan, 0, False
        self.dl, self.d, self.du = diagonals[:n - 1], diagonals[n - 1:2 * n - 1], diagonals[2 * n - 1:]
        self.du2, self.ipiv = du2, ipiv
        self._gttrs = _lapack_pair("gt", diagonals.dtype)[1]
        return self

    @property
    def nbytes(self) -> int:
        """Memory held by the factor (bytes)."""
        return int(sum(a.nbytes for a in (self.dl, self.d, self.du, self.du2, self.ipiv)))

    def u_diagonal(self) -> np.ndarray:
        """Diagonal of U (the pivots), for the singularity test."""
        return self.d

    def solve(self, rhs: np.ndarray, transposed: bool = False) -> np.ndarray:
        """x with S x = rhs, or Sᵀ x = rhs when ``transposed``."""
        return _permuted_solve(self, rhs, transposed, lambda b: self._gttrs(
            self.dl, self.d, self.du, self.du2, self.ipiv, b, trans="T" if transposed else "N")[0])


def _permuted_solve(factor: "BandFactor | TridiagonalFactor", rhs: np.ndarray, transposed: bool,
                    solve: Any) -> np.ndarray:
    """A band factor's solve with the plan's symmetric reordering around it: P S Pᵀ has the
    transpose P Sᵀ Pᵀ, so the same permutation serves both.  A complex right-hand side of a
    real factor is solved as its real and imaginary parts."""
    if np.iscomplexobj(rhs) and not factor.complex:
        return factor.solve(rhs.real, transposed) + 1j * factor.solve(rhs.imag, transposed)
    p = factor.plan
    b = rhs if p.perm is None else rhs[p.perm]
    x = solve(b.reshape(p.n, -1)).reshape(rhs.shape)
    if p.perm is None:
        return x
    out = np.empty_like(x)
    out[p.perm] = x
    return out


def dense_band_plan(S: np.ndarray, cache: dict[Any, BandPlan | None],
                    within: np.ndarray | None = None) -> BandPlan | None:
    """The band plan of a dense square matrix S if it pays (else None), kept per shape in
    ``cache`` and re-used while S has no entry outside the kept band (one count, exact).

    ``within``: flat (row-major) positions outside which S is zero by construction (a model's
    assembly pattern, the same array while it holds).  The band is then made to hold all of
    them, checked against S once, and a plan made for that array serves it without a count."""
    n = S.shape[0]
    if n < DENSE_BAND_MIN_N:
        return None
    key = (n, S.dtype.kind)
    plan = cache.get(key)
    if plan is not None and within is not None and plan.within is within:
        return plan
    nnz = np.count_nonzero(S)
    if plan is not None and np.count_nonzero(S.ravel()[plan.src]) == nnz:
        if within is not None and _holds(plan, within, S, nnz):
            plan.within = within
        return plan
    i, j = np.nonzero(S)
    if within is not None:
        # the positions that may be nonzero later too (S's own are among them, checked below)
        i, j = np.concatenate([i, within // n]), np.concatenate([j, within % n])
    lower = int(np.max(i - j, initial=0))
    upper = int(np.max(j - i, initial=0))
    if lower + upper + 1 > DENSE_BAND_FRACTION * n:
        cache.pop(key, None)
        return None
    # every position of the band (entries that are zero now may not be later)
    d = np.arange(-lower, upper + 1)
    jj = (np.arange(n)[None, :] + 0 * d[:, None])
    ii = jj - d[:, None]
    ok = (ii >= 0) & (ii < n)
    ii, jj = ii[ok], jj[ok]
    plan = BandPlan(n, ii, jj, None, src=ii * n + jj)
    if within is not None and _holds(plan, within, S, nnz):
        plan.within = within
    cache[key] = plan
    return plan


def _holds(plan: BandPlan, within: np.ndarray, S: np.ndarray, nnz: Any) -> bool:
    """Whether every flat position of ``within`` lies in the (unpermuted) band of ``plan`` and
    S (nnz nonzeros) has none outside ``within`` (the model's claim, checked on this S)."""
    i, j = within // plan.n, within % plan.n
    return bool(np.all(i - j <= plan.kl) and np.all(j - i <= plan.ku)
                and np.count_nonzero(S.ravel()[within]) == nnz)


class SparsePlan:
    """What the pattern of a sparse (CSC, canonical) matrix decides, worked out once: a band
    plan after reverse Cuthill–McKee when the band is narrow, else SuperLU's column order."""

    def __init__(self, S: sp.csc_matrix):
        self.indptr, self.indices = S.indptr.copy(), S.indices.copy()
        self._seen: tuple[Any, Any] = (None, None)     # the index arrays of the last match
        n = S.shape[0]
        self.n = n
        j = np.repeat(np.arange(n), np.diff(S.indptr))
        i = S.indices
        # the symmetric pattern S + Sᵀ orders rows and columns alike
        sym = sp.csr_matrix((np.ones(i.size), (i, j)), shape=(n, n))
        perm = reverse_cuthill_mckee((sym + sym.T).tocsr(), symmetric_mode=True).astype(np.intp)
        band = BandPlan(n, i, j, perm)
        self.band = band if band.width <= SPARSE_BAND_MAX else None
        # SuperLU's column order from the first factorization: (order, data gather, pattern of
        # S[:, order]), set once as a whole and only read afterwards (runs may share a plan)
        self._kept: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None

    def matches(self, S: sp.csc_matrix) -> bool:
        """Whether S has exactly this plan's pattern (recognised at once when S shares the
        never-modified index arrays of the last matrix that matched, as a model's matrices on a
        kept pattern do)."""
        if S.indptr is self._seen[0] and S.indices is self._seen[1]:
            return True
        same = (S.indptr.size == self.indptr.size and S.indices.size == self.indices.size
                and np.array_equal(S.indptr, self.indptr) and np.array_equal(S.indices, self.indices))
        if same:
            self._seen = (S.indptr, S.indices)
        return same

    def superlu(self, S: sp.csc_matrix) -> Any:
        """SuperLU of S; from the second call on with the kept column order (no ordering step)."""
        kept = self._kept
        if kept is None:
            lu = spla.splu(S)
            order = np.argsort(lu.perm_c)            # new column k is old column order[k]
            tag = sp.csc_matrix((np.arange(S.nnz, dtype=float), S.indices, S.indptr), shape=S.shape)
            P = tag[:, order]
            self._kept = (order, P.data.astype(np.intp), P.indices.copy(), P.indptr.copy())
            return lu
        order, gather, indices, indptr = kept
        Pm = sp.csc_matrix((S.data[gather], indices, indptr), shape=S.shape)
        return _ColumnPermutedLU(spla.splu(Pm, permc_spec="NATURAL"), order)


class _ColumnPermutedLU:
    """SuperLU of S[:, order] answering for S: x[order] = y; for Sᵀ, whose rows are permuted
    instead, the right-hand side is taken in that order: (S[:, order])ᵀ x = rhs[order]."""

    def __init__(self, lu: Any, order: np.ndarray):
        self.lu, self.order = lu, order

    @property
    def U(self) -> Any:
        """U of the column-permuted matrix (its diagonal: the pivots)."""
        return self.lu.U

    @property
    def L(self) -> Any:
        """L of the column-permuted matrix."""
        return self.lu.L

    def solve(self, rhs: np.ndarray, trans: str = "N") -> np.ndarray:
        """x with S x = rhs (``trans`` "N") or Sᵀ x = rhs ("T"), as SuperLU's own ``solve``."""
        if trans == "T":
            return self.lu.solve(np.ascontiguousarray(rhs[self.order]), trans="T")
        y = self.lu.solve(rhs)
        x = np.empty_like(y)
        x[self.order] = y
        return x


def sparse_plan(S: sp.csc_matrix, cache: dict[Any, list[SparsePlan]]) -> SparsePlan:
    """The kept plan of S's pattern (made on first sight)."""
    key = (S.shape[0], S.nnz)
    for plan in cache.get(key, []):
        if plan.matches(S):
            return plan
    plan = SparsePlan(S)
    cache.setdefault(key, []).append(plan)
    # a run sees one or two patterns (t0 and the steps): keep the few most recent ones
    while sum(len(v) for v in cache.values()) > 4:
        oldest = next(iter(cache))
        cache[oldest].pop(0)
        if not cache[oldest]:
            del cache[oldest]
    return plan
