"""Sparse structural assembly on kept patterns (dynsens/models/sparse_assembly.py) gives the
matrices of scipy's COO conversion and sparse additions: the truss (bars, several elements per
node, Rayleigh damping added) stored sparse against the same model stored dense."""
from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import pytest

import dynsens
import dynsens.solver.banded as banded
import dynsens.solver.linalg as linalg
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


# ------------------------------------------------- beams, nonlinear dampers, followers, turning mass
def _frame_models() -> list:
    """A flexible beam pinned at its root with consistent (turning) mass, a follower load at its
    tip, a nonlinear damper and a spring at the tip, Rayleigh damping: every state-dependent
    term of the structural model, stored dense and sparse."""
    n_el = 6
    nodes = {f"n{i}": {"coords": [f"L*{i}/{n_el}", 0.0]} for i in range(n_el + 1)}
    nodes["n0"]["fixed"] = ["x", "y"]
    section = {"shape": "tube", "D": "D", "t": 3.0}
    elements: list[dict] = [{"type": "beam", "name": f"b{i}", "nodes": [f"n{i}", f"n{i + 1}"], "E": 2.1e5,
                             "density": 7.85e-9, "section": section, "mass": "consistent"} for i in range(n_el)]
    elements += [{"type": "damper", "name": "fluid", "dofs": [f"n{n_el}.y", "ground"], "c": "c",
                  "exponent": 0.4, "regularization": 0.05},
                 {"type": "spring", "name": "tie", "dofs": [f"n{n_el}.x", "ground"], "k": 20.0, "k3": 1e-3}]
    d = {"name": "frame", "design": {"variables": [{"name": "P", "value": 400.0}, {"name": "L", "value": 1000.0},
                                                   {"name": "D", "value": 40.0}, {"name": "c", "value": 2.0}]},
         "model": {"type": "structural", "dim": 2, "nodes": nodes, "elements": elements,
                   "loads": [{"node": f"n{n_el}", "direction": "y", "value": "P", "function": "constant",
                              "follower": True}],
                   "damping": {"rayleigh": {"alpha": 0.5, "beta": 1e-5}}},
         "integrator": {"dt": 1e-4, "t_end": 0.004},
         "sensitivity": {"enabled": True, "partials": "complex"},
         "responses": [{"name": "angle", "type": "value", "quantity": {"dof": f"n{n_el}.rz"}},
                       {"name": "tip_y_max", "type": "max", "quantity": {"dof": f"n{n_el}.y"}}]}
    out = []
    for la in ("dense", "sparse"):
        d["model"]["linear_algebra"] = la
        out.append(dynsens.load_case_dict(d))
    return out


def test_sparse_frame_linearization_equals_dense_and_keeps_one_pattern() -> None:
    """Turning mass, follower tangent and nonlinear damping go through the kept patterns: the
    sparse blocks and iteration matrices equal the dense ones, and S has the same pattern at
    the undeformed state as at large random states (one factorization plan for the run)."""
    dense, sparse = _frame_models()
    m = sparse.model
    assert m.traits.sparse and m.rotating_mass and len(m.followers) and len(m.nl_dampers)
    n = m.traits.n_q
    rng = np.random.default_rng(2)
    zero = StepState(np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(0), np.zeros(0), np.zeros(0))
    for x in (dense.x0, dense.x0 + 1e-20j):
        pd_, ps = dense.model.parameters(x), m.parameters(x)
        patterns = []
        for k in range(3):
            s = zero if k == 0 else StepState(*(0.3 * rng.standard_normal((3, n))),
                                               np.zeros(0), np.zeros(0), np.zeros(0))
            ld, ls = dense.model.linearize(0.01, s, pd_), m.linearize(0.01, s, ps)
            for block in ("R_z", "R_q", "R_qd"):
                a, b = getattr(ls, block).toarray(), getattr(ld, block)
                assert np.max(np.abs(a - b)) <= 1e-14 * np.max(np.abs(b)), block
            S = ls.iteration_matrix(2.5e-9, 5e-5, 0.0, n_q=n)
            ref = ld.iteration_matrix(2.5e-9, 5e-5, 0.0, n_q=n)
            assert np.max(np.abs(S.toarray() - ref)) <= 1e-14 * np.max(np.abs(ref))
            patterns.append((S.indptr.copy(), S.indices.copy()))
        assert all(np.array_equal(p[0], patterns[0][0]) and np.array_equal(p[1], patterns[0][1])
                   for p in patterns[1:])


