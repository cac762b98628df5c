"""The compiled block of direct-differentiation steps against the same steps run as Python.

Both run :func:`dynsens.derivatives.direct_step.direct_step`; compiled, its operations are the
overloads for a block of dense real records (BLAS gemm for the state part of the pseudo load,
LAPACK getrs for the solve, as the Python path's numpy product and ``Factor.solve``).  So the
sensitivities agree bit for bit where numba's BLAS is numpy's build, and to 1e-5 of each
array's largest entry where it is not (the minimum versions).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

import dynsens
from helpers import DIFFERENT_BLAS_RTOL, assert_identical_runs, blas_builds_agree
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


def _blocks_taken(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Count the records each compiled block takes."""
    taken: list[int] = []
    original = direct.run_block
    monkeypatch.setattr(direct, "run_block", lambda scheme, trail, *a: taken.append(len(trail))
                        or original(scheme, trail, *a))
    return taken


def _same(a: np.ndarray, b: np.ndarray, what: str) -> None:
    if blas_builds_agree():
        np.testing.assert_array_equal(a, b, err_msg=what)
    else:
        scale = max(float(np.max(np.abs(b), initial=0.0)), 1e-300)
        np.testing.assert_allclose(a, b, rtol=0, atol=DIFFERENT_BLAS_RTOL * scale, err_msg=what)


# ----------------------------------------------------------------------------- whole runs
# shipped cases whose sensitivity steps the compiled block takes (dense real records, plain
# Newmark): mechanisms and dense structural models
SERVED = ["duffing_chain", "four_bar", "hydraulic_lever", "pendulum_3d", "point_pendulum", "rheonomic",
          "slider_crank", "torsional_pair", "truss_impact", "tyrolean_weir"]


@compiled_only
@pytest.mark.parametrize("name", SERVED)
def test_the_compiled_block_equals_the_python_steps(monkeypatch, name):
    case = _short(name, 150, "output.sensitivity_history=true")
    taken = _blocks_taken(monkeypatch)
    compiled = dynsens.run_case(case, sensitivities=True)
    assert sum(taken) == compiled.counters["steps"] + compiled.counters["step_cuts"], taken
    with monkeypatch.context() as m:
        m.setattr(direct, "serves", lambda *a: False)
        python = dynsens.run_case(case, sensitivities=True)
    assert_identical_runs(compiled, python)
    for field, a in compiled.sensitivity_history.items():
        _same(a, python.sensitivity_history[field], field)


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
def _records(rng: np.random.Generator, K: int, n_q: int, n_lam: int, n_p: int) -> list[StepRecord]:
    n_z = n_q + n_lam + n_p
    out = []
    for k in range(K):
        S = rng.standard_normal((n_z, n_z)) + n_z * np.eye(n_z)
        lin = Linearization(S, rng.standard_normal((n_z, n_q)), rng.standard_normal((n_z, n_q)),
                            rng.standard_normal((n_z, n_p)) if n_p else None)
        factor = Factor(S, Counters(), dense_general=True)
        h = 1e-3 * (1.0 + 0.5 * k)       # step sizes vary (step cuts, adaptive steps)
        out.append(StepRecord(k + 1, 0.0, h, None, lin, factor, 2))   # type: ignore[arg-type]
    return out


@compiled_only
@pytest.mark.parametrize("K, n_p, m", [(1, 0, 1), (5, 2, 3), (12, 1, 4)])
def test_a_block_of_random_records_equals_the_python_steps(K, n_p, m):
    rng = np.random.default_rng(K + 10 * n_p + 100 * m)
    n_q, n_lam = 9, 4
    records = _records(rng, K, n_q, n_lam, n_p)
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
            _same(x, y, f"record {k}: {field}")
    for x, y in zip([*ds_end, *daux_end], [*s, *a]):
        _same(x, y, "after the block")


@compiled_only
def test_a_wrong_state_part_would_be_seen():
    """The comparison above can fail: one entry of one record's R_q moved by 1e-12 relative
    changes the block's result."""
    rng = np.random.default_rng(3)
    records = _records(rng, 3, 6, 2, 1)
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
    records = _records(rng, 2, 4, 1, 0)
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
