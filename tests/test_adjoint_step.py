"""The compiled blocks of adjoint steps against the same steps run as Python.

Both run :func:`dynsens.derivatives.adjoint_step.adjoint_step`; compiled, its operations are the
overloads for a block of sparse records whose factor is a tridiagonal band (chains): scipy's CSC
transposed products summed in their order, dgttrs's arithmetic with TRANS = 'T', the scheme's
transposed maps.  No BLAS on either side: whole runs agree bit for bit everywhere (gradients of
every response, counters), with checkpoints and recomputed segments too.
"""
from __future__ import annotations

import os

import numpy as np
import pytest
from scipy.linalg import lapack

import dynsens
import scripts_path  # noqa: F401  (puts scripts/ on the path)
from bench_peers import chain_case
from helpers import assert_identical_runs
from make_cases import duffing_chain
from dynsens.derivatives import adjoint_step
from dynsens.integrators.newmark import make_scheme
from dynsens.solver._jit import enabled

compiled_only = pytest.mark.skipif(
    not enabled(), reason=f"DYNSENS_KERNEL={os.environ.get('DYNSENS_KERNEL')}: no compiled code")


def _blocks_taken(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Count the records each compiled block of adjoint steps takes."""
    taken: list[int] = []
    original = adjoint_step.run_block

    def counted(scheme, records, *a):  # type: ignore[no-untyped-def]
        taken.append(len(records))
        return original(scheme, records, *a)
    monkeypatch.setattr(adjoint_step, "run_block", counted)
    return taken


def _per_element_chain(n: int = 40, t_end: float = 0.3) -> dict:
    d = chain_case(n, t_end, per_element=True)
    d["model"]["linear_algebra"] = "sparse"
    d["sensitivity"]["method"] = "adjoint"
    return d


def _sparse_network() -> dict:
    """A chain on sparse storage with what a spring network may have beyond it: Rayleigh damping,
    a softening spring to ground, initial conditions, a pulse; its four design variables."""
    d = duffing_chain(30, t_end=0.25)
    d["model"]["linear_algebra"] = "sparse"
    d["model"]["elements"].append({"type": "spring", "name": "s_extra", "dofs": ["u15", "ground"], "k": 300.0,
                                   "k2": 2.0e4, "k3": -5.0e4})
    d["model"]["damping"] = {"rayleigh": {"alpha": 0.3, "beta": 1.0e-4}}
    d["model"]["initial"] = {"displacement": {"u3": "1e-5 * k"}, "velocity": {"u30": -0.2}}
    d["sensitivity"] = {"enabled": True, "partials": "forward", "method": "adjoint"}
    return d


def _both(monkeypatch: pytest.MonkeyPatch, case: dynsens.Case) -> tuple:
    taken = _blocks_taken(monkeypatch)
    compiled = dynsens.run_case(case, sensitivities=True)
    with monkeypatch.context() as m:
        m.setattr(adjoint_step, "serves", lambda *a: False)
        python = dynsens.run_case(case, sensitivities=True)
    return compiled, python, taken


@compiled_only
@pytest.mark.parametrize("build, overrides", [
    (_per_element_chain, ()),
    (_sparse_network, ()),
    (_per_element_chain, ("sensitivity.memory_budget=20000",)),     # checkpoints: segments recomputed
], ids=["per-element-chain", "network", "checkpointed"])
def test_the_compiled_adjoint_steps_equal_the_python_steps(monkeypatch, build, overrides):
    """Every step record but the initial one is taken compiled; gradients of every response (the
    chain's tip value, KS aggregates and integral), counters and values bit for bit."""
    case = dynsens.load_case_dict(build(), "chain.yaml", list(overrides))
    compiled, python, taken = _both(monkeypatch, case)
    assert compiled.method == "adjoint"
    assert sum(taken) == compiled.counters["steps"] > 0, taken     # every record but the initial one
    if overrides:
        assert compiled.counters["recomputed_steps"] > 0
    assert_identical_runs(compiled, python)
    for name, res in compiled.responses.items():
        np.testing.assert_array_equal(res.gradient, python.responses[name].gradient, err_msg=name)


@compiled_only
@pytest.mark.parametrize("overrides, what", [
    (("integrator.solver.max_iterations=2",), "step_cuts"),
    (("integrator.adaptive={rtol: 1e-5, atol: 1e-9}",), "adaptive"),
], ids=["step-cuts", "adaptive"])
def test_records_of_cut_and_adaptive_steps_take_the_compiled_block_alike(monkeypatch, overrides, what):
    """Step records of varying size, with sub-steps between the grid instants (step cuts) or a
    grid the controller chose (adaptive steps): the block reads each record's own h and adds
    the seeds at the grid instants only; bit for bit the Python steps."""
    case = dynsens.load_case_dict(_sparse_network(), "chain.yaml", list(overrides))
    compiled, python, taken = _both(monkeypatch, case)
    # every record but the initial one: a cut step's records are its sub-steps
    assert sum(taken) == compiled.counters["steps"] + compiled.counters["step_cuts"] > 0
    if what == "step_cuts":
        assert compiled.counters["step_cuts"] > 0
    else:
        assert len(set(np.round(np.diff(compiled.time), 12))) > 2        # steps of many sizes
    assert_identical_runs(compiled, python)
    for name, res in compiled.responses.items():
        np.testing.assert_array_equal(res.gradient, python.responses[name].gradient, err_msg=name)


@compiled_only
def test_the_compiled_adjoint_equals_the_direct_gradient(monkeypatch):
    """The compiled sweep is the adjoint: its gradients are the direct mode's to round-off."""
    case = dynsens.load_case_dict(_sparse_network(), "chain.yaml")
    taken = _blocks_taken(monkeypatch)
    adjoint = dynsens.run_case(case, sensitivities=True)
    assert sum(taken) > 0
    direct = dynsens.run_case(dynsens.load_case_dict(_sparse_network(), "chain.yaml", ["sensitivity.method=direct"]),
                              sensitivities=True)
    for name, res in direct.responses.items():
        ref = np.asarray(res.gradient)
        np.testing.assert_allclose(adjoint.responses[name].gradient, ref, rtol=1e-7,
                                   atol=1e-9 * np.max(np.abs(ref)), err_msg=name)


@compiled_only
@pytest.mark.parametrize("overrides, why", [
    (("integrator.scheme=hht", "integrator.alpha=0.1"), "HHT-α is not plain Newmark"),
    (("model.linear_algebra=dense",), "dense records (a dense LU or band of a dense model)"),
])
def test_records_the_block_does_not_serve_take_the_python_steps(monkeypatch, overrides, why):
    taken = _blocks_taken(monkeypatch)
    result = dynsens.run_case(dynsens.load_case_dict(_sparse_network(), "chain.yaml", list(overrides)),
                              sensitivities=True)
    assert result.method == "adjoint"
    assert taken == [], why


def test_without_compiled_code_the_python_steps_run(monkeypatch):
    monkeypatch.setenv("DYNSENS_KERNEL", "numpy")
    taken = _blocks_taken(monkeypatch)
    dynsens.run_case(dynsens.load_case_dict(_per_element_chain(12, 0.05), "chain.yaml"), sensitivities=True)
    assert taken == []
    assert not adjoint_step.serves(make_scheme("newmark"), [], [])


@compiled_only
@pytest.mark.parametrize("n, m", [(3, 1), (5, 3), (40, 4), (201, 2)])
def test_the_transposed_tridiagonal_solve_equals_lapack(n, m):
    """gttrs_transposed_columns (dgttrs's TRANS = 'T' arithmetic for each column) against scipy's
    LAPACK dgttrs on the same factor, bit for bit, with row interchanges in the factor."""
    from numba import njit

    from dynsens.solver.tridiagonal import gttrs_transposed_columns
    rng = np.random.default_rng(n * m + 1)
    dl, d, du = rng.standard_normal(n - 1) * 3.0, rng.standard_normal(n), rng.standard_normal(n - 1)
    dl_, d_, du_, du2, ipiv, info = lapack.dgttrf(dl, d, du)
    assert info == 0 and np.any(ipiv != np.arange(1, n + 1))       # pivoting happened
    B = rng.standard_normal((n, m))
    expected = lapack.dgttrs(dl_, d_, du_, du2, ipiv, B, trans="T")[0]
    got = B.copy()
    njit(lambda *a: gttrs_transposed_columns(*a))(dl_, d_, du_, du2, ipiv, got)
    np.testing.assert_array_equal(got, expected)
    plain = B.copy()            # the transposed solve is not the plain one
    assert not np.array_equal(lapack.dgttrs(dl_, d_, du_, du2, ipiv, plain)[0], expected)
