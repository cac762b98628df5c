"""Redundant joint equations: Bricard's mechanism (IFToMM A04) against an independent
joint-coordinate reference and complex step of the whole run; a spatial four-bar written with
four revolutes against its planar_pin form; inconsistent redundancy and changes of rank refused."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

import dynsens
from bricard_reference import Bricard
from conftest import CASES
from dynsens.errors import CaseError, ModelError
from dynsens.models.base import StepState
from helpers import complex_step_gradients, pendulum_with_coaxial_hinges, rel_err


def _raw(name):
    return yaml.safe_load((CASES / f"{name}.yaml").read_text())


def test_bricard_drops_one_equation_and_follows_the_reference():
    """One of the 30 joint equations is dependent: exactly one is left out.  The COM paths
    agree with the joint-coordinate reference (DOP853, rtol 1e-12) to the trapezoidal rule's
    O(Δt²) error: 2.6e-6 m at Δt = 2 ms, a quarter of that at 1 ms."""
    ts = np.array([0.25, 0.5, 0.75, 1.0])
    ref, closure = Bricard().solve(ts)
    assert closure < 1e-9
    errs = []
    for dt in (2e-3, 1e-3):
        case = dynsens.load_case(CASES / "bricard.yaml", overrides=[f"integrator.dt={dt}"])
        m = case.model
        assert [(j, lab) for j, lab, _ in m.redundant] == [("J6", "v.w")]
        assert m.traits.n_lam == 30 + 5 - 1
        res = dynsens.run_case(case, sensitivities=False, history=("q",))
        assert res.status == "completed"
        idx = [int(np.argmin(abs(res.time - t))) for t in ts]
        q = res.history["q"][idx].reshape(len(ts), 5, 7)[:, :, :3]
        errs.append(np.max(np.abs(q - ref)))
        # the dropped equation holds along the run too (it is implied by the kept ones)
        assert res.monitors["constraint_position"].max() < 1e-5
    assert errs[0] < 5e-6
    assert 3.5 < errs[0] / errs[1] < 4.5          # second order: the error is the scheme's


def test_bricard_sensitivities_match_complex_step():
    case = dynsens.load_case(CASES / "bricard.yaml", overrides=["integrator.t_end=0.5"])
    res = dynsens.run_case(case, sensitivities=True)
    cs = complex_step_gradients(case)
    for name, r in res.responses.items():
        assert rel_err(r.gradient, cs[name]) < 1e-6, name


def test_four_bar_with_four_revolutes_equals_its_planar_pin_form():
    """The planar loop with four spatial revolutes has three redundant equations; the model
    without them is the planar_pin model: the same responses and gradients."""
    raw = _raw("four_bar")
    raw["integrator"]["t_end"] = 0.3
    ref = dynsens.run_case(dynsens.load_case_dict(raw))
    raw["model"]["joints"][3]["type"] = "revolute"           # O4 planar_pin -> revolute
    case = dynsens.load_case_dict(raw)
    assert [(j, lab) for j, lab, _ in case.model.redundant] == [("O4", "z"), ("O4", "u.w"), ("O4", "v.w")]
    res = dynsens.run_case(case)
    for name, r in ref.responses.items():
        assert abs(res.responses[name].value - r.value) <= 1e-10 * (1 + abs(r.value)), name
        assert rel_err(res.responses[name].gradient, r.gradient) < 1e-9, name


def test_inconsistent_redundancy_names_the_smallest_dependent_set():
    raw = _raw("four_bar")
    raw["model"]["joints"][3]["type"] = "revolute"
    raw["model"]["joints"][3]["axis"] = [0, 0.2, 1]          # tilted: the loop cannot close
    with pytest.raises(CaseError) as exc:
        dynsens.load_case_dict(raw, source="tilted_four_bar.yaml")
    msg = str(exc.value)
    assert "tilted_four_bar.yaml" in msg and "model.joints" in msg
    assert "inconsistent redundant joints" in msg and "O2, A, B, O4" in msg


def test_smallest_dependent_set_leaves_out_independent_joints():
    """A pendulum held by two coaxial revolutes plus an independent second body: only the two
    hinges are named."""
    from dynsens.models.multibody.assembly import jacobian_rows
    from dynsens.models.multibody.redundancy import smallest_dependent_joints
    raw = pendulum_with_coaxial_hinges(_raw("pendulum_3d"))
    case = dynsens.load_case_dict(raw)
    m = case.model
    assert {j for j, _, _ in m.redundant} == {"hinge2"}
    # all joints' equations (the full set) at the assembled pose
    prm = m.parameters(case.x0)
    q0 = m.initial_state(prm)[0]
    eqs = m.eqs + [eq for _, _, eq in m.redundant]
    J = np.real(jacobian_rows(eqs, q0, prm, 0.0))
    full = type("M", (), {})()
    full.eq_owner = m.eq_owner + [f"{j}.{lab}" for j, lab, _ in m.redundant]
    rows = {jt.name: list(jt.rows) for jt in m.joints}
    rows["hinge2"] = rows["hinge2"] + list(range(len(m.eqs), len(eqs)))
    full.joints = [type("J", (), {"name": n, "rows": r})() for n, r in rows.items()]
    assert smallest_dependent_joints(full, J) == ["pivot", "hinge2"]
    res = dynsens.run_case(case, sensitivities=False)
    assert res.status == "terminated"          # by the far-side event, as the one-hinge pendulum


def test_change_of_rank_is_an_error_naming_time_and_joints():
    """At a pose off the Bricard motion (rod3 turned about its own axis), the dropped equation
    is no longer implied by the kept ones: the model's step check refuses the state."""
    case = dynsens.load_case(CASES / "bricard.yaml")
    m = case.model
    prm = m.parameters(case.x0)
    q0, qd0, _ = m.initial_state(prm)
    z = np.zeros(m.traits.n_q)
    m.check_state(0.0, StepState(q0, qd0, z, np.zeros(m.traits.n_lam), z[:0], z[:0]), prm)   # fine
    q = q0.copy()
    c, s = np.cos(0.3), np.sin(0.3)
    q[7 * 2 + 3:7 * 2 + 7] = [c, 0.2 * s, 0.4 * s, np.sqrt(1 - 0.2) * s]                         # rod3 turned
    with pytest.raises(ModelError) as exc:
        m.check_state(0.125, StepState(q, qd0, z, np.zeros(m.traits.n_lam), z[:0], z[:0]), prm)
    msg = str(exc.value)
    assert "t = 0.125 s" in msg and "J6.v.w" in msg and "changed rank" in msg


