"""The compiled blocks of adjoint steps against the same steps run as Python.

Both run :func:`dynsens.derivatives.adjoint_step.adjoint_step`; compiled, its operations are the
overloads for a block of sparse records whose factor is a tridiagonal band (chains): scipy's CSC
transposed products summed in their order, dgttrs's arithmetic with TRANS = 'T', the scheme's
transposed maps.  No BLAS on either side: whole runs agree bit for bit everywhere (gradients of
every response, counters), with checkpoints and recomputed segments too.  Or they are the
overloads for a block of dense real records (mechanisms, small structural models): the BLAS
routines numpy's products call (gemm, gemv, dot by shape) for the transposed products and LAPACK
getrs with TRANS = 'T', as the Python path's numpy products and ``Factor.solve_transposed``: bit
for bit where numba's BLAS is numpy's build, to 1e-5 of each gradient's largest entry where it is
not (the minimum versions).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import lapack

import dynsens
import scripts_path  # noqa: F401  (puts scripts/ on the path)
from bench_peers import chain_case
from helpers import assert_identical_runs, assert_same_or_blas_close, random_dense_records
from make_cases import duffing_chain
from dynsens.derivatives import adjoint_step
from dynsens.integrators.newmark import make_scheme
from dynsens.solver._jit import enabled

CASES = Path(__file__).resolve().parent.parent / "cases"

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
    blocks = len(taken)
    with monkeypatch.context() as m:
        m.setattr(adjoint_step, "block_kind", lambda *a: None)
        python = dynsens.run_case(case, sensitivities=True)
    assert len(taken) == blocks          # the reference took the Python steps only
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
@pytest.mark.parametrize("build, overrides, why", [
    (_sparse_network, ("integrator.scheme=hht", "integrator.alpha=0.1"), "HHT-α is not plain Newmark"),
    (lambda: duffing_chain(60, t_end=0.05), ("model.linear_algebra=dense", "sensitivity.method=adjoint"),
     "a dense model of 60 unknowns: its S factored as a band, its R_q dense"),
])
def test_records_the_block_does_not_serve_take_the_python_steps(monkeypatch, build, overrides, why):
    taken = _blocks_taken(monkeypatch)
    result = dynsens.run_case(dynsens.load_case_dict(build(), "chain.yaml", list(overrides)), sensitivities=True)
    assert result.method == "adjoint"
    assert taken == [], why


@compiled_only
@pytest.mark.parametrize("name, why", [
    ("pendulum_projection", "its steps are projected"),
    ("cart_pole", "its steps are projected"),
])
def test_projected_steps_take_the_python_steps(monkeypatch, name, why):
    taken = _blocks_taken(monkeypatch)
    result = dynsens.run_case(_short(name, 40), sensitivities=True)
    assert result.method == "adjoint"
    assert taken == [], why


# ----------------------------------------------------------------------------- dense records
# shipped cases whose adjoint steps the dense block takes: mechanisms (multipliers, the weir's
# and the lever's pressures) and small structural models
SERVED_DENSE = ["duffing_chain", "four_bar", "hydraulic_lever", "pendulum_3d", "point_pendulum", "rheonomic",
                "slider_crank", "torsional_pair", "truss_impact", "tyrolean_weir"]


def _short(name: str, steps: int, *extra: str) -> dynsens.Case:
    case = dynsens.load_case(CASES / f"{name}.yaml")
    return dynsens.load_case(CASES / f"{name}.yaml", [f"integrator.t_end={case.plan.t0 + steps * case.plan.dt!r}",
                                                      "sensitivity.method=adjoint", *extra])


@compiled_only
@pytest.mark.parametrize("name", SERVED_DENSE)
def test_the_dense_block_equals_the_python_steps(monkeypatch, name):
    """Every step record but the initial one is taken by the dense block; every response's
    gradient as the Python steps' (bit for bit where the BLAS builds agree), values and counters
    alike."""
    case = _short(name, 150)
    compiled, python, taken = _both(monkeypatch, case)
    assert compiled.method == "adjoint"
    assert sum(taken) == compiled.counters["steps"] + compiled.counters["step_cuts"] > 0, taken
    assert_identical_runs(compiled, python)
    graded = [n for n, r in compiled.responses.items() if r.gradient is not None]
    assert graded
    for n in graded:
        assert_same_or_blas_close(np.asarray(compiled.responses[n].gradient),
                                  np.asarray(python.responses[n].gradient), n)


@compiled_only
@pytest.mark.parametrize("name, overrides, what", [
    ("tyrolean_weir", (), "event"),             # the whole run, to its event: t_F's gradient too
    ("slider_crank", ("integrator.solver.max_iterations=2",), "step_cuts"),
    ("slider_crank", ("integrator.adaptive={rtol: 1.0e-5, atol: 1.0e-8}",), "adaptive"),
    ("slider_crank", ("sensitivity.memory_budget=20000",), "checkpoints"),
], ids=["weir-event", "step-cuts", "adaptive", "checkpoints"])
def test_mechanism_records_take_the_dense_block_alike(monkeypatch, name, overrides, what):
    """A mechanism's records after an event, step cuts, adaptive steps, or recomputed from
    checkpoints: the dense block reads each record's own h and factor; gradients as the Python
    steps' (bit for bit where the BLAS builds agree)."""
    over = ["sensitivity.method=adjoint", *overrides]
    case = dynsens.load_case(CASES / f"{name}.yaml", over) if what == "event" else _short(name, 200, *overrides)
    compiled, python, taken = _both(monkeypatch, case)
    assert compiled.method == "adjoint" and sum(taken) > 0
    if what == "event":
        assert compiled.status == "terminated" and compiled.responses["t_F"].gradient is not None
    elif what == "step_cuts":
        assert compiled.counters["step_cuts"] > 0
    elif what == "adaptive":
        assert len(set(np.round(np.diff(compiled.time), 12))) > 2
    else:
        assert compiled.counters["recomputed_steps"] > 0
    assert_identical_runs(compiled, python)
    for n, r in compiled.responses.items():
        if r.gradient is not None:
            assert_same_or_blas_close(np.asarray(r.gradient), np.asarray(python.responses[n].gradient), n)


