"""Factorizations chosen from the matrix's structure (dynsens/solver/banded.py): band LU for
narrow bands (dense input, or sparse after reverse Cuthill–McKee), SuperLU with a kept column
order otherwise; every kind solves to round-off, a kept plan is never applied to another
pattern, and a whole run gives the numbers of the dense factorization to round-off."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import dynsens.solver.banded as banded
from dynsens.solver.linalg import Counters, Factor, SingularMatrixError

import scripts_path  # noqa: F401
import yardstick_chain as ys


def _band(n: int, w: int, seed: int = 0) -> sp.csc_matrix:
    rng = np.random.default_rng(seed)
    A = sp.diags([rng.standard_normal(n - abs(d)) for d in range(-w, w + 1)], list(range(-w, w + 1)))
    return sp.csc_matrix(A + sp.identity(n) * (2.0 * w + 1.0))


def _residual(S, x, b) -> float:
    return float(np.max(np.abs(S @ x - b)) / np.max(np.abs(b)))


@pytest.mark.parametrize("dtype", [float, complex])
def test_dense_band_matrix_is_factorized_as_band(dtype) -> None:
    A = _band(100, 2).toarray().astype(dtype)
    if dtype is complex:
        A = A + 1j * np.diag(np.ones(100))
    rng = np.random.default_rng(1)
    f = Factor(A, Counters())
    assert f.kind == "banded"
    for b in (rng.standard_normal(100), rng.standard_normal((100, 4)) + 1j * rng.standard_normal((100, 4))):
        x = f.solve(b)
        assert x.shape == b.shape and _residual(A, x, b) < 1e-14
        assert np.allclose(x, np.linalg.solve(A, b), rtol=1e-12, atol=0)


def test_dense_matrix_leaving_the_kept_band_is_factorized_dense() -> None:
    A = _band(100, 1).toarray()
    assert Factor(A, Counters()).kind == "banded"
    B = A.copy()
    B[0, 60] = 0.5                     # same size, an entry far outside the kept band
    f = Factor(B, Counters())
    assert f.kind == "dense"
    b = np.arange(1.0, 101.0)
    assert _residual(B, f.solve(b), b) < 1e-14
    assert Factor(A, Counters()).kind == "banded"
    small = _band(20, 1).toarray()     # below the measured break-even: dense
    assert Factor(small, Counters()).kind == "dense"


def test_sparse_permuted_band_is_reordered_and_factorized_as_band() -> None:
    n = 400
    p = np.random.default_rng(2).permutation(n)
    A = sp.csc_matrix(_band(n, 1)[p][:, p])          # a tridiagonal matrix, scrambled
    f = Factor(A, Counters())
    assert f.kind == "banded" and f._lu.plan.width <= 5
    b = np.random.default_rng(3).standard_normal((n, 3)) * (1 + 1j)
    assert _residual(A, f.solve(b), b) < 1e-14


def test_sparse_wide_pattern_keeps_superlu_column_order_across_values() -> None:
    n = 300
    pattern = sp.random(n, n, density=0.03, random_state=4, format="csc")
    A = sp.csc_matrix(pattern + sp.identity(n) * 10.0)
    rng = np.random.default_rng(5)
    for _ in range(3):                                 # new values, same pattern
        S = A.copy()
        S.data = S.data * (1.0 + rng.random(S.nnz))
        f = Factor(S, Counters())
        assert f.kind == "sparse"
        b = rng.standard_normal(n)
        assert _residual(S, f.solve(b), b) < 1e-13
    # same size and count of entries, another pattern: a new plan, not the kept one
    other = sp.csc_matrix(sp.random(n, n, density=0.03, random_state=6, format="csc") + sp.identity(n) * 10.0)
    other.data[:] = 1.0
    other = other + sp.identity(n) * 9.0
    f = Factor(other, Counters())
    b = rng.standard_normal(n)
    assert _residual(other, f.solve(b), b) < 1e-13


@pytest.mark.parametrize("dtype", [float, complex])
@pytest.mark.parametrize("storage", ["dense", "sparse"])
def test_tridiagonal_matrix_is_factorized_by_gttrf(dtype, storage) -> None:
    """A tridiagonal matrix (dense, or sparse and scrambled) goes to gttrf / gttrs: solves with S
    and with Sᵀ (not the conjugate transpose), one or several right-hand sides, real or complex,
    against numpy's dense solve; pivoting happens (small diagonal entries)."""
    n = 120
    rng = np.random.default_rng(7)
    A = sp.diags([rng.standard_normal(n - 1), 0.1 * rng.standard_normal(n), rng.standard_normal(n - 1)],
                 [-1, 0, 1]).toarray().astype(dtype)
    if dtype is complex:
        A = A + 1j * np.diag(rng.standard_normal(n))
    S: object = A
    if storage == "sparse":
        p = rng.permutation(n)
        S = sp.csc_matrix(A[p][:, p])
        A = A[p][:, p]
    f = Factor(S, Counters())
    assert f.kind == "banded" and isinstance(f._lu, banded.TridiagonalFactor)
    assert np.any(f._lu.ipiv != np.arange(1, n + 1))      # rows were swapped
    for b in (rng.standard_normal(n), rng.standard_normal((n, 3)) + 1j * rng.standard_normal((n, 3))):
        x = f.solve(b)
        assert x.shape == b.shape
        assert np.allclose(x, np.linalg.solve(A, b), rtol=1e-11, atol=0)
        xt = f.solve_transposed(b)
        assert np.allclose(xt, np.linalg.solve(A.T, b), rtol=1e-11, atol=0)
    assert f.nbytes > 0