def test_two_drivers_of_one_freedom_are_refused_when_they_part():
    """Both drivers hold at t0, so one of them is dependent there and left out; as soon as the
    prescribed motions disagree, the run stops naming it (never following one driver silently)."""
    from test_multibody_singular import CASE
    text = CASE.replace("AMP", "0.3").replace(
        "integrator: {", "    - {name: spin, type: driving, joint: O, rate: 0.2}\nintegrator: {")
    case = dynsens.case.load.load_case_text(text, "two_drivers.yaml")
    assert [(j, lab) for j, lab, _ in case.model.redundant] == [("spin", "drive")]
    with pytest.raises(ModelError) as exc:
        dynsens.run_case(case, sensitivities=False)
    msg = str(exc.value)
    assert "spin.drive" in msg and "do not hold here" in msg and "t = 0.01 s" in msg, msg


def test_a_singular_initial_pose_is_not_taken_for_redundancy():
    """The link starting upright, where its height driver and the hinge are dependent only at that
    pose: refused at load as a singular configuration, not run as a redundant mechanism."""
    from test_multibody_singular import CASE
    text = CASE.replace("position: [0.5, 0, 0]", "position: [0, 0.5, 0]\n      orientation: "
                        "{axis: [0, 0, 1], angle: 1.5707963267948966}").replace("AMP", "0.1")
    with pytest.raises(CaseError) as exc:
        dynsens.case.load.load_case_text(text, "apex_start.yaml")
    msg = str(exc.value)
    assert "apex_start.yaml" in msg and "initial pose is a singular configuration" in msg
    assert "joints O, lift" in msg
