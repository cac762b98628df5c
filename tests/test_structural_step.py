"""The compiled Newton iteration of a spring network's step against the same iteration as Python.

Both run :func:`dynsens.solver.newton_core.newton_iterations`; compiled, its step operations are
the overloads of :mod:`dynsens.models.structural.step_kernels`, with the spring law's one definition and
a tridiagonal LU that repeats LAPACK's operations.  The runs agree bit for bit: responses,
direct and adjoint gradients, histories, counters, and the errors of a step that fails.  The
tridiagonal LU is compared with scipy's LAPACK on random systems, pivoting and zero pivots
included.
"""
from __future__ import annotations

import copy
import os
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import lapack

import dynsens
from helpers import (DIFFERENT_BLAS_RTOL, assert_identical_runs, assert_same_failures, blas_builds_agree,
                     failures_compiled_and_python, python_iteration)
import scripts_path  # noqa: F401  (puts scripts/ on the path)
from make_cases import duffing_chain
from dynsens.errors import ConvergenceError
from dynsens.integrators.newmark import Prediction, correct_arrays
from dynsens.models.base import StepState
from dynsens.models.structural import step as structural_step
from dynsens.models.structural import step_kernels as structural_step_kernels
from dynsens.models.structural.model import StructuralModel
from dynsens.solver import _jit
from dynsens.solver.linalg import Counters
from dynsens.solver.newton import NewtonSettings, StepSolver
from dynsens.solver.tridiagonal import gttrf, gttrs
from dynsens.timeloop.step_blocks import StepBlocks

CASES = Path(__file__).resolve().parent.parent / "cases"
compiled_only = pytest.mark.skipif(
    not _jit.enabled(), reason=f"DYNSENS_KERNEL={os.environ.get('DYNSENS_KERNEL')}: no compiled step")


def _chain(n: int = 30, steps: int = 300, linear_algebra: str = "sparse") -> dict:
    d = duffing_chain(n, t_end=steps * 1e-3)
    d["model"]["linear_algebra"] = linear_algebra
    d["output"]["history"] = ["q", "qd"]
    return d


def _dense_chain() -> dict:
    """60 masses, stored dense: the Python path factors S as a band (from 48 unknowns on)."""
    return _chain(60, linear_algebra="dense")


def _small_dense_chain() -> dict:
    """The P1 chain at N = 10, stored dense (as ``linear_algebra: auto`` stores it): below the
    band's break-even the Python path factors S with a dense LU (getrf), as the compiled step."""
    return _chain(10, linear_algebra="dense")


def _small_dense_network() -> dict:
    """A dense network that is no chain: springs across two and five links and a second spring to
    ground, Rayleigh damping (D on a wider pattern); the Python path's dense LU factors it."""
    d = _chain(12, linear_algebra="dense")
    d["model"]["elements"] += [
        {"type": "spring", "name": "across2", "dofs": ["u2", "u4"], "k": 80.0, "k3": 2.0e4},
        {"type": "spring", "name": "across5", "dofs": ["u9", "u4"], "k": 40.0, "k2": 1.0e3, "k3": -1.0e3},
        {"type": "spring", "name": "s_extra", "dofs": ["u6", "ground"], "k": 300.0, "k3": 1.0e5}]
    d["model"]["damping"] = {"rayleigh": {"alpha": 0.3, "beta": 1.0e-4}}
    return d


def _network(n: int = 24) -> dict:
    """A chain with what a spring network may have beyond it: quadratic and softening springs,
    a second spring to ground, a DOF without a damper, Rayleigh damping, initial conditions and
    two loads; still tridiagonal in its band order."""
    d = _chain(n)
    els = d["model"]["elements"]
    els.append({"type": "spring", "name": "s_extra", "dofs": [f"u{n // 2}", "ground"], "k": 300.0,
                "k2": 2.0e4, "k3": -5.0e4})
    d["model"]["elements"] = [e for e in els if e["name"] != "d5"]
    d["model"]["damping"] = {"rayleigh": {"alpha": 0.3, "beta": 1.0e-4}}
    d["model"]["initial"] = {"displacement": {"u3": 0.01}, "velocity": {f"u{n}": -0.2}}
    d["model"]["loads"].append({"dof": "u7", "value": -40.0, "function": {"type": "pulse", "t0": 0.05,
                                                                          "duration": 0.05}})
    return d


