"""Plane co-rotational beams against closed forms, and their sensitivities.

Contract (issue 14): a cantilever's static tip deflection PL³/(3EI) and rotation PL²/(2EI);
its first natural frequencies (β_iL)²·sqrt(EI/(ρAL⁴)) with consistent and lumped mass; a
cantilever rolled up by an end moment M = πEI/L (half circle) and 2πEI/L (full circle); the
element tangent equals complex step of the internal force at a large-rotation state; extreme-
fibre stresses N/A ± Mc/I; section properties; sensitivities of a dynamic frame against complex
step of the whole run; bad beam entries reported with their path.
"""
from __future__ import annotations

import copy

import numpy as np
import pytest
import scipy.linalg as sla

import dynsens
from dynsens import CaseError
from dynsens.case.load import load_case_dict
from dynsens.models.base import StepState, as_dense
from dynsens.models.structural.beams import section_properties
from helpers import complex_step_gradients, complex_step_jacobians

E, RHO = 210000.0, 7.85e-9                 # MPa, t/mm³
L = 1000.0                                 # mm
TUBE = {"shape": "tube", "D": 60.0, "t": 4.0}
A_T, I_T, C_T = section_properties("tube", [60.0, 4.0])


def cantilever(n_el: int, *, mass: str = "lumped", loads: list | None = None, section: dict = TUBE,
               design: list | None = None, **extra) -> dict:
    """A cantilever along x from the clamped node n0 to the tip n{n_el} (mm, s, t, N, MPa)."""
    nodes = {f"n{i}": {"coords": [L * i / n_el, 0.0]} for i in range(n_el + 1)}
    nodes["n0"]["fixed"] = "all"
    elements = [{"type": "beam", "name": f"b{i}", "nodes": [f"n{i}", f"n{i + 1}"], "E": E, "density": RHO,
                 "section": dict(section), "mass": mass} for i in range(n_el)]
    raw = {"name": "cantilever", "design": {"variables": design or []},
           "model": {"type": "structural", "dim": 2, "nodes": nodes, "elements": elements, "loads": loads or []},
           "integrator": {"dt": 1e-3, "t_end": 1e-3}, "sensitivity": {"enabled": False}}
    raw.update(extra)
    return raw


def static_solution(case, load_steps: int = 1, tol: float = 1e-10) -> np.ndarray:
    """Static equilibrium f_int(q) = f_ext by Newton with load increments, from the model's own
    residual and tangent (q̇ = q̈ = 0; the loads are constant time functions)."""
    model = case.model
    params = model.parameters(case.x0)
    n = model.traits.n_q
    f_ext = model.external_force(0.0, params)
    q = np.zeros(n)
    empty = np.zeros(0)
    for k in range(1, load_steps + 1):
        target = f_ext * k / load_steps
        for _ in range(50):
            s = StepState(q, np.zeros(n), np.zeros(n), empty, empty, empty)
            R = model.residual(0.0, s, params) + f_ext - target
            if np.linalg.norm(R) <= tol * max(1.0, np.linalg.norm(target)):
                break
            q = q - np.linalg.solve(as_dense(model.linearize(0.0, s, params).R_q), R)
        else:
            raise AssertionError("static Newton did not converge")
    return q


def tip(case, q: np.ndarray, n_el: int) -> tuple[float, float, float]:
    names = case.model.dof_labels()
    return tuple(q[names.index(f"n{n_el}.{a}")] for a in ("x", "y", "rz"))


def test_cantilever_static_tip_deflection_and_rotation() -> None:
    P = 1.0                                                   # N: linear range (δ/L ≈ 1e-5)
    case = load_case_dict(cantilever(4, loads=[{"node": "n4", "direction": "y", "value": P}]))
    ux, uy, rz = tip(case, static_solution(case), 4)
    assert uy == pytest.approx(P * L ** 3 / (3 * E * I_T), rel=1e-8)
    assert rz == pytest.approx(P * L ** 2 / (2 * E * I_T), rel=1e-8)
    assert abs(ux) < 1e-5 * uy                                # second order: the arc shortening
    # an end moment: δ = ML²/(2EI), θ = ML/(EI); an axial force: u = PL/(EA)
    case = load_case_dict(cantilever(4, loads=[{"node": "n4", "direction": "rz", "value": 100.0}]))
    ux, uy, rz = tip(case, static_solution(case), 4)
    assert uy == pytest.approx(100.0 * L ** 2 / (2 * E * I_T), rel=1e-7)
    assert rz == pytest.approx(100.0 * L / (E * I_T), rel=1e-12)
    case = load_case_dict(cantilever(4, loads=[{"node": "n4", "direction": "x", "value": 10.0}]))
    ux, uy, rz = tip(case, static_solution(case), 4)
    assert ux == pytest.approx(10.0 * L / (E * A_T), rel=1e-7) and uy == 0.0 and rz == 0.0


