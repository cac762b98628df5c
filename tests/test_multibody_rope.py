"""The ``rope`` force law (dynsens/models/multibody/laws/rope.py), added through the force-law
protocol alone: a bob hanging on a tension-only rope against the closed forms of a linear
oscillator (half period π/ω, ω² = EA/(m L0)) and of free fall while the rope is slack, the
rope's state Jacobian against its closed form and central differences, and the gradients of a
run (direct and adjoint) against the complex step of the whole run."""
from __future__ import annotations

import copy

import numpy as np
import pytest

import dynsens
from dynsens.errors import CaseError
from dynsens.models.multibody.residual import other_forces_jacobians, other_forces_q
from helpers import complex_step_gradients, rel_err

G = 9.81
M, EA, L0 = 1.0, 400.0, 1.0          # ω = 20 rad/s, static stretch m g L0 / EA = 24.5 mm

BASE = {
    "name": "rope_bob",
    "design": {"variables": [{"name": "m", "value": M, "lower": 0.5, "upper": 2.0},
                             {"name": "EA", "value": EA, "lower": 100.0, "upper": 1000.0}]},
    "model": {
        "type": "multibody", "gravity": [0, -G, 0],
        "bodies": {"ground": {"markers": {"O": [0, 0, 0]}},
                   "bob": {"point_mass": True, "mass": "m", "position": [0, -1.0, 0], "markers": {"c": [0, 0, 0]}}},
        "joints": [],
        "forces": [{"type": "rope", "name": "rope", "body_1": "ground", "point_1": "O", "body_2": "bob",
                    "point_2": "c", "stiffness": "EA", "free_length": L0}],
    },
    "integrator": {"scheme": "newmark", "dt": 1.0e-3, "t_end": 0.5},
    "sensitivity": {"enabled": True, "partials": "complex"},
}


def _case(y0: float, events: list, responses: list, **rope: object) -> dict:
    raw = copy.deepcopy(BASE)
    raw["model"]["bodies"]["bob"]["position"] = [0, y0, 0]
    raw["model"]["forces"][0].update(rope)
    raw["events"], raw["responses"] = events, responses
    return raw


LOWEST = [{"name": "lowest", "quantity": {"body": "bob", "kind": "velocity"}, "component": "bob.vy",
           "value": 0.0, "direction": "rising"}]
OSCILLATOR = _case(-(L0 + 0.5 * M * G * L0 / EA), LOWEST, [
    {"name": "half_period", "type": "event_time", "event": "lowest"},
    {"name": "y_low", "type": "value", "quantity": {"body": "bob", "kind": "position"}, "component": "bob.y",
     "event": "lowest"},
    {"name": "tension", "type": "ks", "quantity": {"element": "rope", "kind": "force"}, "rho": 50.0}])

TAUT = [{"name": "taut", "quantity": {"element": "rope", "kind": "length"}, "component": "rope.length",
         "value": L0, "direction": "rising"}]
DROP_H = 0.05                                                       # the bob starts 5 cm above taut
DROP = _case(-(L0 - DROP_H), TAUT, [{"name": "t_taut", "type": "event_time", "event": "taut"}])


def test_oscillator_half_period_and_lowest_point():
    """Released at rest with half the static stretch δ = m g L0/EA, the bob oscillates about
    y = −(L0 + δ) with amplitude δ/2 (the rope stays taut): its lowest point, −(L0 + 3δ/2), is
    reached after half a period π/ω, ω = √(EA/(m L0)) (linear oscillator, e.g. Meirovitch,
    Fundamentals of Vibrations, §2.1).  The trapezoidal rule lengthens the period by
    (ω Δt)²/12 = 3.3e-5 at Δt = 1 ms."""
    res = dynsens.run_case(dynsens.load_case_dict(OSCILLATOR), sensitivities=False)
    omega, delta = np.sqrt(EA / (M * L0)), M * G * L0 / EA
    assert abs(res.responses["half_period"].value / (np.pi / omega) - 1) < 1e-4
    assert abs(res.responses["y_low"].value + (L0 + 1.5 * delta)) < 1e-4 * delta * 1.5
    assert abs(res.responses["tension"].value / (EA * 1.5 * delta / L0) - 1) < 2e-2   # KS bound, ρ = 50


@pytest.mark.parametrize("switch", [{}, {"switch": "smooth", "width": 1e-6}])
def test_a_slack_rope_carries_no_compression(switch):
    """Released 5 cm above its free length, the bob falls freely until the rope is taut:
    t = √(2h/g).  The trapezoidal rule is exact for a constant acceleration; the event is found
    by interpolation over the step in which the rope becomes taut, whose end state already feels
    the rope (1.7e-6 of t at Δt = 1 ms: tolerance 1e-5); the smooth switch's residual tension,
    ≈ EA w²/(4 L0 h) = 1e-9 N, is far below it.  A rope that pushed (a spring, EA h/L0 = 20 N
    on 1 kg) would change t at the first order."""
    res = dynsens.run_case(dynsens.load_case_dict(_case(DROP["model"]["bodies"]["bob"]["position"][1],
                                                        TAUT, DROP["responses"], **switch)), sensitivities=False)
    assert abs(res.responses["t_taut"].value / np.sqrt(2 * DROP_H / G) - 1) < 1e-5


