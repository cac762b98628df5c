"""Constraint projection (``model.projection``) together with the other step machinery: adaptive
steps (the light cart pole), cut steps (Newton failures halved) and the sparse multibody path
(the N-four-bar).  Each against complex step of the whole run (which takes the same accepted and
cut steps: the step controller and Newton's test read real parts), the adjoint against the
direct mode to round-off.

Tolerances: the gradients of adaptive runs to 1e-8 (as without projection, tests/test_cart_pole.py),
of fixed and cut steps to 1e-9; adjoint against direct 1e-11.  The accuracy gain on the cart pole
(mode ``state`` against the plain index-1 run, both adaptive at rtol 1e-7 over 5 s: 2.4e-3 m
against 2.8e-5 m, BENCHMARKS.md "Projection with adaptive steps") is asserted as a factor 20.
"""
from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import pytest

import dynsens
import scripts_path  # noqa: F401  (puts scripts/ on the path)
from adaptive_report import CASE as CART_POLE
from adaptive_report import errors, reference
from conftest import CASES
from helpers import complex_step_gradients, rel_err


def _with_method(case, method):
    c = copy.copy(case)
    c.plan = replace(case.plan, method=method)
    return c


def _check(case, tol, min_checked=2):
    """Direct against complex step of the whole run (tol), adjoint against direct (1e-11)."""
    direct = dynsens.run_case(_with_method(case, "direct"))
    adjoint = dynsens.run_case(_with_method(case, "adjoint"))
    cs = complex_step_gradients(case)
    checked = 0
    for name, rv in direct.responses.items():
        if rv.gradient is None or np.linalg.norm(cs[name]) == 0:
            continue
        assert rel_err(rv.gradient, cs[name]) < tol, (name, rel_err(rv.gradient, cs[name]))
        assert rel_err(adjoint.responses[name].gradient, rv.gradient) < 1e-11, name
        checked += 1
    assert checked >= min_checked
    return direct


@pytest.mark.parametrize("mode", ["state", "output"])
def test_adaptive_cart_pole_with_projection_against_complex_step(mode):
    case = dynsens.load_case(CART_POLE, ["integrator.t_end=1.0", f"model.projection={{mode: {mode}}}"])
    res = _check(case, 1e-8, min_checked=4)
    assert res.counters["rejected_steps"] >= 0 and np.ptp(np.diff(res.time)) > 1e-3      # adaptive
    assert res.monitors["constraint_position"].max() <= 1e-13
    assert res.monitors["constraint_velocity"].max() <= 1e-12


def test_sensitivities_of_adaptive_projected_runs_hold_the_constraints():
    """J_Φ ∇q_j + ∂Φ/∂x_j and its velocity counterpart (/monitors sensitivity_constraint_*) at
    round-off of their scale on adaptive steps with projection; drifting without it."""
    sets = ["integrator.t_end=0.8", "output.sensitivity_history=true", "output.history=[q,qd,qdd]"]
    proj = dynsens.run_case(dynsens.load_case(CART_POLE, [*sets, "model.projection={mode: state}"]))
    plain = dynsens.run_case(dynsens.load_case(CART_POLE, [*sets, "model.projection.enabled=false"]))
    scale = proj.monitors["sensitivity_constraint_scale"].max()
    assert scale > 0.1
    assert proj.monitors["sensitivity_constraint_position"].max() <= 1e-12 * scale
    assert proj.monitors["sensitivity_constraint_velocity"].max() <= 1e-12 * scale
    assert plain.monitors["sensitivity_constraint_position"].max() > 1e-8 * scale


def test_projection_of_the_state_removes_the_drift_that_limits_adaptive_steps():
    sol = reference(5.0)
    sets = ["integrator.adaptive.rtol=1e-7", "integrator.adaptive.atol=1e-10"]
    plain, projected = (dynsens.run_case(dynsens.load_case(CART_POLE, [*sets, *extra]), sensitivities=False)
                        for extra in (["model.projection.enabled=false"], ["model.projection={mode: state}"]))
    assert plain.status == projected.status == "completed"
    e_plain, e_proj = errors(plain, sol)[0], errors(projected, sol)[0]
    assert e_proj * 20 < e_plain, (e_plain, e_proj)
    # the integrated state is held too (mode state): its drift is that of one step, not of the run
    assert projected.monitors["constraint_position_solved"].max() < 1e-3 * plain.monitors["constraint_position"].max()


@pytest.mark.parametrize("mode", ["state", "output"])
def test_cut_steps_with_projection_against_complex_step(mode):
    """Steps of 50 ms with at most 3 Newton iterations: about two cuts per step."""
    case = dynsens.load_case(CASES / "point_pendulum.yaml", [
        "integrator.dt=5e-2", "integrator.solver.max_iterations=3", "integrator.max_step_cuts=8",
        f"model.projection={{mode: {mode}}}"])
    res = _check(case, 1e-9, min_checked=3)
    assert res.counters["step_cuts"] > res.counters["steps"] // 2
    assert res.monitors["constraint_position"].max() <= 1e-13


@pytest.mark.parametrize("sparse_rows", [False, True])
def test_projection_on_the_sparse_multibody_path(sparse_rows, monkeypatch):
    """The N-four-bar (3 loops, redundant equations left out) on sparse linear algebra: exact
    gradients with projection, and the same run as on the dense path; the projection with dense
    J_Φ (the default below 200 equations) and with sparse J_Φ and SuperLU (forced here)."""
    from dynsens.models.multibody import projection
    monkeypatch.setattr(projection, "SPARSE_MIN_EQ", 0 if sparse_rows else 10 ** 9)
    sets = ["integrator.t_end=0.15", "model.projection={mode: state}"]
    case = dynsens.load_case(CASES / "n_four_bar.yaml", [*sets, "model.linear_algebra=sparse"])
    assert case.model.traits.sparse
    q0 = case.model.initial_state(case.model.parameters(case.x0))[0]
    rows = projection._jacobians(case.model, 0.0, q0[:, None], case.model.parameters(case.x0))
    assert (rows.sparse is not None) == sparse_rows
    res = _check(case, 1e-9, min_checked=3)
    assert res.monitors["constraint_position"].max() <= 1e-13
    dense = dynsens.run_case(dynsens.load_case(CASES / "n_four_bar.yaml", [*sets, "model.linear_algebra=dense"]))
    for name, rv in res.responses.items():
        assert rv.value == pytest.approx(dense.responses[name].value, rel=1e-12, abs=1e-14)
        assert rel_err(rv.gradient, dense.responses[name].gradient) < 1e-10, name
