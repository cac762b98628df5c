"""The shortcuts that cut a step's cost give the numbers of the plain forms they replace, bit
for bit: the element maps with their transpose kept (x @ G), the round-off terms |Re S| |z|
summed entry by entry, the spring state a residual leaves for the tangent at the same state,
the iteration matrix on a union pattern its blocks share, and a dense iteration matrix formed
at its blocks' pattern only."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import dynsens
from dynsens.models.base import PATTERN_SHARE, Linearization, StepState
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
    # the kept mass and c_q̇ D entries follow a new step size and a new design
    for coeffs in ((2.5e-7, 5e-4, 5e-4), (1e-6, 2e-3, 2e-3), (2.5e-7, 5e-4, 5e-4)):
        S = lin.iteration_matrix(*coeffs, n_q=n)
        generic = Linearization(lin.R_z, lin.R_q, lin.R_qd).iteration_matrix(*coeffs, n_q=n)
        assert np.array_equal(S.toarray(), generic.toarray()), coeffs
    other = model.parameters(case.x0 * np.array([2.0, 3.0, 1.0, 1.0]))
    lin2 = model.linearize(0.0, s, other)
    S = lin2.iteration_matrix(2.5e-7, 5e-4, 5e-4, n_q=n)
    generic = Linearization(lin2.R_z, lin2.R_q, lin2.R_qd).iteration_matrix(2.5e-7, 5e-4, 5e-4, n_q=n)
    assert np.array_equal(S.toarray(), generic.toarray())


def test_dense_iteration_matrix_on_the_pattern_equals_the_whole_matrix_sums() -> None:
    """Chain stored dense at 100 DOFs: its linearization carries the pattern of its blocks, S is
    formed at those positions only, and equals the sums over the whole matrices bit for bit,
    real and complex, with either coefficient zero."""
    d = duffing_chain(100, t_end=0.01)
    d["model"]["linear_algebra"] = "dense"
    case = dynsens.load_case_dict(d)
    model = case.model
    n = model.traits.n_q
    rng = np.random.default_rng(4)
    empty = np.zeros(0)
    for x in (case.x0, case.x0 + 1e-20j * np.arange(1, 5)):
        params = model.parameters(x)
        s = StepState(1e-2 * rng.standard_normal(n), rng.standard_normal(n), rng.standard_normal(n),
                      empty, empty, empty)
        lin = model.linearize(0.0, s, params)
        assert lin.dense_pattern is not None and PATTERN_SHARE * lin.dense_pattern.size < n * n
        for coeffs in ((2.5e-7, 5e-4, 5e-4), (1e-6, 0.0, 0.0), (0.0, 1e-3, 0.0), (0.0, 0.0, 0.0)):
            S = lin.iteration_matrix(*coeffs, n_q=n)
            whole = Linearization(lin.R_z, lin.R_q, lin.R_qd).iteration_matrix(*coeffs, n_q=n)
            assert S.dtype == whole.dtype and np.array_equal(S, whole), coeffs


def test_kept_constant_is_never_trusted_for_a_writable_array() -> None:
    """UnionCache.constant keeps a value only for a read-only source: a writable one may change
    in place between calls, so it is computed again every time."""
    from dynsens.models.sparse_assembly import UnionCache
    cache = UnionCache()
    a = np.arange(4.0)
    assert np.array_equal(cache.constant("x", a, 2.0, lambda: 2.0 * a), 2.0 * np.arange(4.0))
    a[0] = 10.0
    assert cache.constant("x", a, 2.0, lambda: 2.0 * a)[0] == 20.0
    b = np.arange(4.0)
    b.flags.writeable = False
    first = cache.constant("x", b, 2.0, lambda: 2.0 * b)
    assert cache.constant("x", b, 2.0, lambda: 2.0 * b) is first      # kept
    assert cache.constant("x", b, 3.0, lambda: 3.0 * b)[1] == 3.0      # another factor
    c = np.arange(4.0)
    c.flags.writeable = False
    assert cache.constant("x", c, 3.0, lambda: 5.0 * c)[1] == 5.0      # another array


def test_on_pattern_is_a_shallow_copy_with_new_values() -> None:
    """The matrix made on a kept pattern equals copy.copy of the pattern with new data: the same
    attributes, the index arrays shared, the pattern itself untouched."""
    import copy
    from dynsens.models.sparse_assembly import on_pattern
    rng = np.random.default_rng(5)
    P = _random_csc(20, 0.2, rng)
    P.sort_indices()
    data = rng.standard_normal(P.nnz)
    old = P.data.copy()
    A, B = on_pattern(P, data), copy.copy(P)
    B.data = data
    assert type(A) is type(B) and A.__dict__.keys() == B.__dict__.keys()
    assert A.indices is P.indices and A.indptr is P.indptr and A.data is data
    assert np.array_equal(A.toarray(), B.toarray()) and np.array_equal(P.data, old)


@pytest.mark.parametrize("kind", ["dense", "sparse", "complex"])
def test_round_off_quick_rejection_decides_as_the_full_test(kind: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The round-off test rejects a residual above c·ε·‖S‖_F ‖z‖₂ without forming |S| |z|: it
    must decide exactly as the entrywise test, for residuals on both sides of its threshold."""
    from dynsens.solver.linalg import Counters
    from dynsens.solver.newton import ROUNDOFF, NewtonSettings, StepSolver

    class _Traits:
        n_q, n_lam, n_p, n_z = 30, 0, 0, 30

    class _Model:
        traits = _Traits()

    solver = StepSolver(_Model(), NewtonSettings(), Counters(), newton=True, refactor=True,   # type: ignore[arg-type]
                        need_converged_factor=False)
    import dynsens.solver.newton as newton_module
    full_tests = []
    monkeypatch.setattr(newton_module, "abs_product", lambda S, v: full_tests.append(1) or abs_product(S, v))
    rng = np.random.default_rng(6)
    decided = {True: 0, False: 0}
    for trial in range(400):
        S = _random_csc(30, 0.1, rng, complex_=kind == "complex")
        if kind == "dense":
            S = S.toarray()
        z = rng.standard_normal(30) * 10.0 ** rng.uniform(-3, 3, 30)
        terms = abs_product(S, np.abs(z.real))
        # residuals at a factor f of the threshold in every row, or far above it in one row
        f = 10.0 ** rng.uniform(-1.0, 1.0)
        R = ROUNDOFF * terms * f * rng.choice([-1.0, 1.0], 30)
        if trial % 3 == 0:
            R[rng.integers(30)] *= 10.0 ** rng.uniform(0, 8)
        full = bool(np.all(np.abs(R.real) <= ROUNDOFF * terms))
        solver._S = S
        got = solver._at_roundoff(R, z, float(np.linalg.norm(R.real)))
        assert got == full, trial
        decided[full] += 1
    assert decided[True] > 50 and decided[False] > 50
    # both paths ran: rejections without the entrywise test, and the entrywise test
    assert 50 < len(full_tests) < 400 - 50
