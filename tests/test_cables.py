"""Tension-only cables (dynsens/models/structural/elements/cables.py): a cable is a Green–Lagrange bar whose
axial force is EA·max(ε, 0) (exact switch) or EA·½(ε + √(ε² + w²)) (smooth switch, width w).

Closed forms on a node held by a spring k to ground and a cable of length L to a support, loaded
along the cable by P: in tension the cable pulls as a bar, k u + EA ε (L + u)/L = P with
ε = ((L + u)² − L²)/(2L²) (the total-Lagrangian bar's nodal force N d/L); in compression the
slack cable carries nothing, u = P/k exactly (a bar would carry compression: another u).
Sensitivities of a dynamic run in which the cable goes taut and slack (smooth switch) equal the
complex step of the whole run, and the adjoint equals the direct.
"""
from __future__ import annotations

import numpy as np
import pytest

import dynsens
from dynsens.case.load import load_case_dict
from dynsens.models.base import StepState, as_dense
from dynsens.models.structural.elements.cables import switch
from helpers import assert_gradients_match_complex_step_and_adjoint

L, E, AREA, K = 1.0, 1.0e4, 0.01, 10.0          # consistent units (EA = 100, k = 10)


def cable_case(load: float, *, kind: str = "cable", law: dict | None = None, v0: float = 0.0) -> dict:
    """A support a at the origin, node b at (L, 0) (y fixed) with a point mass, a spring k from
    b.x to ground and a cable (or bar) a–b; the load P on b along x."""
    element = {"type": kind, "name": "c1", "nodes": ["a", "b"], "area": AREA, "E": E}
    element.update(law or {})
    return {"name": "cable", "design": {"variables": []},
            "model": {"type": "structural", "dim": 2,
                      "nodes": {"a": {"coords": [0.0, 0.0], "fixed": "all"},
                                "b": {"coords": [L, 0.0], "fixed": ["y"]}},
                      "elements": [element, {"type": "spring", "name": "s", "dofs": ["b.x", "ground"], "k": K},
                                   {"type": "mass", "name": "m", "dof": "b.x", "mass": 1.0}],
                      "loads": [{"node": "b", "direction": "x", "value": load}] if load else [],
                      "initial": {"velocity": {"b.x": v0}} if v0 else {}},
            "integrator": {"dt": 1e-2, "t_end": 1e-2}, "sensitivity": {"enabled": False}}


def static_u(raw: dict) -> float:
    """Static equilibrium u of b.x by Newton on the model's own residual and tangent."""
    case = load_case_dict(raw)
    model, params = case.model, case.model.parameters(case.x0)
    empty, zero = np.zeros(0), np.zeros(1)
    q = np.zeros(1)
    for _ in range(60):
        s = StepState(q, zero, zero, empty, empty, empty)
        R = model.residual(0.0, s, params)
        if abs(R[0]) < 1e-13:
            return float(q[0])
        q = q - np.linalg.solve(as_dense(model.linearize(0.0, s, params).R_q), R)
    raise AssertionError("static Newton did not converge")


def test_a_taut_cable_pulls_as_the_green_lagrange_bar() -> None:
    P = 2.0
    u = static_u(cable_case(P))
    strain = ((L + u) ** 2 - L ** 2) / (2 * L ** 2)
    assert u > 0
    assert K * u + E * AREA * strain * (L + u) / L == pytest.approx(P, rel=1e-12)


def test_a_slack_cable_carries_no_compression() -> None:
    P = -0.5
    assert static_u(cable_case(P)) == pytest.approx(P / K, rel=1e-13)
    # a bar in its place carries the compression: the closed form above tells them apart
    assert abs(static_u(cable_case(P, kind="bar")) - P / K) > 0.5 * abs(P / K)