def _python_iteration(monkeypatch: pytest.MonkeyPatch) -> None:
    python_iteration(monkeypatch, StructuralModel)


def _count_compiled_steps(m: pytest.MonkeyPatch, calls: list[int]) -> None:
    """Count the steps iterated compiled, one at a time or in a block of steps."""
    original = structural_step.CompiledSpringStep.iterate
    m.setattr(structural_step.CompiledSpringStep, "iterate", lambda self, *a: calls.append(1) or original(self, *a))
    hand_out = StepBlocks._hand_out
    m.setattr(StepBlocks, "_hand_out", lambda self, *a: calls.append(1) or hand_out(self, *a))


def _both(monkeypatch: pytest.MonkeyPatch, case: dynsens.Case, **kw):  # type: ignore[no-untyped-def]
    calls: list[int] = []
    with monkeypatch.context() as m:
        _count_compiled_steps(m, calls)
        compiled = dynsens.run_case(case, **kw)
    with monkeypatch.context() as m:
        _python_iteration(m)
        python = dynsens.run_case(case, **kw)
    return compiled, python, len(calls)


@compiled_only
@pytest.mark.parametrize("build, sets", [
    (_chain, []),
    (_chain, ["sensitivity.method=adjoint"]),
    (_chain, ["sensitivity.partials=complex"]),
    (_network, []),
    (_network, ["sensitivity.method=adjoint"]),
    (_dense_chain, []),
    (_dense_chain, ["sensitivity.method=adjoint"]),
    (_small_dense_chain, []),
    (_small_dense_chain, ["sensitivity.method=adjoint"]),
    (_small_dense_chain, ["sensitivity.partials=complex"]),
    (_small_dense_network, []),
    (_small_dense_network, ["sensitivity.method=adjoint"]),
    (_small_dense_chain, ["integrator.adaptive={rtol: 1.0e-6, atol: 1.0e-9}", "integrator.scheme=hht",
                          "integrator.alpha=0.1"]),
    (_chain, ["integrator.adaptive={rtol: 1.0e-6, atol: 1.0e-9}", "integrator.scheme=hht",
              "integrator.alpha=0.1"]),
    (_chain, ["integrator.adaptive={rtol: 1.0e-6, atol: 1.0e-9}", "sensitivity.method=adjoint"]),
], ids=["chain", "chain-adjoint", "chain-complex-partials", "network", "network-adjoint", "dense-chain",
        "dense-chain-adjoint", "small-dense-chain", "small-dense-chain-adjoint", "small-dense-chain-complex-partials",
        "small-dense-network", "small-dense-network-adjoint", "small-dense-adaptive-hht", "adaptive-hht",
        "adaptive-adjoint"])
def test_compiled_step_equals_the_python_iteration_bit_for_bit(monkeypatch, build, sets):
    case = dynsens.load_case_dict(build(), "chain.yaml", sets)
    compiled, python, calls = _both(monkeypatch, case, sensitivities=True)
    # every step iterated compiled (an adaptive run's rejected trials as well)
    every = compiled.counters["steps"] + compiled.counters.get("rejected_steps", 0)
    assert calls == every
    assert_identical_runs(compiled, python)
    primal, python_primal, _ = _both(monkeypatch, case, sensitivities=False)
    assert_identical_runs(primal, python_primal)
    for key, r in primal.responses.items():          # the same primal with or without gradients
        np.testing.assert_array_equal(r.value, compiled.responses[key].value, err_msg=key)


