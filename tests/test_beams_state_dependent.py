"""State-dependent structural terms: nonlinear viscous dampers F = c|v|^α sign v (regularized).

Contract (issue 14): a mass coasting against a damper alone follows the closed form
v^(1−α) = v0^(1−α) − (1−α)ct/m; α = 1 is the linear damper exactly; the Newton matrix's
∂F_R/∂q̇ equals complex step of the residual; the design sensitivities (c, α, ε, k, m) equal
complex step of the whole run; a damper with only one of exponent/regularization is rejected.
"""
from __future__ import annotations

import copy

import numpy as np
import pytest

import dynsens
from dynsens import CaseError
from dynsens.case.load import load_case_dict
from dynsens.models.base import StepState, as_dense
from helpers import complex_step_gradients

COAST = {
    "name": "coast",
    "model": {"type": "structural", "dofs": ["u"],
              "elements": [{"type": "mass", "name": "body", "dof": "u", "mass": 2.0},
                           {"type": "damper", "name": "fluid", "dofs": ["u", "ground"], "c": 3.0,
                            "exponent": 0.4, "regularization": 1e-7}],
              "initial": {"velocity": {"u": 1.5}}},
    "integrator": {"dt": 2e-4, "t_end": 0.6},
    "sensitivity": {"enabled": False},
    "responses": [{"name": "v_half", "type": "value", "quantity": {"dof": "u", "kind": "velocity"}, "time": 0.5},
                  {"name": "u_half", "type": "value", "quantity": {"dof": "u"}, "time": 0.5}],
}


def test_coasting_mass_follows_the_closed_form() -> None:
    m, c, a, v0, t = 2.0, 3.0, 0.4, 1.5, 0.5
    res = dynsens.run_case(load_case_dict(COAST))
    v = (v0 ** (1 - a) - (1 - a) * c * t / m) ** (1 / (1 - a))
    # u(t) = ∫ v dt = m/(c(2−α)) (v0^(2−α) − v^(2−α))
    u = m / (c * (2 - a)) * (v0 ** (2 - a) - v ** (2 - a))
    assert 0.1 < v < 1.0                                       # well before the mass stops (t ≈ 0.85 s)
    assert float(res.responses["v_half"].value) == pytest.approx(v, rel=1e-6)
    assert float(res.responses["u_half"].value) == pytest.approx(u, rel=1e-6)


def two_dof(exponent: float | str = "alpha", linear: bool = False) -> dict:
    damper = {"type": "damper", "name": "fluid", "dofs": ["top", "base"], "c": "c"}
    if not linear:
        damper.update(exponent=exponent, regularization="eps")
    return {
        "name": "two_dof_damper",
        "design": {"variables": [{"name": "c", "value": 40.0}, {"name": "alpha", "value": 0.35},
                                 {"name": "eps", "value": 0.02}, {"name": "k", "value": 5000.0},
                                 {"name": "m", "value": 1.5}]},
        "model": {"type": "structural", "dofs": ["base", "top"],
                  "elements": [{"type": "mass", "name": "mb", "dof": "base", "mass": 3.0},
                               {"type": "mass", "name": "mt", "dof": "top", "mass": "m"},
                               {"type": "spring", "name": "ground_spring", "dofs": ["base", "ground"], "k": 2.0e4},
                               {"type": "spring", "name": "link", "dofs": ["top", "base"], "k": "k"},
                               damper],
                  "loads": [{"dof": "base", "value": 300.0, "function": {"type": "harmonic", "frequency": 9.0}}]},
        "integrator": {"dt": 2e-3, "t_end": 0.6},
        "sensitivity": {"partials": "complex"},
        "responses": [{"name": "top_max", "type": "max", "quantity": {"dof": "top"}, "absolute": True},
                      {"name": "top_ks", "type": "ks", "quantity": {"dof": "top"}, "rho": 200.0},
                      {"name": "top_end", "type": "value", "quantity": {"dof": "top", "kind": "velocity"}}],
    }


def test_exponent_one_is_the_linear_damper() -> None:
    nl = dynsens.run_case(load_case_dict(two_dof(exponent=1.0)))
    lin = dynsens.run_case(load_case_dict(two_dof(linear=True)))
    for name in ("top_max", "top_ks", "top_end"):
        assert float(nl.responses[name].value) == pytest.approx(float(lin.responses[name].value), rel=1e-12)
        np.testing.assert_allclose(np.delete(nl.responses[name].gradient, [1, 2]),
                                   np.delete(lin.responses[name].gradient, [1, 2]), rtol=1e-10, atol=1e-14)