@pytest.mark.parametrize("turns, n_el, tol", [(0.5, 20, 2e-3), (1.0, 40, 2e-3)])
def test_cantilever_rolled_up_by_an_end_moment(turns: float, n_el: int, tol: float) -> None:
    """M = 2π·turns·EI/L bends the beam into an arc of radius R = EI/M through the angle ML/EI:
    tip at (R sin θ, R(1 − cos θ)); a full circle brings the tip back to the root."""
    M = 2 * np.pi * turns * E * I_T / L
    case = load_case_dict(cantilever(n_el, loads=[{"node": f"n{n_el}", "direction": "rz", "value": M}]))
    ux, uy, rz = tip(case, static_solution(case, load_steps=8 * int(np.ceil(2 * turns)) * 2), n_el)
    theta = M * L / (E * I_T)
    R = E * I_T / M
    assert rz == pytest.approx(theta, rel=1e-9)               # uniform curvature: nodal rotations exact
    assert np.hypot(L + ux - R * np.sin(theta), uy - R * (1 - np.cos(theta))) < tol * L


@pytest.mark.parametrize("mass, n_el, tol", [("consistent", 20, 2e-5), ("lumped", 20, 1.2e-2), ("lumped", 40, 3e-3)])
def test_cantilever_natural_frequencies(mass: str, n_el: int, tol: float) -> None:
    """Consistent mass: 2e-5 with 20 elements; lumped (HRZ) converges as h²: 1.2e-2 → 3e-3."""
    case = load_case_dict(cantilever(n_el, mass=mass))
    model = case.model
    params = model.parameters(case.x0)
    n = model.traits.n_q
    s = StepState(np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(0), np.zeros(0), np.zeros(0))
    lin = model.linearize(0.0, s, params)
    omega = np.sqrt(sla.eigh(as_dense(lin.R_q), as_dense(lin.R_z), eigvals_only=True))
    bending = [(bl ** 2) * np.sqrt(E * I_T / (RHO * A_T * L ** 4)) for bl in (1.875104069, 4.694091133, 7.854757438)]
    axial = np.pi / 2 * np.sqrt(E / RHO) / L
    for w in bending:
        assert np.min(np.abs(omega / w - 1)) < tol, (w, omega[:6])
    assert np.min(np.abs(omega / axial - 1)) < max(tol, 1e-3)
    assert np.all(omega[:3] == pytest.approx(bending, rel=tol))   # the three lowest are bending modes


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_tangent_and_mass_equal_complex_step_at_a_large_rotation_state(mass: str) -> None:
    raw = cantilever(3, mass=mass)
    raw["model"]["damping"] = {"rayleigh": {"alpha": 3.0, "beta": 1e-4}}
    case = load_case_dict(raw)
    model = case.model
    params = model.parameters(case.x0)
    n = model.traits.n_q
    rng = np.random.default_rng(3)
    q = rng.normal(scale=[80.0, 80.0, 1.5] * 3)               # rotations of ~1.5 rad: far from linear
    qd, qdd = rng.normal(size=n), rng.normal(size=n)
    empty = np.zeros(0)
    lin = model.linearize(0.0, StepState(q, qd, qdd, empty, empty, empty), params)
    # (a consistent mass turns with the element: M(q), and velocity terms in ∂F_R/∂q̇ and ∂F_R/∂q)
    for block, cs in zip((lin.R_q, lin.R_qd, lin.R_z), complex_step_jacobians(model, 0.0, q, qd, qdd, params)):
        np.testing.assert_allclose(as_dense(block), cs, rtol=1e-12, atol=1e-12 * np.abs(cs).max())