def test_the_switch_laws_values_slopes_and_limit() -> None:
    eps = np.array([-2e-3, -1e-6, 0.0, 1e-6, 3e-3])
    g, dg = switch(eps, None)
    np.testing.assert_array_equal(g, np.maximum(eps, 0.0))
    np.testing.assert_array_equal(dg, (eps > 0).astype(float))
    w = 1e-4
    g_s, dg_s = switch(eps, w)
    assert g_s[2] == pytest.approx(w / 2, rel=1e-15)        # just taut at ε = 0
    assert np.all(np.abs(g_s - np.maximum(eps, 0)) <= w / 2 + 1e-18)
    assert np.all(np.diff(g_s) > 0) and np.all((dg_s > 0) & (dg_s < 1))
    h = 1e-30                                                # its slope: the complex step of g
    np.testing.assert_allclose(np.imag(switch(eps + 1j * h, w)[0]) / h, dg_s, rtol=1e-14)
    # the smooth static solutions tend to the exact ones as the width shrinks
    exact = static_u(cable_case(-0.5))
    gaps = [abs(static_u(cable_case(-0.5, law={"switch": "smooth", "width": w})) - exact)
            for w in (1e-2, 1e-3, 1e-4)]
    assert gaps[0] > gaps[1] > gaps[2] and gaps[2] < 1e-4 * abs(exact)


@pytest.mark.parametrize("law, key", [({"switch": "smooth"}, "width"), ({"width": 1e-3}, "width"),
                                      ({"switch": "soft", "width": 1e-3}, "switch")])
def test_a_switch_without_its_width_or_an_unknown_one_is_one_problem_at_its_key(law: dict, key: str) -> None:
    with pytest.raises(dynsens.CaseError, match=rf"elements\[0\]\.{key}"):
        load_case_dict(cable_case(1.0, law=law))


def test_a_mass_on_a_spring_and_a_cable_swings_as_the_bilinear_oscillator() -> None:
    """Released at rest length with velocity v0: taut while u > 0 (stiffness k + EA/L), slack
    while u < 0 (k alone), so u_max = v0/ω₁ and u_min = −v0/ω₀ with ω₁² = (k + EA/L)/m and
    ω₀² = k/m (small amplitude: the Green–Lagrange strain is linear to 1e-4 here)."""
    v0 = 1e-3
    raw = cable_case(0.0, v0=v0)
    raw["integrator"] = {"dt": 1e-3, "t_end": 1.0}
    raw["responses"] = [{"name": "u_max", "type": "max", "quantity": {"dof": "b.x"}},
                        {"name": "u_min", "type": "min", "quantity": {"dof": "b.x"}}]
    res = dynsens.run_case(load_case_dict(raw))
    w1, w0 = np.sqrt(K + E * AREA / L), np.sqrt(K)
    assert float(res.responses["u_max"].value) == pytest.approx(v0 / w1, rel=2e-3)
    assert float(res.responses["u_min"].value) == pytest.approx(-v0 / w0, rel=2e-3)


def test_output_force_and_stress_of_a_slack_and_a_taut_cable() -> None:
    raw = cable_case(0.0, v0=0.05)
    raw["integrator"] = {"dt": 1e-2, "t_end": 0.6}
    raw["responses"] = [{"name": "N_max", "type": "max", "quantity": {"element": "c1", "kind": "force"}},
                        {"name": "N_min", "type": "min", "quantity": {"element": "c1", "kind": "force"}}]
    res = dynsens.run_case(load_case_dict(raw))
    assert res.status == "completed"
    assert float(res.responses["N_max"].value) > 0.1
    assert float(res.responses["N_min"].value) == 0.0            # never in compression


def test_sensitivities_of_a_run_through_taut_and_slack_equal_the_complex_step_and_adjoint() -> None:
    raw = cable_case(0.0, law={"switch": "smooth", "width": "w"}, v0=0.05)
    raw["model"]["elements"][0]["area"] = "A"
    raw["design"]["variables"] = [{"name": "A", "value": AREA, "lower": 1e-3, "upper": 0.1},
                                  {"name": "w", "value": 1e-3, "lower": 1e-5, "upper": 1e-2}]
    raw["integrator"] = {"dt": 1e-2, "t_end": 0.5}
    raw["sensitivity"] = {"partials": "complex"}
    raw["responses"] = [{"name": "u_end", "type": "value", "quantity": {"dof": "b.x"}},
                        {"name": "N_ks", "type": "ks", "quantity": {"element": "c1", "kind": "force"}, "rho": 50.0}]
    case = load_case_dict(raw)
    res = dynsens.run_case(case)
    assert res.status == "completed"
    assert_gradients_match_complex_step_and_adjoint(case, res)