def test_velocity_jacobian_equals_complex_step_of_the_residual() -> None:
    case = load_case_dict(two_dof())
    model = case.model
    params = model.parameters(case.x0)
    rng = np.random.default_rng(0)
    empty = np.zeros(0)
    for scale in (1e-3, 0.05, 2.0):                            # below, near and above ε
        q, qd, qdd = rng.normal(size=(3, 2)) * [[1.0], [scale], [1.0]]
        lin = model.linearize(0.0, StepState(q, qd, qdd, empty, empty, empty), params)
        cs = np.zeros((2, 2))
        for j in range(2):
            d = qd.astype(complex)
            d[j] += 1e-30j
            cs[:, j] = np.imag(model.residual(0.0, StepState(q, d, qdd, empty, empty, empty), params)) / 1e-30
        np.testing.assert_allclose(as_dense(lin.R_qd), cs, rtol=1e-13, atol=1e-13 * np.abs(cs).max())


def test_damper_sensitivities_equal_complex_step_of_the_whole_run() -> None:
    case = load_case_dict(two_dof())
    res = dynsens.run_case(case)
    cs = complex_step_gradients(case)
    for name, rv in res.responses.items():
        assert np.abs(cs[name][:3]).min() > 0                 # c, α and ε all matter
        np.testing.assert_allclose(np.real(rv.gradient), cs[name], rtol=1e-8,
                                   atol=1e-10 * np.abs(cs[name]).max(), err_msg=name)


@pytest.mark.parametrize("drop", ["exponent", "regularization"])
def test_nonlinear_damper_needs_exponent_and_regularization(drop: str) -> None:
    raw = copy.deepcopy(COAST)
    del raw["model"]["elements"][1][drop]
    with pytest.raises(CaseError, match="needs 'exponent'"):
        load_case_dict(raw)


# ---------------------------------------------------------------------- follower loads
E_STIFF, RHO, LEN = 2.1e7, 7.85e-9, 1000.0          # a stiff tube rod: it turns as a rigid body


def rod(follower: bool = True, n_el: int = 4, design: list | None = None, value: float | str = 1000.0,
        mass: str = "lumped") -> dict:
    """A rod along x pinned at n0 (free to turn), pushed at its tip by a force along the tip's
    local y axis (perpendicular to the rod as it turns when ``follower``)."""
    nodes = {f"n{i}": {"coords": [f"L*{i}/{n_el}" if design else LEN * i / n_el, 0.0]} for i in range(n_el + 1)}
    nodes["n0"]["fixed"] = ["x", "y"]
    section = {"shape": "tube", "D": "D" if design else 40.0, "t": 3.0}
    elements = [{"type": "beam", "name": f"b{i}", "nodes": [f"n{i}", f"n{i + 1}"], "E": E_STIFF,
                 "density": RHO, "section": section, "mass": mass} for i in range(n_el)]
    load = {"node": f"n{n_el}", "direction": "y", "value": value, "function": "constant"}
    if follower:
        load["follower"] = True
    return {"name": "rod", "design": {"variables": design or []},
            "model": {"type": "structural", "dim": 2, "nodes": nodes, "elements": elements, "loads": [load]},
            "integrator": {"dt": 1e-4, "t_end": 0.05},
            "sensitivity": {"enabled": bool(design), "partials": "complex"},
            "responses": [{"name": "angle", "type": "value", "quantity": {"dof": f"n{n_el}.rz"}},
                          {"name": "tip_x", "type": "value", "quantity": {"dof": f"n{n_el}.x"}},
                          {"name": "tip_y_max", "type": "max", "quantity": {"dof": f"n{n_el}.y"}}]}


def polar_inertia(case) -> float:
    """J = φᵀMφ of the rigid rotation about the pin (φ: x_i on y DOFs, 1 on rotations)."""
    model = case.model
    params = model.parameters(case.x0)
    names = model.dof_labels()
    phi = np.array([float(nm[1:].split(".")[0]) * LEN / 4 if nm.endswith(".y") else
                    1.0 if nm.endswith(".rz") else 0.0 for nm in names])
    n = len(names)
    M = as_dense(model.linearize(0.0, StepState(*np.zeros((3, n)), *np.zeros((3, 0))), params).R_z)
    return float(phi @ M @ phi)


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_follower_force_turns_a_rod_with_constant_angular_acceleration(mass: str) -> None:
    """A force that stays perpendicular to the rod gives the moment PL at every angle:
    θ(t) = PLt²/(2J); a dead force of the same size gives PL cos θ and turns it less.  With
    consistent mass this holds only because the mass turns with the rod (J is invariant)."""
    case = load_case_dict(rod(mass=mass))
    res = dynsens.run_case(case)
    t, P = 0.05, 1000.0
    theta = P * LEN * t ** 2 / (2 * polar_inertia(case))
    assert 1.0 < theta < 2.5                                    # a large rotation
    assert float(res.responses["angle"].value) == pytest.approx(theta, rel=1e-4)
    assert float(res.responses["tip_x"].value) == pytest.approx(LEN * (np.cos(theta) - 1), rel=1e-3)
    # the dead force: J θ'' = PL cos θ, integrated to round-off
    from scipy.integrate import solve_ivp
    k = P * LEN / polar_inertia(case)
    ref = solve_ivp(lambda _, y: [y[1], k * np.cos(y[0])], (0.0, t), [0.0, 0.0], rtol=1e-12, atol=1e-12).y[0, -1]
    dead = float(dynsens.run_case(load_case_dict(rod(follower=False, mass=mass))).responses["angle"].value)
    assert dead == pytest.approx(ref, rel=1e-4) and dead < 0.97 * theta