def test_extreme_fibre_stresses_and_end_forces() -> None:
    P, N = 50.0, 2000.0
    case = load_case_dict(cantilever(2, loads=[{"node": "n2", "direction": "y", "value": P},
                                               {"node": "n2", "direction": "x", "value": N}]))
    q = static_solution(case)
    params = case.model.parameters(case.x0)
    from dynsens.errors import ProblemCollector
    pc = ProblemCollector("test")
    stress = case.model.output({"element": "all", "kind": "stress"}, "q", pc)
    forces = case.model.output({"element": ["b0"], "kind": "force"}, "q", pc)
    assert not pc.problems and stress.labels[:4] == ("b0.stress.1+", "b0.stress.1-", "b0.stress.2+", "b0.stress.2-")
    s = StepState(q, 0 * q, 0 * q, np.zeros(0), np.zeros(0), np.zeros(0))
    sig = stress.fn(0.0, s, params)
    ux, uy, _ = tip(case, q, 2)
    names = case.model.dof_labels()
    ux_m, uy_m = (q[names.index(f"n1.{a}")] for a in ("x", "y"))
    # moments about the root and the mid node in the deformed state (the tension straightens
    # the beam: the root moment is P(L + u_x) − N u_y, about 1 % below PL)
    m_root = P * (L + ux) - N * uy
    m_mid = P * (L / 2 + ux - ux_m) - N * (uy - uy_m)
    assert m_root < 0.995 * P * L
    W = I_T / C_T
    assert sorted(np.abs(sig[:2] - sig[:2].mean())) == pytest.approx([m_root / W] * 2, rel=1e-6)
    # the axial force of the first element: the tip load along its chord
    chord = np.array([L / 2 + ux_m, uy_m])
    n_b0 = np.dot([N, P], chord) / np.linalg.norm(chord)
    assert sig[:2].mean() == pytest.approx(n_b0 / A_T, rel=1e-9)
    n_, m1, m2 = forces.fn(0.0, s, params)
    assert n_ == pytest.approx(n_b0, rel=1e-9) and abs(m1) == pytest.approx(m_root, rel=1e-6)
    assert abs(m2) == pytest.approx(m_mid, rel=1e-6)


def test_section_properties() -> None:
    A, I, c = section_properties("tube", [60.0, 4.0])
    assert A == pytest.approx(np.pi * (60 ** 2 - 52 ** 2) / 4) and I == pytest.approx(np.pi * (60 ** 4 - 52 ** 4) / 64)
    assert c == 30.0
    assert section_properties("rectangle", [20.0, 50.0]) == pytest.approx((1000.0, 20 * 50 ** 3 / 12, 25.0))
    # a box whose walls fill it is the rectangle; a thin box has I ≈ t h²(h/6 + b/2)
    assert section_properties("box", [20.0, 50.0, 10.0]) == pytest.approx(section_properties("rectangle", [20.0, 50.0]))
    A, I, _ = section_properties("box", [100.0, 200.0, 0.1])
    assert I == pytest.approx(0.1 * 200 ** 2 * (200 / 6 + 100 / 2), rel=2e-3)


def portal_frame() -> dict:
    """Two tube columns and a box girder, pinned and clamped feet, a horizontal impact at the
    top: geometric nonlinearity, design in section dimensions, a coordinate and E."""
    return {
        "name": "portal",
        "design": {"variables": [
            {"name": "D", "value": 80.0, "lower": 30.0, "upper": 200.0},
            {"name": "t", "value": 5.0, "lower": 1.0, "upper": 20.0},
            {"name": "h", "value": 120.0, "lower": 50.0, "upper": 300.0},
            {"name": "H", "value": 2000.0, "lower": 1000.0, "upper": 3000.0},
            {"name": "E_col", "value": 210000.0, "lower": 1e5, "upper": 3e5},
        ]},
        "model": {
            "type": "structural", "dim": 2,
            "nodes": {"a": {"coords": [0.0, 0.0], "fixed": "all"}, "b": {"coords": [3000.0, 0.0], "fixed": ["x", "y"]},
                      "c": {"coords": [0.0, "H"]}, "m": {"coords": [1500.0, "H"]}, "d": {"coords": [3000.0, "H"]}},
            "elements": [
                {"type": "beam", "name": "col_a", "nodes": ["a", "c"], "E": "E_col", "density": RHO,
                 "section": {"shape": "tube", "D": "D", "t": "t"}},
                {"type": "beam", "name": "col_b", "nodes": ["b", "d"], "E": "E_col", "density": RHO,
                 "section": {"shape": "tube", "D": "D", "t": "t"}, "mass": "consistent"},
                {"type": "beam", "name": "girder_1", "nodes": ["c", "m"], "E": E, "density": RHO,
                 "section": {"shape": "box", "b": 80.0, "h": "h", "t": 6.0}, "mass": "consistent"},
                {"type": "beam", "name": "girder_2", "nodes": ["m", "d"], "E": E, "density": RHO,
                 "section": {"shape": "rectangle", "b": 30.0, "h": "h"}},
                {"type": "bar", "name": "brace", "nodes": ["a", "m"], "area": 100.0, "E": E, "density": RHO},
                {"type": "mass", "name": "load_mass", "node": "m", "mass": 0.2},
            ],
            "damping": {"rayleigh": {"alpha": 2.0, "beta": 1e-4}},
            "loads": [{"node": "c", "direction": "x", "value": 4.0e4,
                       "function": {"type": "pulse", "t0": 0.0, "duration": 0.02}},
                      {"node": "d", "direction": "rz", "value": 2.0e6,
                       "function": {"type": "ramp", "t0": 0.0, "t1": 0.03}}],
        },
        "integrator": {"dt": 2e-3, "t_end": 0.05},
        "sensitivity": {"partials": "complex"},
        "responses": [
            {"name": "mass", "type": "mass"},
            {"name": "stress_ks", "type": "stress_ratio", "elements": ["col_a", "col_b", "girder_1", "girder_2"],
             "limit": 235.0, "rho": 50.0},
            {"name": "stress_max", "type": "stress_ratio", "limit": 235.0, "aggregate": "max"},
            {"name": "drift_max", "type": "max", "quantity": {"dof": "c.x"}, "absolute": True},
            {"name": "rot_end", "type": "value", "quantity": {"dof": "d.rz"}},
            {"name": "moment_ks", "type": "ks", "quantity": {"element": "col_a", "kind": "force"},
             "components": ["col_a.M1"], "absolute": True, "rho": 1e-5},
        ],
    }


