"""Slider-crank and four-bar in 3D: planar motion, zero out-of-plane reactions, sensitivities
against complex step of the whole run, assembly errors and case-file problems."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

import dynsens
from conftest import CASES
from dynsens.errors import CaseError, ModelError
from dynsens.models.base import StepState
from helpers import complex_step_gradients, rel_err


def _states(res):
    h = res.history
    return [StepState(*(h[f][i] for f in ("q", "qd", "qdd", "lam", "p", "pd"))) for i in range(len(res.time))]


def _quantity(case, spec):
    from dynsens.errors import ProblemCollector
    pc = ProblemCollector()
    out = case.model.output(spec, "q", pc)
    assert out is not None, pc.problems
    return out


@pytest.mark.parametrize("name, joints", [("slider_crank", ("O", "A", "P")),
                                          ("four_bar", ("O2", "A", "B"))])
def test_planar_motion_and_zero_out_of_plane_reactions(name, joints):
    case = dynsens.load_case(CASES / f"{name}.yaml", overrides=["integrator.t_end=0.4"])
    res = dynsens.run_case(case, sensitivities=False, history=("q", "qd", "qdd", "lam", "p", "pd"))
    assert res.status == "completed"
    q = res.history["q"]
    nb = q.shape[1] // 7
    for i in range(nb):
        assert np.max(np.abs(q[:, 7 * i + 2])) < 1e-12          # z of every COM
        assert np.max(np.abs(q[:, 7 * i + 4:7 * i + 6])) < 1e-12  # e1, e2: rotation about z only
    states = _states(res)
    prm = case.model.parameters(case.x0)
    for j in joints:
        F = _quantity(case, {"joint": j, "kind": "reaction_force"})
        M = _quantity(case, {"joint": j, "kind": "reaction_moment"})
        Fn = _quantity(case, {"joint": j, "kind": "reaction_force_norm"})
        f = np.array([F.fn(t, s, prm) for t, s in zip(res.time, states)])
        mom = np.array([M.fn(t, s, prm) for t, s in zip(res.time, states)])
        scale = np.max(np.abs(f))
        assert scale > 0.1
        assert np.max(np.abs(f[:, 2])) < 1e-9 * scale, j
        assert np.max(np.abs(mom[:, :2])) < 1e-9 * scale, j
        fn = np.array([Fn.fn(t, s, prm)[0] for t, s in zip(res.time, states)])
        assert np.allclose(fn, np.linalg.norm(f, axis=1), rtol=1e-12)
    assert res.monitors["constraint_position"].max() < 2e-5


def test_slider_crank_kinematics_and_force_balance():
    """Slider position follows the closed-form crank-slider relation; with the crank driven
    at 2π rad/s the run returns to its start after one revolution."""
    case = dynsens.load_case(CASES / "slider_crank.yaml", overrides=["integrator.dt=5e-3"])
    res = dynsens.run_case(case, sensitivities=False)
    l1, l2 = 0.1, 0.3
    th = np.pi / 6 + 2 * np.pi * res.time
    x_exact = l1 * np.cos(th) + np.sqrt(l2 ** 2 - (l1 * np.sin(th)) ** 2)
    assert np.max(np.abs(res.history["q"][:, 14] - x_exact)) < 1e-4


@pytest.mark.parametrize("name", ["slider_crank", "four_bar"])
def test_sensitivities_match_complex_step_of_whole_run(name):
    """Responses (KS of reaction forces, end values, integral) and the state/multiplier
    sensitivities at the end, against complex step of the whole simulation: 1e-8 relative."""
    case = dynsens.load_case(CASES / f"{name}.yaml",
                             overrides=["integrator.t_end=0.1", "integrator.dt=5e-3",
                                        "output.sensitivity_history=true", "output.history=all"])
    res = dynsens.run_case(case)
    cs = complex_step_gradients(case)
    for rname, rv in res.responses.items():
        assert rel_err(rv.gradient, cs[rname]) < 1e-8, rname
    x0 = case.x0
    for j in range(x0.size):
        x = x0.astype(complex)
        h = 1e-20 * max(abs(x0[j]), 1.0)
        x[j] += 1j * h
        r = dynsens.run_case(case, x, history=("q", "lam"))
        for f in ("q", "lam"):
            ref = np.imag(r.history[f][-1]) / h
            dd = res.sensitivity_history[f][-1][:, j]
            assert np.linalg.norm(dd - ref) <= 1e-8 * max(np.linalg.norm(ref), 1e-8), (f, j)


def _raw(name):
    return yaml.safe_load((CASES / f"{name}.yaml").read_text())


def test_unassemblable_mechanism_names_residual_and_joint():
    raw = _raw("four_bar")
    raw["model"]["bodies"]["rocker"]["markers"]["B"] = [2.0, 0, 0]   # rocker far too long
    case = dynsens.load_case_dict(raw)
    with pytest.raises(ModelError) as exc:
        dynsens.run_case(case, sensitivities=False)
    msg = str(exc.value)
    assert "assembly failed" in msg and "‖Φ‖" in msg and "largest joint residual" in msg
    assert any(f"'{j}." in msg for j in ("A", "B", "O4", "O2"))


def test_case_problems_are_collected_with_paths():
    raw = _raw("slider_crank")
    m = raw["model"]
    m["bodies"]["rod"]["mas"] = 1.0
    m["joints"][1]["body_2"] = "rood"
    m["joints"][2]["marker_1"] = "C"
    m["joints"].append({"name": "X", "type": "revolut", "body_1": "ground", "body_2": "rod"})
    m["forces"] = [{"type": "point_force", "body": "slider", "point": "B", "forc": [1, 0, 0]}]
    with pytest.raises(CaseError) as exc:
        dynsens.load_case_dict(raw)
    msg = str(exc.value)
    for expected in ("model.bodies.rod.mas: unknown key; did you mean 'mass'?",
                     "model.joints[1].body_2: unknown body 'rood'; did you mean 'rod'?",
                     "model.joints[2].marker_1: body 'rod' has no marker 'C'",
                     "model.joints[5].type: unknown joint type 'revolut'; did you mean 'revolute'?",
                     "model.forces[0].forc: unknown key; did you mean 'force'?"):
        assert expected in msg, (expected, msg)
    # quantities are resolved once the model is valid
    raw = _raw("slider_crank")
    raw["responses"][0]["quantity"] = {"joint": "AA", "kind": "reaction_force_norm"}
    raw["responses"][1]["quantity"] = {"body": "slider", "kind": "positon"}
    raw["responses"][2]["quantity"] = {"element": "cyl", "kind": "stroke"}
    with pytest.raises(CaseError) as exc:
        dynsens.load_case_dict(raw)
    msg = str(exc.value)
    for expected in ("responses[0].quantities[0].joint: unknown joint 'AA'; did you mean 'A'?",
                     "responses[1].quantity.kind: unknown body quantity 'positon'; did you mean 'position'?",
                     "responses[2].quantities[0].element: unknown element 'cyl'"):
        assert expected in msg, (expected, msg)


def test_dof_and_multiplier_labels():
    case = dynsens.load_case(CASES / "slider_crank.yaml")
    labels = case.model.dof_labels()
    assert labels[:7] == ["crank.x", "crank.y", "crank.z", "crank.e0", "crank.e1", "crank.e2", "crank.e3"]
    lam = case.model.multiplier_labels()
    assert lam[0] == "O.x" and "drive.drive" in lam and lam[-1] == "slider.normalization"
    assert len(lam) == case.model.traits.n_lam == 5 + 5 + 2 + 5 + 1 + 3


def test_reaction_sign_conventions_static_hanging_body():
    """A body hanging at rest from a revolute: the joint pushes body_2 up with m g, the
    moment about the joint point is zero, joint-frame components follow the joint axes."""
    raw = yaml.safe_load((CASES / "pendulum_3d.yaml").read_text())
    raw["model"]["bodies"]["bob"]["position"] = [0, "-L", 0]
    raw["model"]["joints"][0]["axis"] = [1, 0, 0]
    raw["events"], raw["responses"] = [], []
    raw["integrator"]["t_end"] = 0.01
    case = dynsens.load_case_dict(raw)
    res = dynsens.run_case(case, sensitivities=False, history=("q", "qd", "qdd", "lam", "p", "pd"))
    s = _states(res)[-1]
    prm = case.model.parameters(case.x0)
    f = _quantity(case, {"joint": "pivot", "kind": "reaction_force"}).fn(0.01, s, prm)
    m = _quantity(case, {"joint": "pivot", "kind": "reaction_moment"}).fn(0.01, s, prm)
    fj = _quantity(case, {"joint": "pivot", "kind": "reaction_force_joint_frame"}).fn(0.01, s, prm)
    assert np.allclose(f, [0.0, 9.81, 0.0], atol=1e-9)
    assert np.allclose(m, 0.0, atol=1e-9)
    # joint frame (u, v, w = x): w-component 0, in-plane magnitude m g
    assert abs(fj[2]) < 1e-9 and abs(np.hypot(fj[0], fj[1]) - 9.81) < 1e-9
    assert np.max(np.abs(res.history["qdd"])) < 1e-9


def test_prismatic_reaction_has_no_axial_component():
    case = dynsens.load_case(CASES / "slider_crank.yaml", overrides=["integrator.t_end=0.1"])
    res = dynsens.run_case(case, sensitivities=False, history=("q", "qd", "qdd", "lam", "p", "pd"))
    prm = case.model.parameters(case.x0)
    out = _quantity(case, {"joint": "P", "kind": "reaction_force_joint_frame"})
    fj = np.array([out.fn(t, s, prm) for t, s in zip(res.time, _states(res))])
    assert np.max(np.abs(fj[:, :2])) > 1.0 and np.max(np.abs(fj[:, 2])) < 1e-9
