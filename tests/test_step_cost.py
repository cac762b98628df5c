"""The shortcuts that cut a step's cost give the numbers of the plain forms they replace, bit
for bit: the element maps with their transpose kept (x @ G), the round-off terms |Re S| |z|
summed entry by entry, the spring state a residual leaves for the tangent at the same state,
and the iteration matrix on a union pattern its blocks share."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import dynsens
from dynsens.models.base import Linearization, StepState
from dynsens.models.sparse_assembly import RightProduct
from dynsens.solver.linalg import abs_product

from scripts_path import duffing_chain


def _random_csc(n: int, density: float, rng: np.random.Generator, complex_: bool = False) -> sp.csc_matrix:
    A = sp.random(n, n, density=density, format="csc", random_state=rng) + sp.eye(n, format="csc")
    if complex_:
        A = A + 1j * sp.random(n, n, density=density, format="csc", random_state=rng)
    return sp.csc_matrix(A)


@pytest.mark.parametrize("sparse", [True, False])
def test_right_product_equals_matmul_bitwise(sparse: bool) -> None:
    rng = np.random.default_rng(0)
    G = sp.random(40, 25, density=0.1, format="csr", random_state=rng)
    G = G if sparse else G.toarray()
    prod = RightProduct(G)
    for shape in ((40,), (3, 40), (2, 3, 40)):
        for x in (rng.standard_normal(shape), rng.standard_normal(shape) + 1e-20j * rng.standard_normal(shape)):
            ref = x @ G if x.ndim <= 2 or not sparse else (x.reshape(-1, 40) @ G).reshape(shape[:-1] + (25,))
            assert np.array_equal(prod(x), ref), shape
    back = prod.transposed()
    y = rng.standard_normal(25)
    assert np.array_equal(back(y), y @ G.T)
    cols = np.array([3, 7, 11])
    x = rng.standard_normal(40)
    assert np.array_equal(prod.columns(cols)(x), x @ G[:, cols])


@pytest.mark.parametrize("complex_", [False, True])
def test_abs_product_equals_scipy_product_bitwise(complex_: bool) -> None:
    rng = np.random.default_rng(1)
    for n in (5, 60, 300):
        S = _random_csc(n, 0.05, rng, complex_)
        v = np.abs(rng.standard_normal(n))
        assert np.array_equal(abs_product(S, v), abs(S.real) @ v)
        assert np.array_equal(abs_product(S.toarray(), v), abs(S.toarray().real) @ v)
        # same column pointers, other rows: the kept entry columns still fit
        S2 = _random_csc(n, 0.05, rng, complex_)
        assert np.array_equal(abs_product(S2, v), abs(S2.real) @ v)
    csr = sp.csr_matrix(_random_csc(30, 0.1, rng))
    v = np.abs(rng.standard_normal(30))
    assert np.array_equal(abs_product(csr, v), abs(csr.real) @ v)


@pytest.mark.parametrize("storage", ["dense", "sparse"])
def test_tangent_after_residual_is_the_tangent_of_its_own_state(storage: str) -> None:
    """The spring state a residual leaves is used only for the same state and parameters."""
    d = duffing_chain(12, t_end=0.01)
    d["model"]["linear_algebra"] = storage
    case = dynsens.load_case_dict(d)
    model = case.model
    n = model.traits.n_q
    rng = np.random.default_rng(2)
    params = model.parameters(case.x0)
    empty = np.zeros(0)

    def state() -> StepState:
        return StepState(1e-2 * rng.standard_normal(n), rng.standard_normal(n), rng.standard_normal(n),
                         empty, empty, empty)

    s1, s2 = state(), state()
    fresh = dynsens.load_case_dict(d).model
    model.residual(0.0, s1, params)
    for s in (s2, s1):
        got = model.linearize(0.0, s, params)
        ref = fresh.linearize(0.0, s, fresh.parameters(case.x0))
        K, Kr = (got.R_q, ref.R_q) if storage == "dense" else (got.R_q.toarray(), ref.R_q.toarray())
        assert np.array_equal(K, Kr)
    # the same state under other parameters is evaluated anew
    other = model.parameters(case.x0 * 1.5)
    r_other = model.residual(0.0, s1, other)
    assert np.array_equal(r_other, fresh.residual(0.0, s1, fresh.parameters(case.x0 * 1.5)))


def test_iteration_matrix_on_the_shared_pattern_equals_the_sparse_sums() -> None:
    """Chain stored sparse: K and D have the union pattern itself (the shortcut) and M its
    diagonal; S equals the generic sparse additions entry by entry."""
    d = duffing_chain(300, t_end=0.01)
    case = dynsens.load_case_dict(d)
    model = case.model
    assert model.traits.sparse
    n = model.traits.n_q
    rng = np.random.default_rng(3)
    params = model.parameters(case.x0)
    empty = np.zeros(0)
    s = StepState(1e-2 * rng.standard_normal(n), rng.standard_normal(n), rng.standard_normal(n), empty, empty, empty)
    lin = model.linearize(0.0, s, params)
    for coeffs in ((2.5e-7, 5e-4, 5e-4), (1e-6, 0.0, 0.0), (0.0, 1e-3, 0.0)):
        S = lin.iteration_matrix(*coeffs, n_q=n)
        generic = Linearization(lin.R_z, lin.R_q, lin.R_qd).iteration_matrix(*coeffs, n_q=n)
        assert np.array_equal(S.toarray(), generic.toarray()), coeffs
