"""Stiffness-proportional Rayleigh damping on co-rotational members (issue 38, first bullet).

Contract: β K acts on the element's deformation rates in its co-rotated frame
(:mod:`dynsens.models.structural.corotated_damping`), for bars, plane beams and co-rotational 3D beams:
- a member turning rigidly feels no damping force (before this change, D_R = α M + β K₀ acted
  on the total rates in global axes and resisted rigid rotation: these tests failed);
- at q = 0 it equals the former β K₀ q̇ exactly, and `corotated: false` keeps the former term;
- its Jacobians ∂F_R/∂q and ∂F_R/∂q̇ equal the complex step of the residual at a large-rotation
  state;
- a cantilever under a suddenly applied tip load PL²/EI = 1 settles on the elastica's tip
  deflection (Bisshopp & Drucker, Q. Appl. Math. 3 (1945) 272: w/L = 0.30172, u/L = 0.05643);
- the design gradients through it equal the complex step of the whole run, and adjoint = direct.
"""
from __future__ import annotations

import numpy as np
import pytest

import dynsens
from dynsens.case.load import load_case_dict
from dynsens.models.base import StepState, as_dense
from dynsens.models.structural.beams import section_properties
from helpers import assert_gradients_match_complex_step_and_adjoint, complex_step_jacobians
from test_beams import E, L, RHO, TUBE, cantilever, static_solution, tip

G = 81000.0                                      # MPa
EMPTY = np.zeros(0)


def _structure(dim: int, elements: list, nodes: dict, beta: float, corotated: bool = True) -> dict:
    return {"name": "rigid", "design": {"variables": []},
            "model": {"type": "structural", "dim": dim, "nodes": nodes, "elements": elements, "loads": [],
                      "damping": {"rayleigh": {"alpha": 0.0, "beta": beta, "corotated": corotated}}},
            "integrator": {"dt": 1e-3, "t_end": 1e-3}, "sensitivity": {"enabled": False}}


def plane_beam(beta: float, corotated: bool = True) -> dict:
    """One free plane beam n0 (0, 0) → n1 (L, 0) (mm, s, t, N, MPa)."""
    return _structure(2, [{"type": "beam", "name": "b", "nodes": ["n0", "n1"], "E": E, "density": RHO,
                           "section": dict(TUBE), "mass": "lumped"}],
                      {"n0": {"coords": [0.0, 0.0]}, "n1": {"coords": [L, 0.0]}}, beta, corotated)


def bar(dim: int, beta: float, corotated: bool = True) -> dict:
    """One free bar n0 (0, …) → n1 (L, 0, …)."""
    zero = [0.0] * (dim - 1)
    return _structure(dim, [{"type": "bar", "name": "b", "nodes": ["n0", "n1"], "area": 700.0, "E": E,
                             "density": RHO}],
                      {"n0": {"coords": [0.0] + zero}, "n1": {"coords": [L] + zero}}, beta, corotated)


def space_beam(beta: float, corotated: bool = True) -> dict:
    """One free co-rotational 3D beam n0 (0, 0, 0) → n1 (L, 0, 0), a box section."""
    return _structure(3, [{"type": "beam", "name": "b", "nodes": ["n0", "n1"], "E": E, "G": G, "density": RHO,
                           "section": {"shape": "box", "b": 60.0, "h": 90.0, "t": 4.0},
                           "kinematics": "corotational", "mass": "lumped"}],
                      {"n0": {"coords": [0.0, 0.0, 0.0]}, "n1": {"coords": [L, 0.0, 0.0]}}, beta, corotated)


