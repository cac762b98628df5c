"""Multibody models on the sparse path (``model.linear_algebra: sparse``, models/multibody/sparse.py):
the block-sparse linearization equals the dense one entry by entry, and whole runs give the same
responses and gradients, on every shipped multibody case."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

import dynsens
from conftest import CASES
from dynsens.errors import CaseError
from dynsens.models.base import StepState, as_dense

MECHANISMS = sorted(p.stem for p in CASES.glob("*.yaml")
                    if yaml.safe_load(p.read_text(encoding="utf-8"))["model"]["type"] == "multibody")


def _pair(name, *extra):
    return [dynsens.load_case(CASES / f"{name}.yaml", [f"model.linear_algebra={la}", *extra])
            for la in ("dense", "sparse")]


def _random_state(model, x, rng):
    tr = model.traits
    q0, qd0, p0 = model.initial_state(model.parameters(x))
    return StepState(q0 + 0.01 * rng.standard_normal(tr.n_q), qd0 + rng.standard_normal(tr.n_q),
                     rng.standard_normal(tr.n_q), rng.standard_normal(tr.n_lam), p0,
                     rng.standard_normal(tr.n_p))


def test_every_multibody_case_is_covered():
    assert {"bricard", "four_bar", "hydraulic_lever", "n_four_bar", "slider_crank"} <= set(MECHANISMS)


@pytest.mark.parametrize("name", MECHANISMS)
def test_block_sparse_linearization_equals_the_dense_one(name):
    dense, sparse = _pair(name)
    assert not dense.model.traits.sparse and sparse.model.traits.sparse
    rng = np.random.default_rng(3)
    for x in (dense.x0, dense.x0 + 1e-3j):          # real, and complex (complex step of a run)
        s = _random_state(dense.model, np.real(x), rng)
        a = dense.model.linearize(0.3, s, dense.model.parameters(x))
        b = sparse.model.linearize(0.3, s, sparse.model.parameters(x))
        for block in ("R_z", "R_q", "R_qd", "R_p"):
            A, B = getattr(a, block), getattr(b, block)
            assert (A is None) == (B is None), block
            if A is not None:
                assert np.array_equal(as_dense(A), as_dense(B)), (name, block)
        Sa = as_dense(a.iteration_matrix(2.5e-7, 1e-3, 1e-3, dense.model.traits.n_q))
        Sb = b.iteration_matrix(2.5e-7, 1e-3, 1e-3, dense.model.traits.n_q)
        assert Sb.format == "csc" and np.array_equal(Sa, as_dense(Sb)), name


# the weir's iteration matrix (stiff hydraulic states) has a condition number near 1e13: the two
# factorizations (LAPACK's dense LU, the band LU after reordering) differ by 1.4e-9 there; the
# flexible weir has the same hydraulic states (1.6e-10 measured on a fresh clone)
GRADIENT_TOL = {"tyrolean_weir": 1e-8, "tyrolean_weir_flexible": 1e-8}
# the flexible weir's response values, through the same conditioning: 1.6e-12 measured (its KS of
# the joint forces, the lever model); every other mechanism's values agree to 1e-12
VALUE_TOL = {"tyrolean_weir_flexible": 1e-11}


@pytest.mark.parametrize("name", MECHANISMS)
def test_sparse_runs_give_the_dense_responses_and_gradients(name):
    dense, sparse = _pair(name, "integrator.t_end=0.2", "sensitivity.partials=complex")
    a, b = dynsens.run_case(dense), dynsens.run_case(sparse)
    assert a.status == b.status
    for key, r in a.responses.items():
        s = b.responses[key]
        if not np.isfinite(r.value):                 # an event not reached within 0.2 s
            assert not np.isfinite(s.value)
            continue
        assert abs(s.value - r.value) <= VALUE_TOL.get(name, 1e-12) * max(abs(r.value), 1e-12), key
        gap = np.linalg.norm(np.asarray(s.gradient) - r.gradient)
        assert gap <= GRADIENT_TOL.get(name, 1e-10) * max(np.linalg.norm(r.gradient), 1e-300), key


def test_the_numpy_kernel_fills_the_same_pattern(monkeypatch):
    compiled = _pair("hydraulic_lever")[1]
    monkeypatch.setenv("DYNSENS_KERNEL", "numpy")
    numpy_kernel = _pair("hydraulic_lever")[1]
    assert not numpy_kernel.model._kin.compiled
    s = _random_state(compiled.model, compiled.x0, np.random.default_rng(5))
    a = compiled.model.linearize(0.1, s, compiled.model.parameters(compiled.x0))
    b = numpy_kernel.model.linearize(0.1, s, numpy_kernel.model.parameters(compiled.x0))
    for block in ("R_z", "R_q", "R_qd", "R_p"):
        A, B = as_dense(getattr(a, block)), as_dense(getattr(b, block))
        assert np.allclose(A, B, rtol=1e-12, atol=1e-12 * np.abs(A).max()), block
        # the dense linearization has no entry outside the pattern
        assert np.count_nonzero(as_dense(getattr(numpy_kernel.model._evaluation(
            0.1, s, numpy_kernel.model.parameters(compiled.x0)).linearization(), block))) <= \
            getattr(b, block).nnz, block


def test_auto_chooses_by_size_and_a_wrong_value_is_named():
    small = dynsens.load_case(CASES / "slider_crank.yaml")
    assert not small.model.traits.sparse
    with pytest.raises(CaseError) as exc:
        dynsens.load_case(CASES / "slider_crank.yaml", ["model.linear_algebra=fast"])
    assert "model.linear_algebra" in str(exc.value) and "expected auto, dense or sparse, found 'fast'" in str(exc.value)