@compiled_only
def test_which_models_are_served(monkeypatch):
    """Spring networks whose S the Python path factors as tridiagonal or by a dense LU: not a
    model with bars or a linear one; for a sparse network with a spring across seven links (a
    wider band, gbtrf) the factory declines every step and the Python iteration runs, with the
    same numbers.  The shipped 20-mass chain (dense, below the band's break-even: a dense LU) is
    served: every step compiled."""
    sparse = dynsens.load_case_dict(_chain(), "chain.yaml").model
    assert structural_step.step_factory(sparse, newton=True, refactor=True) is not None
    assert structural_step.step_factory(sparse, newton=False, refactor=True) is None
    for name in ("truss_impact", "tower_sizing", "sdof_step"):
        model = dynsens.load_case(CASES / f"{name}.yaml").model
        assert structural_step.step_factory(model, newton=True, refactor=True) is None, name
    wide = _chain()
    wide["model"]["elements"].append({"type": "spring", "name": "across", "dofs": ["u2", "u9"], "k": 50.0,
                                      "k3": 1.0e3})
    compiled, python, calls = _both(monkeypatch, dynsens.load_case_dict(wide, "wide.yaml"), sensitivities=True)
    assert calls == 0
    assert_identical_runs(compiled, python)
    shipped = dynsens.load_case(CASES / "duffing_chain.yaml", ["integrator.t_end=0.1"])
    assert not shipped.model.traits.sparse
    compiled, python, calls = _both(monkeypatch, shipped, sensitivities=True)
    assert calls == compiled.counters["steps"] > 0
    assert_identical_runs(compiled, python)


@compiled_only
def test_a_small_dense_chain_takes_the_compiled_direct_block(monkeypatch):
    """The compiled step's dense LU (getrf's, stored by columns) is a record the compiled block of
    direct sensitivity steps reads: every step's sensitivities are taken there, none in Python
    (the primal steps are taken compiled too, in blocks of steps)."""
    from dynsens.derivatives import direct
    blocks: list[int] = []
    original = direct.run_block
    monkeypatch.setattr(direct, "run_block", lambda scheme, trail, *a: blocks.append(len(trail))
                        or original(scheme, trail, *a))
    calls: list[int] = []
    _count_compiled_steps(monkeypatch, calls)
    result = dynsens.run_case(dynsens.load_case_dict(_small_dense_chain(), "chain.yaml"), sensitivities=True)
    steps = result.counters["steps"]
    assert len(calls) == sum(blocks) == steps > 0


@compiled_only
@pytest.mark.parametrize("build", [_chain, _dense_chain, _small_dense_chain, _small_dense_network, _network],
                         ids=["sparse", "dense", "small-dense", "small-dense-network", "network"])
def test_the_compiled_residual_is_the_models(build):
    """What serving a design without a run-time comparison assumes: the compiled F_R is the
    model's, bit for bit at random states where numba's BLAS is numpy's build (and within the
    stated difference of two builds otherwise: see blas_builds_agree)."""
    case = dynsens.load_case_dict(build(), "chain.yaml")
    model = case.model
    params = model.parameters(case.x0)
    coeffs = (2.5e-7, 5e-4, 0.0)
    empty = np.zeros(0)
    rng = np.random.default_rng(1)
    pred = Prediction(rng.standard_normal(model.n), rng.standard_normal(model.n), empty, 0.0, 0.0)
    step = structural_step.step_factory(model, newton=True, refactor=True)(0.001, pred, params, coeffs)
    assert step is not None
    for _ in range(5):
        z = rng.standard_normal(model.n)
        q, qd = correct_arrays(pred.q, pred.qd, pred.p, *coeffs, z, empty)[:2]
        python = model.residual(0.001, StepState(q, qd, z, empty, pred.p, empty), params)
        data = step.data
        sets = tuple(np.asarray(getattr(data, k))[None] for k in ("mass", "k1", "k2", "k3", "d_ptr", "d_col", "d_val"))
        compiled = structural_step_kernels.compiled_residuals(data, sets, q[None], qd[None], z[None],
                                                              np.asarray(data.f_ext)[None, None])[0, 0]
        if blas_builds_agree():
            np.testing.assert_array_equal(compiled, python)
        else:
            np.testing.assert_allclose(compiled, python, rtol=0, atol=DIFFERENT_BLAS_RTOL * np.max(np.abs(python)))


