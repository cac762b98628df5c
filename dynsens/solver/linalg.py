"""Factorizations of the iteration matrix: one factor, many right-hand sides.

Dense LU (LAPACK getrf), band LU (LAPACK gbtrf) or sparse LU (SuperLU via ``splu``).  The
model's traits say whether S comes dense or sparse; what its pattern then allows is analysed
once per pattern (:mod:`.banded`): a sparse matrix whose band after reverse Cuthill–McKee is
narrow, or a dense one with a narrow band, is factorized as a band; other sparse matrices by
SuperLU with the column ordering of the first factorization kept.  A diagonal matrix needs
no factorization at all: it is inverted elementwise (lumped masses, the initial-acceleration
solve of spring-mass systems).  The m sensitivity right-hand sides go to one solve call.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from ._jit import register_jitable
from .banded import BandFactor, TridiagonalFactor, dense_band_plan, sparse_plan

# plans kept per pattern (see .banded): the structure of S is analysed once per run
_DENSE_PLANS: dict[Any, Any] = {}
_SPARSE_PLANS: dict[Any, Any] = {}


class SingularMatrixError(ArithmeticError):
    """The iteration matrix is singular (or numerically so)."""


@dataclass
class Counters:
    """Work counters reported with every run (what was done, and so what was left out).

    ``factorizations`` counts every factorization (diagonal ones included, see
    ``diagonal_inversions``); ``step_factorizations`` only those of the time-step iteration
    matrix, i.e. without the initial-acceleration solve at t0.  The ``backward_*`` counters
    are the adjoint sweep's transposed solves, residual evaluations of its design partials and
    output evaluations of its seeds; ``recomputed_steps`` the steps its checkpointing re-ran.
    """

    steps: int = 0
    newton_iterations: int = 0
    residual_evaluations: int = 0
    linearizations: int = 0
    factorizations: int = 0
    step_factorizations: int = 0
    diagonal_inversions: int = 0
    solves: int = 0
    solve_columns: int = 0
    sensitivity_residual_evaluations: int = 0
    output_evaluations: int = 0
    step_cuts: int = 0
    backward_solves: int = 0
    backward_residual_evaluations: int = 0
    backward_output_evaluations: int = 0
    recomputed_steps: int = 0
    extra: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, int]:
        """Plain mapping of the counters (for reports and HDF5 attributes)."""
        d = {k: v for k, v in self.__dict__.items() if k != "extra"}
        d.update(self.extra)
        return d


# smallest |pivot| relative to the largest of a factor judged regular
PIVOT_RATIO = 1e-14


@register_jitable
def all_finite(a: np.ndarray) -> bool:
    """Whether every entry of a is finite: one reduction first (a NaN or Inf entry makes the sum
    non-finite; so may an overflowing sum of finite entries: then the entries are looked at)."""
    return bool(np.isfinite(a.sum())) or bool(np.all(np.isfinite(a)))


@register_jitable
def pivot_test(udiag: np.ndarray) -> tuple[bool, float]:
    """(whether the factor with U's diagonal udiag (not empty) is regular, min |pivot| / max
    |pivot|): regular when the ratio exceeds PIVOT_RATIO."""
    a = np.abs(udiag)
    lo, scale = a.min(), a.max()
    return not (lo <= PIVOT_RATIO * scale or scale == 0.0), lo / max(scale, 1e-300)


class Factor:
    """A factorized square matrix; ``solve(rhs)`` for rhs (n,) or (n, k).

    ``dense_general`` skips the test for a diagonal matrix: a caller that has seen the
    structure of its matrices (a dense, non-diagonal iteration matrix stays one) says so.
    ``within``: the flat positions outside which a dense S is zero by construction
    (:attr:`~dynsens.models.base.Linearization.dense_pattern`), for the band test.
    """

    # getrf's (lu, piv) as a compiled step returned them: lu row-major (the transpose of the
    # column-major factor), piv 1-based int32 (None: not made by a compiled step)
    _from_compiled: tuple[np.ndarray, np.ndarray] | None = None

    def __init__(self, S: Any, counters: Counters, dense_general: bool = False,
                 within: np.ndarray | None = None):
        self.counters = counters
        self.n = S.shape[0]
        self._lu: Any = None   # the factor: of the kind below
        counters.factorizations += 1
        plan = None
        is_sparse = sp.issparse(S)
        if is_sparse and not dense_general:
            S = S if S.format == "csc" and S.has_canonical_format else sp.csc_matrix(S)
            plan = sparse_plan(S, _SPARSE_PLANS)
            # only a matrix of band width 1 can be diagonal
            diag = _diagonal_or_none(S) if plan.band is not None and plan.band.width == 1 else None
        else:
            diag = None if dense_general else _diagonal_or_none(S)
        if diag is not None:
            # a diagonal matrix is its own factorization: invert elementwise
            if np.any(diag.real == 0.0) or not np.all(np.isfinite(diag)):
                raise SingularMatrixError("zero on the diagonal")
            self._kind = "diag"
            self._inv = 1.0 / diag
            counters.diagonal_inversions += 1
            return
        band = None
        if plan is not None:
            band = plan.band
        elif not is_sparse:
            band = dense_band_plan(S, _DENSE_PLANS, within)
        if band is not None:
            # the stored entries (a dense S has every nonzero, NaN and Inf too, inside its band)
            entries = band.entries(S.data if plan is not None else S)
            if not all_finite(entries):
                raise SingularMatrixError("matrix has non-finite entries")
            self._kind = "banded"
            self._lu = band.factor(entries)
            if self._lu.info > 0:
                raise SingularMatrixError(f"exactly zero pivot in column {self._lu.info}")
            udiag = self._lu.u_diagonal()
        elif plan is not None:
            self._kind = "sparse"
            try:
                self._lu = plan.superlu(S)
            except RuntimeError as exc:  # SuperLU reports exact singularity this way
                raise SingularMatrixError(str(exc)) from None
            udiag = self._lu.U.diagonal()
        else:
            self._kind = "dense"
            if not all_finite(S):
                raise SingularMatrixError("matrix has non-finite entries")
            # LAPACK getrf/getrs directly: scipy's lu_factor/lu_solve wrappers cost more
            # than the factorization itself for the small matrices of mechanisms
            getrf, self._getrs = _lapack(S.dtype)
            lu, piv, info = getrf(S)
            if info > 0:
                raise SingularMatrixError(f"exactly zero pivot in column {info}")
            self._lu = (lu, piv)
            self._complex = lu.dtype.kind == "c"
            udiag = lu.diagonal()
        if udiag.size:
            regular, ratio = pivot_test(udiag)
            if not regular:
                raise SingularMatrixError(f"pivot ratio {ratio:.1e}")

    @classmethod
    def from_compiled_lu(cls, lu_rows: np.ndarray, piv: np.ndarray, counters: Counters) -> "Factor":
        """The factor of a dense real matrix factored by a compiled step (it counts its
        factorizations itself): LAPACK getrf's lu stored row by row (its transpose, C order)
        and 1-based int32 piv, as the compiled step returned them."""
        self = cls.__new__(cls)
        self.counters, self.n = counters, lu_rows.shape[0]
        self._kind, self._complex = "dense", False
        _, self._getrs = _lapack(lu_rows.dtype)
        self._lu = (lu_rows.T, piv - 1)
        self._from_compiled = (lu_rows, piv)
        return self

    @classmethod
    def from_band(cls, lu: BandFactor | TridiagonalFactor, counters: Counters) -> "Factor":
        """The factor of a band matrix factored elsewhere (a compiled step; it counts its
        factorizations itself)."""
        self = cls.__new__(cls)
        self.counters, self.n = counters, lu.plan.n
        self._kind, self._lu = "banded", lu
        return self

    @property
    def nbytes(self) -> int:
        """Memory held by the factor (bytes; SuperLU's: 12 per entry of L and U)."""
        if self._kind == "diag":
            return int(self._inv.nbytes)
        if self._kind == "banded":
            return self._lu.nbytes
        if self._kind == "sparse":
            return 12 * int(self._lu.L.nnz + self._lu.U.nnz)
        return int(self._lu[0].nbytes)

    @property
    def kind(self) -> str:
        """``diag``, ``dense``, ``banded`` or ``sparse``: how S was factorized."""
        return self._kind

    @property
    def dense_real_lu(self) -> tuple[np.ndarray, np.ndarray] | None:
        """LAPACK getrf's (lu (n, n), column-major; piv (n,), 0-based) of a dense real S (float64);
        None for another kind or dtype."""
        if self._kind != "dense" or self._complex or self._lu[0].dtype != np.float64:
            return None
        return self._lu  # type: ignore[no-any-return]

    @property
    def tridiagonal_real(self) -> TridiagonalFactor | None:
        """The :class:`~.banded.TridiagonalFactor` (gttrf's LU of the reordered S) of a real S
        factored as a tridiagonal band; None for another kind or dtype."""
        lu = self._lu if self._kind == "banded" else None
        if not isinstance(lu, TridiagonalFactor) or lu.complex or lu.d.dtype != np.float64:
            return None
        return lu

    @property
    def compiled_lu(self) -> tuple[np.ndarray, np.ndarray] | None:
        """:attr:`dense_real_lu` in a compiled step's form: lu row by row (C order), piv 1-based
        int32 (the arrays the compiled step returned, when it made this factor)."""
        if self._from_compiled is not None:
            return self._from_compiled
        lu = self.dense_real_lu
        return None if lu is None else (lu[0].T, (lu[1] + 1).astype(np.int32))

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve S x = rhs; rhs (n,) or (n, k), real or complex."""
        self.counters.solves += 1
        self.counters.solve_columns += 1 if rhs.ndim == 1 else rhs.shape[1]
        if self._kind == "diag":
            return rhs * (self._inv if rhs.ndim == 1 else self._inv[:, None])
        if self._kind == "banded":
            return self._lu.solve(rhs)
        if self._kind == "sparse":
            if np.iscomplexobj(rhs) and not np.iscomplexobj(self._lu.U.data):
                return self._lu.solve(np.ascontiguousarray(rhs.real)) + \
                    1j * self._lu.solve(np.ascontiguousarray(rhs.imag))
            return self._lu.solve(np.asarray(rhs))
        lu, piv = self._lu
        if np.iscomplexobj(rhs) and not self._complex:
            return self._getrs(lu, piv, rhs.real)[0] + 1j * self._getrs(lu, piv, rhs.imag)[0]
        x, info = self._getrs(lu, piv, rhs)
        return x

    def solve_transposed(self, rhs: np.ndarray) -> np.ndarray:
        """Solve Sᵀ x = rhs (transpose, not conjugate transpose) with the same factor; rhs (n,)
        or (n, k), real or complex (the adjoint sweep's solves)."""
        self.counters.solves += 1
        self.counters.solve_columns += 1 if rhs.ndim == 1 else rhs.shape[1]
        if self._kind == "diag":
            return rhs * (self._inv if rhs.ndim == 1 else self._inv[:, None])
        if self._kind == "banded":
            return self._lu.solve(rhs, transposed=True)
        if self._kind == "sparse":
            if np.iscomplexobj(rhs) and not np.iscomplexobj(self._lu.U.data):
                return self._lu.solve(np.ascontiguousarray(rhs.real), trans="T") + \
                    1j * self._lu.solve(np.ascontiguousarray(rhs.imag), trans="T")
            return self._lu.solve(np.asarray(rhs), trans="T")
        lu, piv = self._lu
        if np.iscomplexobj(rhs) and not self._complex:
            return self._getrs(lu, piv, rhs.real, trans=1)[0] + 1j * self._getrs(lu, piv, rhs.imag, trans=1)[0]
        x, info = self._getrs(lu, piv, rhs, trans=1)
        return x


def abs_product(S: Any, v: np.ndarray) -> np.ndarray:
    """|Re S| v (n,) for a square matrix S, dense or sparse, and a real vector v (n,): the terms
    a residual's round-off is measured against.  For a CSC matrix the sums are those of scipy's
    product, entry by entry in the same (column) order, taken by one bincount instead of through
    the two intermediate matrices Re S and |Re S| (which cost more than the product at a
    thousand unknowns)."""
    if not sp.issparse(S) or S.format != "csc":
        return abs(S.real) @ v
    return np.bincount(S.indices, np.abs(S.data.real) * v[_entry_columns(S.indptr)], S.shape[0])


_COLUMNS: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []   # the last indptr, a copy, entry columns


def _entry_columns(indptr: np.ndarray) -> np.ndarray:
    """The column of every stored entry of a CSC matrix with column pointers ``indptr``
    (a run's iteration matrices share one pattern: the last one is kept)."""
    kept = _COLUMNS[-1] if _COLUMNS else None      # read once: never another caller's triple
    # the same (never modified) array a model's assembly hands with every matrix, or equal to it
    if kept is not None and (indptr is kept[0] or np.array_equal(kept[1], indptr)):
        return kept[2]
    cols = np.repeat(np.arange(indptr.size - 1), np.diff(indptr))
    _COLUMNS[:] = [(indptr, indptr.copy(), cols)]
    return cols


_LAPACK: dict[Any, tuple[Any, Any]] = {}


def _lapack(dtype: Any) -> tuple[Any, Any]:
    """getrf, getrs for a dtype (looked up once: the lookup costs as much as a small solve)."""
    if dtype not in _LAPACK:
        _LAPACK[dtype] = tuple(sla.lapack.get_lapack_funcs(("getrf", "getrs"), dtype=dtype))
    return _LAPACK[dtype]


def _diagonal_or_none(S: Any) -> np.ndarray | None:
    if sp.issparse(S):
        S = sp.csr_matrix(S)
        if S.nnz <= S.shape[0]:
            d = S.diagonal()
            if np.count_nonzero(d) == S.nnz:
                return d
        return None
    S = np.asarray(S)
    if S.shape[0] == 1:
        return S[0].copy()
    d = np.diagonal(S)
    if np.count_nonzero(S) == np.count_nonzero(d):
        return d.copy()
    return None
