"""The compiled CSC products (dynsens.solver.sparse_products) against scipy's, bit for bit, and
the adjoint sweep that uses them: its transposed products and its blocks of design terms.

Neither side calls BLAS: scipy's csc_matvecs / csr_matvecs and the compiled loops add the same
products in the same order, so the results are identical on every installation.
"""
from __future__ import annotations

import os

import numpy as np
import pytest
import scipy.sparse as sp

import dynsens
import scripts_path  # noqa: F401  (puts scripts/ on the path)
from bench_peers import chain_case
from dynsens.derivatives import adjoint_step, partials
from dynsens.solver import sparse_products
from dynsens.solver._jit import enabled, jit

compiled_only = pytest.mark.skipif(
    not enabled(), reason=f"DYNSENS_KERNEL={os.environ.get('DYNSENS_KERNEL')}: no compiled code")


def _matrix(rng: np.random.Generator, n_rows: int, n_cols: int, canonical: bool) -> sp.csc_matrix:
    """A random CSC matrix; not ``canonical``: unsorted row indices and duplicate entries,
    which scipy's products take in the order stored."""
    nnz = 4 * max(n_rows, n_cols)
    i, j = rng.integers(0, n_rows, nnz), rng.integers(0, n_cols, nnz)
    A = sp.csc_matrix((rng.standard_normal(nnz), (i, j)), shape=(n_rows, n_cols))
    if canonical:
        return A
    # the same columns, each column's entries reversed, one entry stored twice
    data, indices, indptr = [], [], [0]
    for c in range(n_cols):
        lo, hi = A.indptr[c], A.indptr[c + 1]
        rows, vals = list(A.indices[lo:hi][::-1]), list(A.data[lo:hi][::-1])
        if rows:
            rows.append(rows[0])
            vals.append(0.5 * vals[0])
        indices += rows
        data += vals
        indptr.append(len(indices))
    B = sp.csc_matrix((np.array(data), np.array(indices), np.array(indptr)), shape=(n_rows, n_cols))
    assert not B.has_canonical_format
    return B


@compiled_only
@pytest.mark.parametrize("canonical", [True, False])
@pytest.mark.parametrize("n, m", [(1, 1), (17, 3), (400, 5)])
def test_the_compiled_products_equal_scipys(n, m, canonical):
    rng = np.random.default_rng(n + 7 * m + canonical)
    A = _matrix(rng, n, n, canonical)
    x = rng.standard_normal((n, m))
    times, transposed = jit(sparse_products.csc_times), jit(sparse_products.csc_transpose_times)
    np.testing.assert_array_equal(times(A.data, A.indptr, A.indices, x), A @ x)
    np.testing.assert_array_equal(transposed(A.data, A.indptr, A.indices, x), A.T @ x)
    np.testing.assert_array_equal(sparse_products.transpose_times(A, x), A.T @ x)


@compiled_only
def test_a_rectangular_transposed_product_and_a_wrong_entry():
    rng = np.random.default_rng(3)
    A = _matrix(rng, 30, 12, canonical=True)
    x = rng.standard_normal((30, 2))
    got = sparse_products.transpose_times(A, x)
    assert got.shape == (12, 2)
    np.testing.assert_array_equal(got, A.T @ x)
    A.data[4] *= 1.0 + 1e-12            # the comparison can fail
    assert not np.array_equal(sparse_products.transpose_times(A, x), got)


def test_what_the_compiled_transposed_product_does_not_take(monkeypatch):
    """A dense or complex operand, or compiled code switched off: scipy's and numpy's product."""
    rng = np.random.default_rng(4)
    A = _matrix(rng, 8, 8, canonical=True)
    x = rng.standard_normal((8, 2))
    np.testing.assert_array_equal(sparse_products.transpose_times(A.toarray(), x), A.toarray().T @ x)
    xc = x + 1j * rng.standard_normal((8, 2))
    np.testing.assert_array_equal(sparse_products.transpose_times(A, xc), A.T @ xc)
    monkeypatch.setenv("DYNSENS_KERNEL", "numpy")
    calls = []
    monkeypatch.setattr(sparse_products, "csc_transpose_times", lambda *a: calls.append(a))
    np.testing.assert_array_equal(sparse_products.transpose_times(A, x), A.T @ x)
    assert calls == []


def _per_element_chain(n: int, steps: int) -> dynsens.case.load.Case:
    """The benchmark's chain with one stiffness per spring (m = n), sparse storage, by the adjoint."""
    d = chain_case(n, steps * 1e-3, per_element=True)
    d["responses"] = [r for r in d["responses"] if r["name"] == "tip_end"]
    d["sensitivity"]["method"] = "adjoint"
    return dynsens.load_case_dict(d)


@compiled_only
def test_the_adjoint_with_compiled_products_equals_scipys_bit_for_bit(monkeypatch):
    case = _per_element_chain(150, 60)
    sparse_operands: list[bool] = []
    original = adjoint_step.transpose_times       # (the Python steps' and the initial solve's)
    monkeypatch.setattr(adjoint_step, "transpose_times", lambda A, x: sparse_operands.append(sp.isspmatrix_csc(A))
                        or original(A, x))
    compiled = dynsens.run_case(case, sensitivities=True, history=())
    assert sparse_operands and all(sparse_operands)        # the compiled product ran
    monkeypatch.setattr(adjoint_step, "transpose_times", lambda A, x: A.T @ x)
    python = dynsens.run_case(case, sensitivities=True, history=())
    for name, r in compiled.responses.items():
        assert r.value == python.responses[name].value
        np.testing.assert_array_equal(r.gradient, python.responses[name].gradient)


def test_the_adjoint_takes_the_design_terms_of_several_records_in_one_call(monkeypatch):
    """m = 150 design variables on a 150-mass chain: the sweep's batched residual call holds
    one residual per parameter set of the batch (a handful, by colouring), not m columns, so
    it takes the records in blocks, not one by one (one by one cost 0.2 s of a 1.3 s adjoint
    run at m = N = 1000, BENCHMARKS.md)."""
    case = _per_element_chain(150, 60)
    calls: list[int] = []
    original = partials.DesignPartials.residual_partials_transposed_steps

    def counted(self, ts, states, mus):  # type: ignore[no-untyped-def]
        calls.append(len(ts))
        return original(self, ts, states, mus)
    monkeypatch.setattr(partials.DesignPartials, "residual_partials_transposed_steps", counted)
    run = dynsens.run_case(case, sensitivities=True, history=())
    assert run.method == "adjoint"
    assert sum(calls) == run.counters["steps"] + 1
    assert max(calls) == 8 and len(calls) <= (sum(calls) + 7) // 8 + 1