def _perturbed_sets(case, m_complex: bool = False) -> list:
    """The design and its forward-difference neighbours (the partials' parameter sets)."""
    x = case.x0.astype(complex) if m_complex else case.x0
    h = 1e-6 * np.maximum(np.abs(case.x0), 1.0)
    return [case.model.parameters(x)] + [case.model.parameters(x + h[j] * np.eye(x.size)[j])
                                         for j in range(x.size)]


def _numpy_batch(monkeypatch, model, ts, states, sets):  # type: ignore[no-untyped-def]
    """The model's batched F_R without its compiled residuals (a fresh list: no kept stack)."""
    with monkeypatch.context() as m:
        m.setattr(structural_step, "batch_residuals", lambda model, params_list: None)
        return model.residual_batch_steps(ts, states, list(sets))


@compiled_only
@pytest.mark.parametrize("build", [_chain, _network], ids=["chain", "network"])
def test_the_partials_residuals_of_a_sparse_network_are_compiled_and_the_models(monkeypatch, build):
    """The design partials' residuals of a sparse spring network (K states, B parameter sets in one
    call) are the compiled step's F_R: bit for bit the model's numpy batch, which the direct and
    adjoint runs therefore do not see (a run's gradients, below, are the same numbers)."""
    case = dynsens.load_case_dict(build(), "chain.yaml")
    model = case.model
    sets = _perturbed_sets(case)
    rng = np.random.default_rng(7)
    empty = np.zeros(0)
    states = [StepState(*(rng.standard_normal(model.n) for _ in range(3)), empty, empty, empty) for _ in range(4)]
    ts = np.array([0.0, 0.01, 0.02, 0.3])
    assert structural_step.batch_residuals(model, sets) is not None
    compiled = model.residual_batch_steps(ts, states, sets)
    python = _numpy_batch(monkeypatch, model, ts, states, sets)
    assert compiled.shape == python.shape == (4, model.n, len(sets))
    np.testing.assert_array_equal(compiled, python)
    # whole runs with their partials so, direct and adjoint
    for mode in ("direct", "adjoint"):
        run = dynsens.load_case_dict(build(), "chain.yaml", [f"sensitivity.method={mode}"])
        with_compiled = dynsens.run_case(run, sensitivities=True)
        with monkeypatch.context() as m:
            m.setattr(structural_step, "batch_residuals", lambda model, params_list: None)
            without = dynsens.run_case(run, sensitivities=True)
        assert_identical_runs(with_compiled, without)


@compiled_only
def test_compiled_partials_residuals_serve_real_sparse_spring_networks_only():
    """Complex designs (complex-step partials), dense models (their batched BLAS products are not
    one product per state) and models beyond springs keep the numpy batch."""
    sparse = dynsens.load_case_dict(_chain(), "chain.yaml")
    assert structural_step.batch_residuals(sparse.model, _perturbed_sets(sparse)) is not None
    assert structural_step.batch_residuals(sparse.model, _perturbed_sets(sparse, m_complex=True)) is None
    dense = dynsens.load_case_dict(_dense_chain(), "chain.yaml")
    assert structural_step.batch_residuals(dense.model, _perturbed_sets(dense)) is None
    truss = dynsens.load_case(CASES / "truss_impact.yaml")
    assert structural_step.batch_residuals(truss.model, _perturbed_sets(truss)) is None


