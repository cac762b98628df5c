"""A mechanism at and near a singular (dead-centre) configuration.

One link pinned to the ground (revolute O about z) whose COM height is prescribed by a body
driver ``lift``: y(t) = A sin(2π·0.25 t).  With A = l/2 = 0.5 m the link is driven to the top
of its circle (θ = 90°), where the driver's row e_y·J_r = (l/2) cos θ vanishes and the
equations of O and lift become linearly dependent.
"""
from __future__ import annotations

import re

import numpy as np
import pytest

import dynsens
from dynsens.errors import ConvergenceError
from dynsens.integrators.newmark import Prediction
from dynsens.models.base import StepState
from dynsens.solver.linalg import Counters
from dynsens.solver.newton import NewtonSettings, StepSolver

CASE = """
name: link_apex
model:
  type: multibody
  bodies:
    link:
      mass: 1.0
      inertia: [0.001, 0.0833, 0.0833]
      position: [0.5, 0, 0]
      markers:
        O: [-0.5, 0, 0]
  joints:
    - {name: O, type: revolute, body_1: ground, body_2: link, point: [0, 0, 0], axis: [0, 0, 1]}
    - {name: lift, type: driving, body: link, coordinate: y, amplitude: AMP, frequency: 0.25}
integrator: {scheme: newmark, dt: 0.01, t_end: 1.5}
sensitivity: {enabled: false}
responses:
  - {name: y_end, type: value, quantity: {body: link, kind: position}, component: link.y, unit: m}
"""


def _case(tmp_path, amplitude: float):
    path = tmp_path / "link.yaml"
    path.write_text(CASE.replace("AMP", repr(amplitude)))
    return dynsens.load_case(path)


def _apex_state(model) -> StepState:
    """The link standing upright (θ = 90°), at rest: the dead-centre of the driver."""
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    q = np.array([0.0, 0.5, 0.0, c, 0.0, 0.0, s])
    z = np.zeros(model.traits.n_q)
    return StepState(q, z, z, np.zeros(model.traits.n_lam), np.zeros(0), np.zeros(0))


def test_singular_configuration_names_the_joints(tmp_path):
    case = _case(tmp_path, 0.5)
    model = case.model
    params = model.parameters(case.x0)
    st = _apex_state(model)
    why = model.diagnose_singular(1.0, st, params)
    assert "O" in why and "lift" in why and "lose rank" in why
    # a regular pose is not reported
    assert model.diagnose_singular(0.0, st._replace(q=np.array([0.5, 0, 0, 1.0, 0, 0, 0])), params) == ""
    # the step solver stops with the time, the joints and a hint when S is singular there
    solver = StepSolver(model, NewtonSettings(), Counters(), newton=True, refactor=True,
                        need_converged_factor=False)
    pred = Prediction(st.q, st.qd, st.p, st.q[:0], st.p[:0])
    z0 = np.zeros(model.traits.n_z)
    with pytest.raises(ConvergenceError) as err:
        solver.solve_step(1.0, 100, pred, z0, params, (0.0, 0.0, 0.0),
                          lambda pr, qdd, lam, pd: StepState(pr.q, pr.qd, qdd, lam, pr.p, pd))
    msg = str(err.value)
    assert "t = 1 s" in msg and "singular iteration matrix" in msg
    assert "joints O, lift lose rank" in msg and "dead-centre" in msg


def test_passing_near_the_dead_centre_runs_through(tmp_path):
    # A = 0.49 m: the link swings up to θ = asin(0.98) ≈ 78.5° and back, 11.5° from the apex
    res = dynsens.run_case(_case(tmp_path, 0.49))
    assert res.status == "completed" and res.counters["step_cuts"] == 0
    # index-1 drift of the position constraints stays below 1e-4 m over the 1.5 s
    assert np.max(res.monitors["constraint_position"]) < 1e-4


def test_run_through_the_dead_centre_does_not_report_success():
    """Driving the link linearly over the top of its circle (y = 0.5 t passes y = 0.5 m at
    t = 1 s) cannot be followed; step cutting must not turn that into a 'successful' run with
    a large constraint drift: the drift guard stops it with an explanation."""
    text = CASE.replace("amplitude: AMP, frequency: 0.25", "rate: 0.5")
    case = dynsens.case.load.load_case_text(text, "link_linear.yaml")
    with pytest.raises((ConvergenceError, dynsens.errors.ModelError)) as info:
        dynsens.run_case(case)
    msg = str(info.value)
    assert re.search(r"t = (0\.9|1\.0)", msg), msg
    assert "singular" in msg or "dead-centre" in msg, msg