def test_follower_jacobian_equals_complex_step_of_the_residual() -> None:
    case = load_case_dict(rod(value="P*sin(0.5)", design=[{"name": "P", "value": 400.0},
                                                            {"name": "L", "value": LEN}, {"name": "D", "value": 40.0}]))
    model = case.model
    params = model.parameters(case.x0)
    n = model.traits.n_q
    rng = np.random.default_rng(5)
    q, qd, qdd = rng.normal(size=(3, n)) * 0.7
    empty = np.zeros(0)
    lin = model.linearize(0.01, StepState(q, qd, qdd, empty, empty, empty), params)
    cs = np.zeros((n, n))
    for j in range(n):
        d = q.astype(complex)
        d[j] += 1e-30j
        cs[:, j] = np.imag(model.residual(0.01, StepState(d, qd, qdd, empty, empty, empty), params)) / 1e-30
    np.testing.assert_allclose(as_dense(lin.R_q), cs, rtol=1e-12, atol=1e-12 * np.abs(cs).max())


def test_follower_sensitivities_equal_complex_step_of_the_whole_run() -> None:
    raw = rod(design=[{"name": "P", "value": 400.0}, {"name": "L", "value": LEN}, {"name": "D", "value": 40.0}],
              value="P", mass="consistent")
    raw["model"]["elements"] = [dict(el, E=2.1e5) for el in raw["model"]["elements"]]   # flexible now
    raw["integrator"]["t_end"] = 0.02
    case = load_case_dict(raw)
    res = dynsens.run_case(case)
    cs = complex_step_gradients(case)
    for name, rv in res.responses.items():
        np.testing.assert_allclose(np.real(rv.gradient), cs[name], rtol=1e-8,
                                   atol=1e-10 * np.abs(cs[name]).max(), err_msg=name)


@pytest.mark.parametrize("change, path, needle", [
    ({"follower": "yes"}, "model.loads[0].follower", "true or false"),
    ({"direction": "rz"}, "model.loads[0].direction", "local x or y"),
    ({"node": "nowhere"}, "model.loads[0].node", "rotation"),
])
def test_bad_follower_loads_are_reported(change, path, needle) -> None:
    raw = rod()
    raw["model"]["loads"][0].update(change)
    with pytest.raises(CaseError) as err:
        load_case_dict(raw)
    msgs = [p.message for p in err.value.problems if p.path == path]
    assert any(needle in m for m in msgs), [str(p) for p in err.value.problems]


def test_damper_forces_are_outputs_with_exact_gradients() -> None:
    """{element: fluid, kind: force} reads F(v) of the nonlinear damper (and c·v of a linear
    one); their KS/max gradients equal complex step of the whole run."""
    raw = two_dof()
    raw["model"]["elements"].append({"type": "damper", "name": "plain", "dofs": ["base", "ground"], "c": 15.0})
    raw["output"] = {"history": ["qd"]}
    raw["responses"] = [
        {"name": "fluid_max", "type": "max", "quantity": {"element": "fluid", "kind": "force"}, "absolute": True},
        {"name": "both_ks", "type": "ks", "quantity": {"element": ["plain", "fluid"], "kind": "force"},
         "absolute": True, "rho": 0.05}]
    case = load_case_dict(raw)
    res = dynsens.run_case(case)
    x = dict(zip(case.design_names, case.x0))
    qd = np.real(res.history["qd"])
    v = qd[:, 1] - qd[:, 0]
    F = x["c"] * v * (v * v + x["eps"] ** 2) ** ((x["alpha"] - 1) / 2)
    assert float(res.responses["fluid_max"].value) == pytest.approx(np.abs(F).max(), rel=1e-12)
    cs = complex_step_gradients(case)
    for name, rv in res.responses.items():
        np.testing.assert_allclose(np.real(rv.gradient), cs[name], rtol=1e-8,
                                   atol=1e-10 * np.abs(cs[name]).max(), err_msg=name)
    with pytest.raises(CaseError, match="dampers report only 'force'"):
        raw["responses"][0]["quantity"]["kind"] = "stress"
        load_case_dict(raw)