@compiled_only
def test_complex_runs_take_the_python_iteration():
    case = dynsens.load_case_dict(_chain(), "chain.yaml")
    model = case.model
    make = structural_step.step_factory(model, newton=True, refactor=True)
    pred = Prediction(np.zeros(model.n), np.zeros(model.n), np.zeros(0), 0.0, 0.0)
    assert make(0.001, pred, model.parameters(case.x0), (2.5e-7, 5e-4, 0.0)) is not None
    assert make(0.001, pred, model.parameters(case.x0.astype(complex)), (2.5e-7, 5e-4, 0.0)) is None


def _failure(monkeypatch: pytest.MonkeyPatch, run):  # type: ignore[no-untyped-def]
    return failures_compiled_and_python(monkeypatch, run, StructuralModel)


@compiled_only
@pytest.mark.parametrize("build", [_chain, _small_dense_chain], ids=["tridiagonal", "dense-lu"])
def test_a_step_that_does_not_converge_fails_alike(monkeypatch, build):
    case = dynsens.load_case_dict(build(), "chain.yaml", ["integrator.solver.max_iterations=1",
                                                        "integrator.max_step_cuts=0"])
    compiled, python = _failure(monkeypatch, lambda: dynsens.run_case(case, sensitivities=False))
    assert_same_failures(compiled, python)
    assert "did not converge" in compiled[1]


@compiled_only
def test_a_softening_run_that_loses_its_way_fails_alike(monkeypatch):
    """Strongly softening springs under a large load: Newton wanders at step 12; both iterations
    end in the same error, with the same residual history."""
    d = _chain()
    d["design"]["variables"][3].update(value=-1.0e9, lower=-1.0e10)
    d["model"]["loads"][0]["value"] = 1.0e4
    case = dynsens.load_case_dict(d, "softening.yaml", ["integrator.max_step_cuts=0"])
    compiled, python = _failure(monkeypatch, lambda: dynsens.run_case(case, sensitivities=False))
    assert_same_failures(compiled, python)
    assert "did not converge at t = 0.012 s" in compiled[1]


@compiled_only
@pytest.mark.parametrize("linear_algebra", ["sparse", "dense"], ids=["tridiagonal", "dense-lu"])
def test_a_singular_iteration_matrix_fails_alike(monkeypatch, linear_algebra):
    """No mass, no damping, purely cubic springs: S = c_q K_t(q) is regular where every spring
    is stretched and zero at q = 0.  A first step served compiled, then one at q = 0: the same
    reason from both iterations (gttrf's or getrf's zero pivot in column 1)."""
    case = dynsens.load_case_dict(_chain(12, linear_algebra=linear_algebra), "chain.yaml")
    model = case.model
    params = model.parameters(np.array([0.0, 0.0, 0.0, 1.0e6]))     # m, c, k, k3
    h = 1e-3
    c_q, c_qd = 0.25 * h * h, 0.5 * h

    def correct(pr, qdd, lam, pd):  # type: ignore[no-untyped-def]
        return StepState(pr.q + c_q * qdd, pr.qd + c_qd * qdd, qdd, lam, pr.p, pd)

    def steps() -> None:
        solver = StepSolver(model, NewtonSettings(), Counters(), newton=True, refactor=True,
                            need_converged_factor=False)
        zero = np.zeros(model.n)
        stretched = Prediction(1e-3 * np.arange(1, model.n + 1) ** 1.5, zero, np.zeros(0), 0.0, 0.0)
        try:
            solver.solve_step(h, 1, stretched, zero, params, (c_q, c_qd, 0.0), correct)
        except ConvergenceError:
            pass
        solver.solve_step(2 * h, 2, Prediction(zero, zero, np.zeros(0), 0.0, 0.0), zero, params,
                          (c_q, c_qd, 0.0), correct)

    calls: list[int] = []
    original = structural_step.CompiledSpringStep.iterate
    monkeypatch.setattr(structural_step.CompiledSpringStep, "iterate",
                        lambda self, *a: calls.append(1) or original(self, *a))
    compiled, python = _failure(monkeypatch, steps)
    assert len(calls) == 2
    assert_same_failures(compiled, python)
    assert "singular iteration matrix (exactly zero pivot in column 1" in compiled[1]
    # what to check is said in a structural model's terms, not a mechanism's
    assert "zero or negative masses or stiffnesses" in compiled[1] and "dead-centre" not in compiled[1]