def test_frame_sensitivities_equal_complex_step_of_the_whole_run() -> None:
    case = load_case_dict(portal_frame())
    res = dynsens.run_case(case)
    assert res.status == "completed"
    drift = float(np.real(res.responses["drift_max"].value))
    assert 1.0 < drift < 200.0                                # a real, but not destructive, sway
    cs = complex_step_gradients(case)
    for name, rv in res.responses.items():
        np.testing.assert_allclose(np.real(rv.gradient), cs[name], rtol=1e-8,
                                   atol=1e-10 * np.abs(cs[name]).max(), err_msg=name)


def test_frame_mass_is_the_sum_of_rho_A_L() -> None:
    case = load_case_dict(portal_frame())
    params = case.model.parameters(case.x0)
    A_col, _, _ = section_properties("tube", [80.0, 5.0])
    A_g1, _, _ = section_properties("box", [80.0, 120.0, 6.0])
    expected = RHO * (2 * A_col * 2000.0 + (A_g1 + 30.0 * 120.0) * 1500.0 + 100.0 * np.hypot(1500.0, 2000.0)) + 0.2
    assert float(case.model.structural_mass(params)) == pytest.approx(expected, rel=1e-12)
    # a consistent element moved rigidly in x or in y has the kinetic energy of its mass ρAL,
    # in its initial position and turned by a large rotation
    m_el = RHO * np.array([A_col * 2000.0, A_g1 * 1500.0])
    n = case.model.traits.n_q
    for q in (np.zeros(n), np.random.default_rng(2).normal(size=n) * 300.0):
        Me = case.model.beams.turning_mass(case.model._ext(q), params)["M"]
        for axis in (0, 1):
            e = np.zeros(6)
            e[[axis, axis + 3]] = 1
            np.testing.assert_allclose(np.einsum("i,eij,j->e", e, Me, e), m_el, rtol=1e-12)


@pytest.mark.parametrize("change, path, needle", [
    (lambda r: r["model"]["elements"][0]["section"].update(shape="pipe"), "model.elements[0].section.shape", "tube"),
    (lambda r: r["model"]["elements"][0]["section"].pop("t"), "model.elements[0].section", "needs t"),
    (lambda r: r["model"]["elements"][0]["section"].update(h=3.0), "model.elements[0].section", "not h"),
    (lambda r: r["model"]["elements"][0].update(mass="diagonal"), "model.elements[0].mass", "consistent"),
    # a 3D model reads its beams as space-frame beams (tests/test_beams3d.py): they need G
    (lambda r: r["model"].update(dim=3), "model.elements[0].G", "missing"),
    (lambda r: r["model"]["loads"].append({"node": "n1", "direction": "rx", "value": 1.0}),
     "model.loads[0].direction", "'rz'"),
    (lambda r: r["model"]["nodes"]["n1"].update(fixed=["rx"]), "model.nodes.n1.fixed", "'rz'"),
])
def test_bad_beam_entries_are_reported_with_their_path(change, path, needle) -> None:
    raw = cantilever(2)
    change(raw)
    with pytest.raises(CaseError) as err:
        load_case_dict(copy.deepcopy(raw))
    msgs = [p.message for p in err.value.problems if p.path == path]
    assert any(needle in m for m in msgs), [str(p) for p in err.value.problems]