def test_singular_tridiagonal_matrix_is_an_error() -> None:
    A = _band(100, 1).toarray()
    A[:, 40] = 0.0                                         # a zero column: an exactly zero pivot
    with pytest.raises(SingularMatrixError):
        Factor(A, Counters())
    A = _band(100, 1).toarray()
    A[40, 39] = A[41, 42] = 0.0
    A[40, 40:42] = A[41, 40:42] = [0.3, 0.7]              # two equal rows inside the band
    plan = banded.dense_band_plan(A, {})
    assert plan is not None and plan.tridiagonal
    with pytest.raises(SingularMatrixError):
        Factor(A, Counters())


@pytest.mark.parametrize("where", [(50, 51), (50, 90)])
def test_non_finite_entry_of_a_dense_band_matrix_is_an_error(where) -> None:
    """Inside the kept band, or far outside it (the band then no longer holds the matrix)."""
    A = _band(100, 1).toarray()
    assert Factor(A, Counters()).kind == "banded"
    for bad in (np.nan, np.inf):
        B = A.copy()
        B[where] = bad
        with pytest.raises(SingularMatrixError):
            Factor(B, Counters())


def test_singular_band_matrix_is_an_error() -> None:
    A = _band(100, 1).toarray()
    A[50, :] = 0.0
    with pytest.raises(SingularMatrixError):
        Factor(A, Counters())
    S = sp.csc_matrix(_band(400, 1))
    S = S.tolil()
    S[7, 6] = S[7, 8] = 0.0
    S[7, 7] = 1e-300
    with pytest.raises(SingularMatrixError):
        Factor(sp.csc_matrix(S), Counters())


@pytest.mark.parametrize("n", [100, 400])
def test_chain_run_on_band_factorization_matches_dense_and_sparse(n, monkeypatch) -> None:
    """The chain's responses and gradients (complex partials, exact to round-off) with band LU
    against the factorization used before (dense LU at N = 100, SuperLU at N = 400): 1e-12."""
    import dynsens
    case = ys.dynsens_case(n, 150, "complex")
    res = dynsens.run_case(case, sensitivities=True, history=())
    monkeypatch.setattr(banded, "DENSE_BAND_MIN_N", 10 ** 9)
    monkeypatch.setattr(banded, "SPARSE_BAND_MAX", 0)
    monkeypatch.setattr("dynsens.solver.linalg._SPARSE_PLANS", {})
    monkeypatch.setattr("dynsens.solver.linalg._DENSE_PLANS", {})
    ref = dynsens.run_case(ys.dynsens_case(n, 150, "complex"), sensitivities=True, history=())
    for name, r in ref.responses.items():
        a = res.responses[name]
        assert abs(a.value - r.value) <= 1e-13 * abs(r.value)
        assert np.max(np.abs(a.gradient - r.gradient)) <= 1e-12 * np.max(np.abs(r.gradient))
    assert res.counters["factorizations"] == ref.counters["factorizations"]


def test_a_models_pattern_lets_the_band_plan_skip_the_scan_only_when_it_holds(monkeypatch) -> None:
    """A dense matrix with the positions its model can fill (``within``): the band is made to hold
    them and, once S is seen inside them, the plan serves that array without counting S's
    nonzeros; a pattern that S leaves (a wrong claim) or a new array is checked again."""
    n = 100
    A = _band(n, 1).toarray()
    A[5, 6] = 0.0                                         # zero now, inside the model's pattern
    i, j = np.nonzero(_band(n, 1).toarray())
    within = np.unique(i * n + j)
    cache: dict = {}
    plan = banded.dense_band_plan(A, cache, within)
    assert plan is not None and plan.within is within and plan.tridiagonal
    counted = []
    monkeypatch.setattr(banded.np, "count_nonzero", lambda *a, **k: counted.append(1) or np.sum(np.asarray(a[0]) != 0))
    assert banded.dense_band_plan(A, cache, within) is plan and not counted
    assert banded.dense_band_plan(A, cache, within.copy()) is plan and counted   # another array: checked
    monkeypatch.undo()
    # a claim that S contradicts: an entry outside the claimed positions is seen, no vouching
    B = A.copy()
    B[0, 60] = 0.5
    narrow = np.unique(np.r_[within, 0])                  # (0, 0) is already in the band
    cache = {}
    assert banded.dense_band_plan(B, cache, narrow) is None   # B's band is too wide: dense LU
    f = Factor(B, Counters(), within=narrow)
    assert f.kind == "dense"
    b = np.arange(1.0, n + 1.0)
    assert _residual(B, f.solve(b), b) < 1e-14
    C = A.copy()
    C[10, 12] = 0.25                                      # inside a band of width 2, outside `within`
    cache = {}
    plan = banded.dense_band_plan(C, cache, within)
    assert plan is not None and plan.within is None       # built, but not trusted for `within`
    x = Factor(C, Counters(), within=within).solve(b)
    assert _residual(C, x, b) < 1e-14