@pytest.mark.parametrize("build", ["compiled", "python"])
def test_tridiagonal_lu_equals_lapack_bit_for_bit(build: str):
    """gttrf / gttrs, compiled (as the step runs them where numba is installed) and as plain
    Python (where it is not), against scipy's dgttrf / dgttrs: factors, pivots, info and
    solutions equal bit for bit, on well and badly scaled systems, with row interchanges and
    exactly zero pivots."""
    if build == "compiled" and not _jit.HAVE_NUMBA:
        pytest.skip("numba is not installed: only the Python build runs")
    run_f, run_s = (_jit.jit(gttrf), _jit.jit(gttrs)) if build == "compiled" else (gttrf, gttrs)
    rng = np.random.default_rng(7)
    interchanges = zero_pivots = 0
    for trial in range(600):
        n = int(rng.integers(3, 40)) if trial < 550 else (1000 if build == "compiled" else 100)
        dl, du = rng.standard_normal(n - 1), rng.standard_normal(n - 1)
        d = rng.standard_normal(n) * (10.0 if trial % 3 == 0 else 0.3)
        if trial % 7 == 0:       # a zero column: singular, an exactly zero pivot
            k = int(rng.integers(1, n - 1))
            du[k - 1] = d[k] = dl[k] = 0.0
        elif trial % 7 == 1:     # a zero on the diagonal: an interchange where it would not be
            d[rng.integers(0, n)] = 0.0
        b = rng.standard_normal(n)
        ref = lapack.dgttrf(dl.copy(), d.copy(), du.copy())
        mine = [dl.copy(), d.copy(), du.copy(), np.zeros(n - 2), np.zeros(n, np.int32)]
        info = run_f(*mine)
        assert info == ref[5]
        for a, r in zip(mine, ref[:5]):
            np.testing.assert_array_equal(a, r)
        interchanges += int(np.any(mine[4] != np.arange(1, n + 1)))
        if info:
            zero_pivots += 1
            continue
        x = b.copy()
        run_s(*mine, x)
        np.testing.assert_array_equal(x, lapack.dgttrs(*ref[:5], b.copy())[0])
    assert interchanges > 100 and zero_pivots > 10


def test_the_cache_key_follows_every_source_compiled_into_the_step(monkeypatch):
    """An edit to the spring law, the tridiagonal LU, the overloads, the iteration or the
    factor's tests selects another cache entry."""
    stamp = structural_step_kernels._stamp()
    original = Path.read_bytes
    for edited in ("spring_law.py", "tridiagonal.py", "step_kernels.py", "newton_core.py", "linalg.py",
                   "newmark.py"):
        with monkeypatch.context() as m:
            m.setattr(Path, "read_bytes", lambda self, f=edited: original(self) + (b"#" if self.name == f else b""))
            assert structural_step_kernels._stamp() != stamp, edited
    assert structural_step_kernels._stamp() == stamp


def test_the_spring_law_is_the_models(monkeypatch):
    """The Python model evaluates the spring law the compiled step compiles (one definition):
    replacing it changes the model's forces."""
    case = dynsens.load_case_dict(_chain(5), "chain.yaml")
    model = case.model
    params = model.parameters(case.x0)
    q = np.linspace(0.0, 0.01, 5)
    before = copy.deepcopy(model.springs.state(q, params, tangent=False)[0])
    from dynsens.models.structural.elements import springs
    monkeypatch.setattr(springs, "spring_law", lambda d, k1, k2, k3: (2 * k1 * d, k1 + 0 * d))
    after = model.springs.state(q.copy(), params, tangent=False)[0]
    np.testing.assert_allclose(after, 2 * params["k1"] * (q - np.concatenate([[0.0], q[:-1]])))
    assert not np.allclose(after, before)
