"""Sparse structural assembly on kept patterns (dynsens/models/sparse_assembly.py) gives the
matrices of scipy's COO conversion and sparse additions: the truss (bars, several elements per
node, Rayleigh damping added) stored sparse against the same model stored dense."""
from __future__ import annotations

import numpy as np

import dynsens
from dynsens.models.base import Linearization, StepState

from scripts_path import truss_impact


def _models():
    d = truss_impact()
    d["model"]["damping"] = {"rayleigh": {"alpha": 0.1, "beta": 1e-4}}
    out = []
    for la in ("dense", "sparse"):
        d["model"]["linear_algebra"] = la
        out.append(dynsens.load_case_dict(d))
    return out


def test_sparse_tangent_damping_and_iteration_matrix_equal_dense() -> None:
    dense, sparse = _models()
    assert sparse.model.traits.sparse and not dense.model.traits.sparse
    n = dense.model.traits.n_q
    rng = np.random.default_rng(0)
    for x in (dense.x0, dense.x0 + 1e-20j):
        pd_, ps = dense.model.parameters(x), sparse.model.parameters(x)
        for _ in range(2):
            s = StepState(rng.standard_normal(n), rng.standard_normal(n), rng.standard_normal(n),
                          np.zeros(0), np.zeros(0), np.zeros(0))
            ld, ls = dense.model.linearize(0.0, s, pd_), sparse.model.linearize(0.0, s, ps)
            for block in ("R_z", "R_q", "R_qd"):
                a, b = getattr(ls, block).toarray(), getattr(ld, block)
                assert np.max(np.abs(a - b)) <= 1e-14 * np.max(np.abs(b)), block
            for coeffs in ((2.5e-7, 5e-4, 0.0), (0.0, 0.0, 0.0), (1e-6, 0.0, 0.0)):
                S = ls.iteration_matrix(*coeffs, n_q=n)
                generic = Linearization(ls.R_z, ls.R_q, ls.R_qd).iteration_matrix(*coeffs, n_q=n)
                assert np.array_equal(S.toarray(), generic.toarray()), coeffs
                ref = ld.iteration_matrix(*coeffs, n_q=n)
                assert np.max(np.abs(S.toarray() - ref)) <= 1e-14 * np.max(np.abs(ref)), coeffs


def test_sparse_and_dense_runs_agree() -> None:
    dense, sparse = _models()
    rd = dynsens.run_case(dense, sensitivities=True, history=())
    rs = dynsens.run_case(sparse, sensitivities=True, history=())
    for name, r in rd.responses.items():
        assert abs(rs.responses[name].value - r.value) <= 1e-12 * abs(r.value)
        g = np.asarray(r.gradient)
        assert np.max(np.abs(np.asarray(rs.responses[name].gradient) - g)) <= 1e-6 * np.max(np.abs(g))


def test_sparse_batched_residuals_equal_state_by_state() -> None:
    """Design partials of sparse models: K states × B parameter sets in one call give the
    residuals of one call per state and set (bitwise for real data, 1e-15 for complex)."""
    _, sparse = _models()
    m = sparse.model
    n = m.traits.n_q
    rng = np.random.default_rng(1)
    for shift, tol in ((0.0, 0.0), (1e-20j, 1e-15)):
        xs = [sparse.x0 + shift] + [sparse.x0 + 1e-6 * np.eye(sparse.x0.size)[j] for j in range(sparse.x0.size)]
        sets = [m.parameters(x) for x in xs]
        states = [StepState(1e-2 * rng.standard_normal(n), rng.standard_normal(n), rng.standard_normal(n),
                            np.zeros(0), np.zeros(0), np.zeros(0)) for _ in range(3)]
        ts = np.array([0.001, 0.002, 0.004])
        batch = m.residual_batch_steps(ts, states, sets)
        one = np.stack([np.stack([m.residual(t, s, p) for p in sets], axis=1) for t, s in zip(ts, states)])
        assert batch.shape == one.shape
        assert np.max(np.abs(batch - one)) <= tol * np.max(np.abs(one))