def test_sparse_frame_batched_residuals_equal_state_by_state() -> None:
    _, sparse = _frame_models()
    m = sparse.model
    n = m.traits.n_q
    rng = np.random.default_rng(4)
    for shift, tol in ((0.0, 1e-15), (1e-20j, 1e-15)):
        xs = [sparse.x0 + shift] + [sparse.x0 * (1 + 1e-6 * np.eye(sparse.x0.size)[j]) for j in range(sparse.x0.size)]
        sets = [m.parameters(x) for x in xs]
        states = [StepState(*(0.2 * rng.standard_normal((3, n))), np.zeros(0), np.zeros(0), np.zeros(0))
                  for _ in range(3)]
        ts = np.array([0.001, 0.002, 0.004])
        batch = m.residual_batch_steps(ts, states, sets)
        one = np.stack([np.stack([m.residual(t, s, p) for p in sets], axis=1) for t, s in zip(ts, states)])
        assert batch.shape == one.shape
        assert np.max(np.abs(batch - one)) <= tol * np.max(np.abs(one))


def test_sparse_and_dense_frame_runs_agree() -> None:
    dense, sparse = _frame_models()
    rd = dynsens.run_case(dense, history=())
    rs = dynsens.run_case(sparse, history=())
    for name, r in rd.responses.items():
        assert abs(rs.responses[name].value - r.value) <= 1e-10 * abs(r.value), name
        g = np.asarray(r.gradient)
        assert np.max(np.abs(np.asarray(rs.responses[name].gradient) - g)) <= 1e-8 * np.max(np.abs(g)), name


@pytest.mark.parametrize("factor", ["banded", "sparse"])
def test_adjoint_equals_direct_on_sparse_models(factor: str, monkeypatch) -> None:
    """The adjoint's transposed solves through the band factor (after reordering) and through
    SuperLU with its kept column order (every band refused): adjoint and direct gradients of
    the sparse truss and the sparse frame (complex partials) agree to 1e-10."""
    if factor == "sparse":
        monkeypatch.setattr(banded, "SPARSE_BAND_MAX", 0)
    monkeypatch.setattr(linalg, "_SPARSE_PLANS", {})        # no plan made under the other limit
    kinds: set[str] = set()
    made = linalg.Factor.__init__

    def spy(self, *args, **kw):
        made(self, *args, **kw)
        kinds.add(self.kind)
    monkeypatch.setattr(linalg.Factor, "__init__", spy)
    truss = _models()[1]
    truss.plan = replace(truss.plan, partials="complex")
    for case in (truss, _frame_models()[1]):
        runs = {}
        for method in ("direct", "adjoint"):
            c = copy.copy(case)
            c.plan = replace(case.plan, method=method)
            runs[method] = dynsens.run_case(c, history=())
        assert runs["adjoint"].method == "adjoint"
        for name, rv in runs["direct"].responses.items():
            ra = runs["adjoint"].responses[name]
            assert ra.value == rv.value, name
            g = np.asarray(rv.gradient)
            assert np.linalg.norm(np.asarray(ra.gradient) - g) <= 1e-10 * np.linalg.norm(g), name
    assert factor in kinds


def test_union_pattern_recognises_new_arrays_of_its_pattern_and_refuses_others() -> None:
    """The kept union of an iteration matrix's terms: the same patterns in new index arrays (the
    next run of the same model builds them anew) fit and are recognised by identity from then on;
    another pattern does not fit, and the cache builds the union of the new matrices."""
    import scipy.sparse as sp

    from dynsens.models.sparse_assembly import UnionCache

    M = sp.diags([1.0, 2.0, 3.0], format="csc")
    K = sp.csc_matrix(np.array([[2.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 2.0]]))
    cache = UnionCache()
    u = cache.get([M, K])
    M2, K2 = M.copy(), K.copy()                     # same patterns, new arrays
    assert M2.indptr is not M.indptr
    assert cache.get([M2, K2]) is u
    assert all(s[0] is A.indptr and s[1] is A.indices for A, s in zip((M2, K2), u._seen))
    total = cache.add([M2, K2]).toarray()
    assert np.array_equal(total, (M + K).toarray())
    K3 = sp.csc_matrix(np.array([[2.0, 0.0, -1.0], [0.0, 2.0, 0.0], [-1.0, 0.0, 2.0]]))
    u3 = cache.get([M2, K3])
    assert u3 is not u
    assert np.array_equal(cache.add([M2, K3]).toarray(), (M2 + K3).toarray())