def test_a_rope_whose_ends_meet_is_slack():
    """The bob starts on the rope's anchor (length 0 < L0): the rope is slack and the bob falls
    freely, y = −g t²/2 (the trapezoidal rule is exact for a constant acceleration).  The force
    N d/L was 0/0 there: the run stopped with a NaN/Inf error."""
    raw = _case(0.0, [], [{"name": "y_end", "type": "value", "quantity": {"body": "bob", "kind": "position"},
                           "component": "bob.y"}])
    raw["integrator"]["t_end"] = 0.2
    res = dynsens.run_case(dynsens.load_case_dict(raw))
    assert res.responses["y_end"].value == pytest.approx(-0.5 * G * 0.2 ** 2, rel=1e-12)
    np.testing.assert_array_equal(res.responses["y_end"].gradient, [0.0, 0.0])     # free fall: no m, EA


@pytest.mark.parametrize("switch", [{}, {"switch": "smooth", "width": 2e-3}])
def test_rope_jacobian_matches_closed_form_and_differences(switch):
    """∂Q/∂r of a taut rope on a point (−K, K = N/L (I − n nᵀ) + (EA/L0) g′(e) n nᵀ, the
    geometric and material stiffness of an axial element) against the model's linearization
    (complex step of the residual) and central differences of the rope's force (rel. 1e-6)."""
    case = dynsens.load_case_dict(_case(-1.0, LOWEST, OSCILLATOR["responses"], **switch))
    model = case.model
    prm = model.parameters(case.x0)
    q = model.initial_state(prm)[0].copy()
    q[:3] = [0.01, -1.02, 0.005]                      # taut and off the axis: both terms count
    qd = np.zeros_like(q)
    Kq, Kqd = other_forces_jacobians(model, 0.0, q, qd, prm)
    r = q[:3]
    L = np.linalg.norm(r)
    n = r / L
    e = L - L0
    w = switch.get("width")
    g, dg = (e, 1.0) if w is None else (0.5 * (e + np.hypot(e, w)), 0.5 * (1 + e / np.hypot(e, w)))
    N = EA / L0 * g
    K = N / L * (np.eye(3) - np.outer(n, n)) + EA / L0 * dg * np.outer(n, n)
    assert rel_err(Kq[:3, :3], -K) < 1e-10
    h = 1e-6
    cd = np.zeros((3, 3))
    for j in range(3):
        qp, qm = q.copy(), q.copy()
        qp[j] += h
        qm[j] -= h
        cd[:, j] = (other_forces_q(model, 0.0, qp[None], qd[None], [prm])[0, :3]
                    - other_forces_q(model, 0.0, qm[None], qd[None], [prm])[0, :3]) / (2 * h)
    assert rel_err(Kq[:3, :3], cd) < 1e-6
    assert np.all(Kqd == 0)
    slack = q.copy()
    slack[:3] = [0.0, -0.9, 0.0]
    K_slack = other_forces_jacobians(model, 0.0, slack, qd, prm)[0][:3, :3]
    assert (np.all(K_slack == 0) if w is None else np.max(np.abs(K_slack)) < 1e-2 * EA)


@pytest.mark.parametrize("method", ["direct", "adjoint"])
@pytest.mark.parametrize("raw", [OSCILLATOR, _case(-(L0 + 0.5 * M * G * L0 / EA), LOWEST, OSCILLATOR["responses"],
                                                  switch="smooth", width=1e-3)], ids=["exact", "smooth"])
def test_rope_gradients_match_complex_step_of_the_run(raw, method):
    """d(half period, lowest point, KS tension)/d(m, EA): direct and adjoint against the complex
    step of the whole run (rel. 1e-7; complex partials), and the two modes agree (rel. 1e-10)."""
    raw = copy.deepcopy(raw)
    raw["sensitivity"]["method"] = method
    case = dynsens.load_case_dict(raw)
    res = dynsens.run_case(case)
    cs = complex_step_gradients(case)
    for name, r in res.responses.items():
        assert rel_err(r.gradient, cs[name]) < 1e-7, name
    other = copy.deepcopy(raw)
    other["sensitivity"]["method"] = "adjoint" if method == "direct" else "direct"
    res2 = dynsens.run_case(dynsens.load_case_dict(other))
    for name, r in res.responses.items():
        assert rel_err(r.gradient, res2.responses[name].gradient) < 1e-10, name


@pytest.mark.parametrize("edit, path, words", [
    (lambda f: f.pop("free_length"), "forces[0].free_length", "missing"),
    (lambda f: f.update(stiffness=-1.0), "forces[0].stiffness", ">"),
    (lambda f: f.update(switch="smooth"), "forces[0].width", "missing"),
    (lambda f: f.update(width=0.01), "forces[0].width", "smooth"),
    (lambda f: f.update(switch="soft"), "forces[0].switch", "soft"),
    (lambda f: f.update(point_2="nowhere"), "forces[0].point_2", "nowhere"),
])
def test_rope_input_errors(edit, path, words):
    raw = copy.deepcopy(OSCILLATOR)
    edit(raw["model"]["forces"][0])
    with pytest.raises(CaseError) as exc:
        dynsens.load_case_dict(raw, source="rope.yaml")
    msg = str(exc.value)
    assert "rope.yaml" in msg and path in msg and words in msg, msg


def test_rope_outputs_are_named_and_checked():
    raw = copy.deepcopy(OSCILLATOR)
    raw["responses"][2]["quantity"]["kind"] = "stroke"
    with pytest.raises(CaseError) as exc:
        dynsens.load_case_dict(raw, source="rope.yaml")
    assert "unknown rope quantity 'stroke'" in str(exc.value) and "length, force" in str(exc.value)
