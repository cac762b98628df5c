"""The compiled Newton iteration of a mechanism's step against the same iteration run as Python.

Both run :func:`dynsens.solver.newton_core.newton_iterations`; compiled, its step operations
are the overloads of :mod:`dynsens.models.multibody.compiled_step`.  They call the same kernels
and the same LAPACK routines, so the runs agree bit for bit: responses, gradients, counters,
and the errors of a step that fails.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

import dynsens
from helpers import (assert_identical_runs, assert_same_failures, failures_compiled_and_python,
                     python_iteration)
from dynsens.errors import NonFiniteError
from dynsens.integrators.newmark import Prediction
from dynsens.models.base import StepState
from dynsens.models.multibody import compiled as cc
from dynsens.models.multibody.compiled_step import step_factory
from dynsens.models.multibody.model import MultibodyModel
from dynsens.solver.linalg import Counters
from dynsens.solver.newton import NewtonSettings, StepSolver

CASES = Path(__file__).resolve().parent.parent / "cases"
# the shipped mechanisms the compiled step serves (real runs), and those it leaves to Python
SERVED = ["cart_pole", "hydraulic_lever", "pendulum_3d", "pendulum_projection", "point_pendulum",
          "rheonomic", "slider_crank", "torsional_pair", "tyrolean_weir"]
NOT_SERVED = {"four_bar": "a Python force element (torque)",
              "bricard": "n_z = 69, where the Python path tries a band",
              "n_four_bar": "n_z = 97, where the Python path tries a band"}

compiled_only = pytest.mark.skipif(
    not cc.enabled(), reason=f"DYNSENS_KERNEL={os.environ.get('DYNSENS_KERNEL')}: the numpy kernel, no compiled step")


def _python_iteration(monkeypatch: pytest.MonkeyPatch) -> None:
    python_iteration(monkeypatch, MultibodyModel)


def _short(name: str, steps: int, *extra: str) -> dynsens.case.load.Case:
    case = dynsens.load_case(CASES / f"{name}.yaml")
    return dynsens.load_case(CASES / f"{name}.yaml",
                             [f"integrator.t_end={case.plan.t0 + steps * case.plan.dt!r}", *extra])


def _both(monkeypatch: pytest.MonkeyPatch, case: dynsens.case.load.Case, **kw):  # type: ignore[no-untyped-def]
    compiled = dynsens.run_case(case, **kw)
    with monkeypatch.context() as m:
        _python_iteration(m)
        python = dynsens.run_case(case, **kw)
    return compiled, python


@compiled_only
def test_the_shipped_mechanisms_served_are_the_expected_ones():
    for name in SERVED:
        model = dynsens.load_case(CASES / f"{name}.yaml").model
        assert step_factory(model, newton=True, refactor=True) is not None, name
    for name, why in NOT_SERVED.items():
        model = dynsens.load_case(CASES / f"{name}.yaml").model
        assert step_factory(model, newton=True, refactor=True) is None, (name, why)


@compiled_only
@pytest.mark.parametrize("name", SERVED)
def test_compiled_step_equals_the_python_iteration_bit_for_bit(monkeypatch, name):
    case = _short(name, 150)
    compiled, python = _both(monkeypatch, case, sensitivities=True)
    assert_identical_runs(compiled, python)


@compiled_only
def test_the_compiled_step_runs_and_counts_its_work(monkeypatch):
    """The compiled iteration is what runs (not the Python one): count its calls."""
    from dynsens.models.multibody import compiled_step
    calls = []
    original = compiled_step.CompiledStep.iterate
    monkeypatch.setattr(compiled_step.CompiledStep, "iterate",
                        lambda self, *a: calls.append(1) or original(self, *a))
    res = dynsens.run_case(_short("slider_crank", 40), sensitivities=False)
    assert len(calls) == res.counters["steps"] == 40
    assert res.counters["newton_iterations"] >= 40 and res.counters["factorizations"] >= 40


@compiled_only
def test_adjoint_gradients_follow_the_compiled_steps(monkeypatch):
    case = _short("tyrolean_weir", 120, "sensitivity.method=adjoint")
    compiled, python = _both(monkeypatch, case, sensitivities=True)
    assert_identical_runs(compiled, python)


def _failure(monkeypatch: pytest.MonkeyPatch, run):  # type: ignore[no-untyped-def]
    return failures_compiled_and_python(monkeypatch, run, MultibodyModel)


@compiled_only
def test_a_step_that_does_not_converge_fails_alike(monkeypatch):
    case = _short("tyrolean_weir", 20, "integrator.solver.max_iterations=1", "integrator.max_step_cuts=0")
    compiled, python = _failure(monkeypatch, lambda: dynsens.run_case(case, sensitivities=False))
    assert_same_failures(compiled, python)
    assert "did not converge" in compiled[1]


@compiled_only
def test_a_singular_iteration_matrix_fails_alike(monkeypatch):
    """The link of tests/test_multibody_singular.py at its dead centre, in a step (coefficients
    not zero): the same reason, pose and joints from both iterations."""
    from test_multibody_singular import CASE, _apex_state
    case = dynsens.case.load.load_case_text(CASE.replace("AMP", "0.5"), "link_apex.yaml")

    def step() -> None:
        model = case.model
        params = model.parameters(case.x0)
        st = _apex_state(model)
        solver = StepSolver(model, NewtonSettings(), Counters(), newton=True, refactor=True,
                            need_converged_factor=False)
        pred = Prediction(st.q, st.qd, st.p, 0.0, 0.0)
        h = 1e-3
        solver.solve_step(1.0, 100, pred, np.zeros(model.traits.n_z), params, (0.25 * h * h, 0.5 * h, 0.5 * h),
                          lambda pr, qdd, lam, pd: StepState(pr.q + 0.25 * h * h * qdd, pr.qd + 0.5 * h * qdd,
                                                             qdd, lam, pr.p, pd))
    compiled, python = _failure(monkeypatch, step)
    assert_same_failures(compiled, python)
    assert "singular iteration matrix" in compiled[1] and "lose rank" in compiled[1]


@compiled_only
def test_a_non_finite_residual_fails_alike(monkeypatch):
    """A first-order state that overflows: the same step, iteration and equation named."""
    case = _short("hydraulic_lever", 30)

    def run() -> None:
        model = case.model
        params = model.parameters(case.x0)
        solver = StepSolver(model, NewtonSettings(), Counters(), newton=True, refactor=True,
                            need_converged_factor=False)
        q0, qd0, p0 = model.initial_state(params)
        pred = Prediction(q0, qd0, np.full_like(p0, np.inf), 0.0, 0.0)
        h = 1e-3
        z0 = np.zeros(model.traits.n_z)
        solver.solve_step(h, 1, pred, z0, params, (0.25 * h * h, 0.5 * h, 0.5 * h),
                          lambda pr, qdd, lam, pd: StepState(pr.q + 0.25 * h * h * qdd, pr.qd + 0.5 * h * qdd,
                                                             qdd, lam, pr.p + 0.5 * h * pd, pd))
    compiled, python = _failure(monkeypatch, run)
    assert_same_failures(compiled, python)
    assert compiled[0] is NonFiniteError


@compiled_only
def test_complex_runs_take_the_python_iteration():
    """A complex-step run of the whole simulation: the factory declines complex data."""
    case = _short("slider_crank", 5)
    model = case.model
    make = step_factory(model, newton=True, refactor=True)
    params = model.parameters(case.x0.astype(complex))
    q0, qd0, p0 = model.initial_state(params)
    pred = Prediction(q0, qd0, p0, 0.0, 0.0)
    assert make(0.002, pred, params, (1e-6, 1e-3, 1e-3)) is None
    real = model.parameters(case.x0)
    q0, qd0, p0 = model.initial_state(real)
    assert make(0.002, Prediction(q0, qd0, p0, 0.0, 0.0), real, (1e-6, 1e-3, 1e-3)) is not None


def test_the_cache_key_follows_every_source_compiled_into_the_step(monkeypatch):
    """numba checks only the compiled function's own file: the step's cache entries are keyed by a
    hash of every source it inlines, so an edit to a force law or to the iteration selects a new
    entry (and a source that cannot be read falls back to the version, without failing)."""
    from dynsens.models.multibody import compiled_step
    stamp = compiled_step._sources_stamp()
    original = Path.read_bytes
    for edited in ("forces.py", "newton_core.py", "compiled_linearization.py", "newmark.py"):
        with monkeypatch.context() as m:
            m.setattr(Path, "read_bytes", lambda self, f=edited: original(self) + (b"#" if self.name == f else b""))
            assert compiled_step._sources_stamp() != stamp, edited
    with monkeypatch.context() as m:
        def unreadable(self: Path) -> bytes:
            raise OSError("no source")
        m.setattr(Path, "read_bytes", unreadable)
        assert len(compiled_step._sources_stamp()) == 64
    assert compiled_step._sources_stamp() == stamp
