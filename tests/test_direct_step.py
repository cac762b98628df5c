"""The compiled blocks of direct-differentiation steps against the same steps run as Python.

Both run :func:`dynsens.derivatives.direct_step.direct_step`; compiled, its operations are the
overloads for a block of dense real records (BLAS gemm for the state part of the pseudo load,
LAPACK getrs for the solve, as the Python path's numpy product and ``Factor.solve``), or for a
block of sparse records with a tridiagonal factor (scipy's CSC product summed in its order,
dgttrs's arithmetic).  So the sensitivities agree bit for bit where numba's BLAS is numpy's
build, and to 1e-5 of each array's largest entry where it is not (the minimum versions); the
band block calls no BLAS and agrees bit for bit everywhere.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import dynsens
from helpers import assert_identical_runs, assert_same_or_blas_close, random_dense_records
from dynsens.derivatives import direct, direct_step
from dynsens.integrators.newmark import Aux, make_scheme
from dynsens.models.base import Linearization, StepState
from dynsens.solver._jit import enabled
from dynsens.solver.linalg import Counters, Factor
from dynsens.timeloop.stepping import StepRecord

CASES = Path(__file__).resolve().parent.parent / "cases"

compiled_only = pytest.mark.skipif(
    not enabled(), reason=f"DYNSENS_KERNEL={os.environ.get('DYNSENS_KERNEL')}: no compiled code")


def _short(name: str, steps: int, *extra: str) -> dynsens.case.load.Case:
    case = dynsens.load_case(CASES / f"{name}.yaml")
    return dynsens.load_case(CASES / f"{name}.yaml",
                             [f"integrator.t_end={case.plan.t0 + steps * case.plan.dt!r}", *extra])


def _blocks_taken(monkeypatch: pytest.MonkeyPatch, kinds: list[str] | None = None) -> list[int]:
    """Count the records each compiled block takes (and note each block's kind in ``kinds``)."""
    taken: list[int] = []
    original = direct.run_block

    def counted(scheme, trail, *a):  # type: ignore[no-untyped-def]
        taken.append(len(trail))
        if kinds is not None:
            kinds.append(a[-1])
        return original(scheme, trail, *a)
    monkeypatch.setattr(direct, "run_block", counted)
    return taken


# ----------------------------------------------------------------------------- whole runs
# shipped cases whose sensitivity steps the compiled block takes (dense real records, plain
# Newmark): mechanisms and dense structural models
SERVED = ["duffing_chain", "four_bar", "hydraulic_lever", "pendulum_3d", "point_pendulum", "rheonomic",
          "slider_crank", "torsional_pair", "truss_impact", "tyrolean_weir"]


# a chain on sparse storage: S tridiagonal after its reordering (the band block), with the
# chain's pulse, damping and cubic springs
SERVED_BAND = [("duffing_chain", ("model.linear_algebra=sparse",))]


@compiled_only
@pytest.mark.parametrize("name, overrides, kind", [pytest.param(name, (), "dense", id=name) for name in SERVED]
                         + [pytest.param(name, o, "band", id=f"{name}-sparse") for name, o in SERVED_BAND])
def test_the_compiled_block_equals_the_python_steps(monkeypatch, name, overrides, kind):
    case = _short(name, 150, "output.sensitivity_history=true", *overrides)
    kinds: list[str] = []
    taken = _blocks_taken(monkeypatch, kinds)
    compiled = dynsens.run_case(case, sensitivities=True)
    assert sum(taken) == compiled.counters["steps"] + compiled.counters["step_cuts"], taken
    assert set(kinds) == {kind}
    with monkeypatch.context() as m:
        m.setattr(direct, "block_kind", lambda *a: None)
        python = dynsens.run_case(case, sensitivities=True)
    assert_identical_runs(compiled, python)
    for field, a in compiled.sensitivity_history.items():
        assert_same_or_blas_close(a, python.sensitivity_history[field], field)


@compiled_only
@pytest.mark.parametrize("name, overrides, why", [
    ("pendulum_projection", (), "its steps are projected"),
    ("cart_pole", (), "its steps are projected"),
    ("slider_crank", ("integrator.scheme=hht", "integrator.alpha=0.1"), "HHT-α is not plain Newmark"),
    ("tower_sizing", (), "a sparse iteration matrix"),
    ("sdof_step", (), "constant matrices: the steps' transition matrices"),
])
def test_records_the_block_does_not_serve_take_the_python_steps(monkeypatch, name, overrides, why):
    taken = _blocks_taken(monkeypatch)
    dynsens.run_case(_short(name, 40, *overrides), sensitivities=True)
    assert taken == [], why


def test_without_compiled_code_the_python_steps_run(monkeypatch):
    monkeypatch.setenv("DYNSENS_KERNEL", "numpy")
    taken = _blocks_taken(monkeypatch)
    dynsens.run_case(_short("slider_crank", 30), sensitivities=True)
    assert taken == []


# ----------------------------------------------------------------------------- random records
@compiled_only
@pytest.mark.parametrize("K, n_p, m, with_R_p", [(1, 0, 1, True), (5, 2, 3, True), (12, 1, 4, True),
                                                (4, 2, 2, False)])
def test_a_block_of_random_records_equals_the_python_steps(K, n_p, m, with_R_p):
    """Random dense records (first-order states with or without R_p, varying step sizes)."""
    rng = np.random.default_rng(K + 10 * n_p + 100 * m)
    n_q, n_lam = 9, 4
    records = random_dense_records(rng, K, n_q, n_lam, n_p, with_R_p)
    sizes = (n_q, n_q, n_q, n_lam, n_p, n_p)
    ds = StepState(*(rng.standard_normal((n, m)) for n in sizes))
    daux = Aux(rng.standard_normal((n_q, m)), rng.standard_normal((n_p, m)))
    design_part = rng.standard_normal((K, n_q + n_lam + n_p, m))
    scheme = make_scheme("newmark")
    assert direct_step.serves(scheme, records, ds, design_part)
    states, ds_end, daux_end = direct_step.run_block(scheme, records, ds, daux, design_part, n_q, n_lam)

    ops = direct_step.PythonDirectStep(scheme, lambda f, P: f.solve(-P), n_q, n_lam, None)
    s, a = ds, daux
    for k, rec in enumerate(records):
        s, a = direct_step.direct_step(ops, (rec.lin, rec.factor, rec.h, None), s, a, design_part[k])
        for field, x, y in zip(StepState._fields, states[k], s):
            assert_same_or_blas_close(x, y, f"record {k}: {field}")
    for x, y in zip([*ds_end, *daux_end], [*s, *a]):
        assert_same_or_blas_close(x, y, "after the block")


@compiled_only
def test_a_wrong_state_part_would_be_seen():
    """The comparison above can fail: one entry of one record's R_q moved by 1e-12 relative
    changes the block's result."""
    rng = np.random.default_rng(3)
    records = random_dense_records(rng, 3, 6, 2, 1)
    ds = StepState(*(rng.standard_normal((n, 2)) for n in (6, 6, 6, 2, 1, 1)))
    daux = Aux(rng.standard_normal((6, 2)), rng.standard_normal((1, 2)))
    design_part = rng.standard_normal((3, 9, 2))
    scheme = make_scheme("newmark")
    before = direct_step.run_block(scheme, records, ds, daux, design_part, 6, 2)[0]
    records[1].lin.R_q[0, 0] *= 1.0 + 1e-12
    after = direct_step.run_block(scheme, records, ds, daux, design_part, 6, 2)[0]
    assert all(np.array_equal(x, y) for x, y in zip(before[0], after[0]))       # before the change
    assert not np.array_equal(before[1].qdd, after[1].qdd)


def test_what_the_block_does_not_serve():
    rng = np.random.default_rng(5)
    records = random_dense_records(rng, 2, 4, 1, 0)
    ds = StepState(*(np.zeros((n, 2)) for n in (4, 4, 4, 1, 0, 0)))
    part = np.zeros((2, 5, 2))
    plain = make_scheme("newmark")
    assert direct_step.serves(plain, records, ds, part) == enabled()
    assert not direct_step.serves(make_scheme("hht", alpha=0.1), records, ds, part)
    assert not direct_step.serves(plain, records, StepState(*(v.astype(complex) for v in ds)), part)
    assert not direct_step.serves(plain, records, ds, part.astype(complex))
    projected = [records[0], StepRecord(2, 0.0, 1e-3, None, records[1].lin, records[1].factor, 2,  # type: ignore[arg-type]
                                        projection=object())]
    assert not direct_step.serves(plain, projected, ds, part)
    lin = records[0].lin
    no_qd = [StepRecord(1, 0.0, 1e-3, None, Linearization(lin.R_z, lin.R_q), records[0].factor, 2)]  # type: ignore[arg-type]
    assert not direct_step.serves(plain, no_qd, ds, part)


# ----------------------------------------------------------------------------- random band records
def _band_records(rng: np.random.Generator, K: int, n: int, same_pattern: bool = True) -> list[StepRecord]:
    """K records of a chain whose unknowns are shuffled: S tridiagonal only after the band
    plan's reordering, R_q and R_q̇ sparse on S's pattern (one pattern for all, unless not
    ``same_pattern``)."""
    shuffle = rng.permutation(n)
    i = np.concatenate([np.arange(n), np.arange(n - 1), np.arange(1, n)])
    j = np.concatenate([np.arange(n), np.arange(1, n), np.arange(n - 1)])

    def on_pattern(values: np.ndarray) -> sp.csc_matrix:
        return sp.csc_matrix((values, (shuffle[i], shuffle[j])), shape=(n, n))
    out = []
    for k in range(K):
        S = on_pattern(np.concatenate([4.0 + rng.random(n), rng.standard_normal(2 * n - 2)]))
        R_q, R_qd = (on_pattern(rng.standard_normal(3 * n - 2)) for _ in range(2))
        if not same_pattern and k == K - 1:
            R_qd.data[0] = 0.0          # one entry fewer stored: another pattern
            R_qd.eliminate_zeros()
        factor = Factor(S, Counters())
        out.append(StepRecord(k + 1, 0.0, 1e-3 * (1.0 + 0.25 * k), None,       # type: ignore[arg-type]
                              Linearization(S, R_q, R_qd, None), factor, 2))
    return out


def _python_steps(records: list[StepRecord], ds: StepState, daux: Aux, design_part: np.ndarray, n: int) -> list:
    ops = direct_step.PythonDirectStep(make_scheme("newmark"), lambda f, P: f.solve(-P), n, 0, None)
    s, a, states = ds, daux, []
    for k, rec in enumerate(records):
        s, a = direct_step.direct_step(ops, (rec.lin, rec.factor, rec.h, None), s, a, design_part[k])
        states.append(s)
    return [states, s, a]


def _band_inputs(rng: np.random.Generator, K: int, n: int, m: int) -> tuple:
    empty = np.zeros((0, m))
    ds = StepState(*(rng.standard_normal((n, m)) for _ in range(3)), empty, empty, empty)
    return ds, Aux(rng.standard_normal((n, m)), empty), rng.standard_normal((K, n, m))


@compiled_only
@pytest.mark.parametrize("K, n, m", [(1, 3, 1), (4, 57, 4), (8, 200, 3)])
def test_a_block_of_random_band_records_equals_the_python_steps(K, n, m):
    rng = np.random.default_rng(K + n + m)
    records = _band_records(rng, K, n)
    assert all(r.factor.tridiagonal_real is not None for r in records)
    assert records[0].factor.tridiagonal_real.plan.perm is not None        # reordered
    ds, daux, design_part = _band_inputs(rng, K, n, m)
    scheme = make_scheme("newmark")
    assert direct_step.block_kind(scheme, records, ds, design_part) == "band"
    states, ds_end, daux_end = direct_step.run_block(scheme, records, ds, daux, design_part, n, 0)
    python, s, a = _python_steps(records, ds, daux, design_part, n)
    for k in range(K):                    # no BLAS on either side: bit for bit everywhere
        for field, x, y in zip(StepState._fields, states[k], python[k]):
            np.testing.assert_array_equal(x, y, err_msg=f"record {k}: {field}")
    for x, y in zip([*ds_end, *daux_end], [*s, *a]):
        np.testing.assert_array_equal(x, y)


@compiled_only
def test_a_wrong_band_entry_would_be_seen():
    """One stored entry of R_q̇ moved by 1e-12 relative, or one pivot of the factor, changes the
    band block's result: the comparison above can fail."""
    rng = np.random.default_rng(11)
    records = _band_records(rng, 3, 30)
    ds, daux, design_part = _band_inputs(rng, 3, 30, 2)
    scheme = make_scheme("newmark")
    before = direct_step.run_block(scheme, records, ds, daux, design_part, 30, 0)[0]
    records[1].lin.R_qd.data[5] *= 1.0 + 1e-12
    after = direct_step.run_block(scheme, records, ds, daux, design_part, 30, 0)[0]
    assert np.array_equal(before[0].qdd, after[0].qdd) and not np.array_equal(before[1].qdd, after[1].qdd)
    records[2].factor.tridiagonal_real.d[3] *= 1.0 + 1e-12
    again = direct_step.run_block(scheme, records, ds, daux, design_part, 30, 0)[0]
    assert not np.array_equal(after[2].qdd, again[2].qdd)


def test_what_the_band_block_does_not_serve():
    rng = np.random.default_rng(12)
    scheme = make_scheme("newmark")
    records = _band_records(rng, 3, 20)
    ds, daux, part = _band_inputs(rng, 3, 20, 2)
    assert direct_step.block_kind(scheme, records, ds, part) == ("band" if enabled() else None)
    # another pattern within the block: the stacked values would not line up
    assert direct_step.block_kind(scheme, _band_records(rng, 3, 20, same_pattern=False), ds, part) is None
    # records of two chains numbered differently: other patterns and another reordering
    other = _band_records(rng, 1, 20)
    assert direct_step.block_kind(scheme, [records[0], other[0]], ds, part[:2]) is None
    # a dense R_q beside a tridiagonal factor (a dense model of 48 or more unknowns)
    lin = records[0].lin
    dense = [StepRecord(1, 0.0, 1e-3, None, Linearization(lin.R_z, lin.R_q.toarray(), lin.R_qd.toarray()),  # type: ignore[arg-type]
                        records[0].factor, 2)]
    assert direct_step.block_kind(scheme, dense, ds, part[:1]) is None
    assert direct_step.block_kind(make_scheme("hht", alpha=0.1), records, ds, part) is None
    assert direct_step.block_kind(scheme, records, ds, part.astype(complex)) is None


@compiled_only
@pytest.mark.parametrize("n, m", [(5, 3), (3, 1), (40, 4)])
def test_the_tridiagonal_solve_of_many_columns_equals_lapack(n, m):
    """gttrs_columns (each column's dgttrs arithmetic, the columns interleaved) against scipy's
    LAPACK dgttrs on the same factor, bit for bit, with row interchanges in the factor."""
    from numba import njit
    from scipy.linalg import lapack

    from dynsens.solver.tridiagonal import gttrs_columns
    rng = np.random.default_rng(n * m)
    dl, d, du = rng.standard_normal(n - 1) * 3.0, rng.standard_normal(n), rng.standard_normal(n - 1)
    dl_, d_, du_, du2, ipiv, info = lapack.dgttrf(dl, d, du)
    assert info == 0 and (n < 3 or np.any(ipiv != np.arange(1, n + 1)))       # pivoting happened
    B = rng.standard_normal((n, m))
    expected = lapack.dgttrs(dl_, d_, du_, du2, ipiv, B)[0]
    got = B.copy()
    njit(lambda *a: gttrs_columns(*a))(dl_, d_, du_, du2, ipiv, got)
    np.testing.assert_array_equal(got, expected)