@compiled_only
@pytest.mark.parametrize("K, n_lam, n_p, r, with_R_p", [(1, 0, 0, 1, True), (5, 4, 2, 3, True), (12, 2, 1, 1, True),
                                                       (7, 0, 3, 2, True), (6, 1, 1, 3, True), (4, 1, 2, 2, False)])
def test_a_dense_block_of_random_records_equals_the_python_steps(K, n_lam, n_p, r, with_R_p):
    """Random dense records (multipliers, first-order states with or without R_p, one response or
    several, varying step sizes), seeds on some of them: the block's bars and μ are the Python
    steps'."""
    rng = np.random.default_rng(K + 10 * n_p + 100 * r + 1000 * n_lam)
    n_q = 9
    records = random_dense_records(rng, K, n_q, n_lam, n_p, with_R_p)
    sizes = (n_q, n_q, n_q, n_lam, n_p, n_p)
    bar = [rng.standard_normal((n, r)) for n in sizes]
    aux = [rng.standard_normal((n_q, r)), rng.standard_normal((n_p, r))]
    seeded = np.array([k % 3 == 0 for k in range(K)])
    seeds = rng.standard_normal((K, sum(sizes), r)) * seeded[:, None, None]
    scheme = make_scheme("newmark")
    assert adjoint_step.block_kind(scheme, records, bar) == "dense"
    got_bar, got_aux, got_mu, finite = adjoint_step.run_block(scheme, records, bar, aux, seeds, seeded, n_q)
    assert finite

    def solve(rec, zbar):  # type: ignore[no-untyped-def]
        return rec.factor.solve_transposed(-zbar)
    ops = adjoint_step.PythonAdjointStep(scheme, solve)
    ends = np.cumsum(sizes)
    b, a = tuple(bar), tuple(aux)
    for k, rec in enumerate(records):
        if seeded[k]:
            b = tuple(leaf + seeds[k][end - n:end] for leaf, n, end in zip(b, sizes, ends))
        b, a, mu = adjoint_step.adjoint_step(ops, rec, b, a)
        assert_same_or_blas_close(got_mu[k], mu, f"mu of record {k}")
        assert got_mu[k].flags.f_contiguous == mu.flags.f_contiguous       # LAPACK's layout
    for i, (x, y) in enumerate(zip(got_bar, b)):
        assert_same_or_blas_close(x, y, f"bar {i}")
    for i, (x, y) in enumerate(zip(got_aux, a)):
        assert_same_or_blas_close(x, y, f"aux {i}")


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