def _rotation(axis: np.ndarray, theta: float) -> np.ndarray:
    """Rodrigues' rotation matrix for the unit axis and angle θ (rad)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(theta) * k + (1 - np.cos(theta)) * k @ k


def rigid_state(raw: dict, theta: float, omega: float) -> tuple[np.ndarray, np.ndarray]:
    """(q, q̇) of the model turned rigidly about n0 by θ (rad) at the rate ω (rad/s): about z in
    the plane, about a skew axis in space (nodal rotation vectors θ·axis, rates ω·axis)."""
    dim = raw["model"]["dim"]
    case = load_case_dict(raw)
    names = case.model.dof_labels()
    axis = np.array([0.0, 0.0, 1.0]) if dim == 2 else np.array([1.0, 2.0, 2.0]) / 3.0
    R = _rotation(axis, theta)
    q, qd = np.zeros(len(names)), np.zeros(len(names))
    for node, spec in raw["model"]["nodes"].items():
        X = np.array(spec["coords"] + [0.0] * (3 - dim))
        x = R @ X
        v = omega * np.cross(axis, x)
        for k, a in enumerate("xyz"[:dim]):
            if f"{node}.{a}" in names:
                q[names.index(f"{node}.{a}")], qd[names.index(f"{node}.{a}")] = x[k] - X[k], v[k]
        for k, a in enumerate(("rx", "ry", "rz")):
            if f"{node}.{a}" in names:
                q[names.index(f"{node}.{a}")], qd[names.index(f"{node}.{a}")] = theta * axis[k], omega * axis[k]
    return q, qd


def residual(raw: dict, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    case = load_case_dict(raw)
    return case.model.residual(0.0, StepState(q, qd, np.zeros_like(q), EMPTY, EMPTY, EMPTY),
                               case.model.parameters(case.x0))


KINDS = {"plane beam": plane_beam, "bar 2D": lambda b, c=True: bar(2, b, c),
         "bar 3D": lambda b, c=True: bar(3, b, c), "space beam": space_beam}


@pytest.mark.parametrize("kind", list(KINDS))
def test_a_rigidly_turning_member_feels_no_rayleigh_stiffness_damping(kind: str) -> None:
    make, beta = KINDS[kind], 1e-3
    q, qd = rigid_state(make(beta), theta=1.0, omega=2.0)
    force = residual(make(beta), q, qd) - residual(make(0.0), q, qd)
    former = residual(make(beta, False), q, qd) - residual(make(0.0), q, qd)
    assert np.max(np.abs(former)) > 1.0          # N: the former β K₀ q̇ resisted the rotation
    assert np.max(np.abs(force)) <= 1e-9 * np.max(np.abs(former))


@pytest.mark.parametrize("kind", list(KINDS))
def test_at_rest_and_for_small_rotations_it_is_the_classical_beta_K0(kind: str) -> None:
    make, beta = KINDS[kind], 1e-3
    n = len(load_case_dict(make(beta)).model.dof_labels())
    rng = np.random.default_rng(7)
    qd = rng.normal(size=n)
    zero = np.zeros(n)
    new, old = residual(make(beta), zero, qd), residual(make(beta, False), zero, qd)
    np.testing.assert_allclose(new, old, rtol=1e-12, atol=1e-12 * np.abs(old).max())
    # a displacement of 1e-6 of the member's size moves the damping force by O(1e-6)
    scale = np.where([lab.split(".")[1].startswith("r") for lab in load_case_dict(make(beta)).model.dof_labels()],
                     1e-6, 1e-6 * L)
    q = scale * rng.normal(size=n)
    new, old = residual(make(beta), q, qd), residual(make(beta, False), q, qd)
    assert np.max(np.abs(new - old)) < 1e-4 * np.abs(old).max()


@pytest.mark.parametrize("kind", list(KINDS))
def test_jacobians_equal_the_complex_step_of_the_residual_at_a_large_rotation_state(kind: str) -> None:
    raw = KINDS[kind](1e-3)
    case = load_case_dict(raw)
    model, params = case.model, case.model.parameters(case.x0)
    q, qd = rigid_state(raw, theta=0.9, omega=1.5)
    rng = np.random.default_rng(11)
    names = model.dof_labels()
    size = np.array([0.3 if lab.split(".")[1].startswith("r") else 30.0 for lab in names])
    q, qd = q + size * rng.normal(size=len(q)), qd + size * rng.normal(size=len(q))   # deformed, straining
    qdd = rng.normal(size=len(q))
    lin = model.linearize(0.0, StepState(q, qd, qdd, EMPTY, EMPTY, EMPTY), params)
    cs_q, cs_qd, _ = complex_step_jacobians(model, 0.0, q, qd, qdd, params)
    for block, cs in ((lin.R_q, cs_q), (lin.R_qd, cs_qd)):
        np.testing.assert_allclose(as_dense(block), cs, rtol=1e-10, atol=1e-11 * np.abs(cs).max())


def _elastica_case(corotated: bool) -> tuple[dict, float]:
    """A 10-element cantilever under a suddenly applied tip load P = EI/L², damped by β only
    (ζ ≈ 0.2 in the first mode), run 0.25 s (about 14 first periods)."""
    A, inertia, _ = section_properties("tube", [TUBE["D"], TUBE["t"]])
    P = E * inertia / L ** 2
    omega_1 = 1.8751 ** 2 * np.sqrt(E * inertia / (RHO * A * L ** 4))
    raw = cantilever(10, loads=[{"node": "n10", "direction": "y", "value": P}])
    raw["model"]["damping"] = {"rayleigh": {"beta": 0.4 / omega_1, "corotated": corotated}}
    raw["integrator"] = {"dt": 1e-3, "t_end": 0.25}
    return raw, P


def test_a_large_deflection_cantilever_settles_on_its_static_elastica() -> None:
    raw, _ = _elastica_case(True)
    case = load_case_dict(raw)
    q_static = static_solution(case, load_steps=4)
    ux, uy, _ = tip(case, q_static, 10)
    # the model's static solution is the elastica (10 elements: within 0.3 %)
    assert uy / L == pytest.approx(0.30172, rel=3e-3) and -ux / L == pytest.approx(0.05643, rel=1e-2)
    res = dynsens.run_case(case, history=("q",))
    assert res.status == "completed"
    names = case.model.dof_labels()
    end = res.history["q"][-1]
    settled = np.array([end[names.index("n10.x")], end[names.index("n10.y")]])
    np.testing.assert_allclose(settled, [ux, uy], rtol=2e-3)
    # the former β K₀ on total rates resists the turning and is still far from it
    former_run = dynsens.run_case(load_case_dict(_elastica_case(False)[0]), history=("q",))
    former = former_run.history["q"][-1][names.index("n10.y")]
    assert abs(former - uy) > 0.05 * uy


def test_gradients_through_it_equal_the_complex_step_and_adjoint_equals_direct() -> None:
    raw, P = _elastica_case(True)
    raw["design"]["variables"] = [{"name": "D", "value": 60.0, "lower": 30.0, "upper": 100.0},
                                  {"name": "beta", "value": 1e-3, "lower": 1e-5, "upper": 1e-2}]
    for el in raw["model"]["elements"]:
        el["section"]["D"] = "D"
    raw["model"]["damping"]["rayleigh"]["beta"] = "beta"
    raw["model"]["loads"][0]["function"] = {"type": "ramp", "t0": 0.0, "t1": 0.01}
    raw["integrator"] = {"dt": 2e-3, "t_end": 0.04}
    raw["sensitivity"] = {"partials": "complex"}
    raw["responses"] = [{"name": "tip_y", "type": "value", "quantity": {"dof": "n10.y"}},
                        {"name": "tip_x_max", "type": "max", "quantity": {"dof": "n10.x"}, "absolute": True}]
    case = load_case_dict(raw)
    res = dynsens.run_case(case)
    assert res.status == "completed"
    assert float(np.real(res.responses["tip_y"].value)) > 0.1 * L      # a large rotation
    assert_gradients_match_complex_step_and_adjoint(case, res)


def test_a_corotated_flag_that_is_not_a_boolean_is_one_problem_at_its_key() -> None:
    raw = plane_beam(1e-3)
    raw["model"]["damping"]["rayleigh"]["corotated"] = "yes"
    with pytest.raises(dynsens.CaseError) as err:
        load_case_dict(raw)
    assert [p.path for p in err.value.problems] == ["model.damping.rayleigh.corotated"]
    assert "expected true or false, found 'yes'" in str(err.value)
