"""Space-frame (3D) beams against closed forms, and their sensitivities.

Contract (issue 14, small rotations): a cantilever's static tip deflection PL³/(3EI) and rotation
PL²/(2EI) in both bending planes, twist TL/(GJ), stretch PL/(EA), also for a cantilever along a
skew axis; a simply supported beam (rotations free at the supports) PL³/(48EI); the first
bending frequencies in both planes (β₁L)²·sqrt(EI/(ρAL⁴)) and the first torsional frequency
(π/2L)·sqrt(GJ/(ρI_p)) with consistent and lumped mass; section constants (Timoshenko's torsion
table, Bredt); extreme-fibre stresses N/A ± M_y/W_y ± M_z/W_z; sensitivities of a dynamic 3D
frame against complex step of the whole run and adjoint against direct; bad entries reported.
"""
from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import pytest
import scipy.linalg as sla

import dynsens
from dynsens import CaseError
from dynsens.case.load import load_case_dict
from dynsens.errors import ProblemCollector
from dynsens.models.base import StepState, as_dense
from dynsens.models.structural.beams3d import section_properties_3d
from helpers import assert_gradients_match_complex_step_and_adjoint, complex_step_gradients

E, G, RHO = 210000.0, 81000.0, 7.85e-9       # MPa, MPa, t/mm³
L = 1000.0                                    # mm
RECT = {"shape": "rectangle", "b": 20.0, "h": 50.0}     # h along local y (= global z here), b along local z
A_R, IY_R, IZ_R, J_R, CY_R, CZ_R = section_properties_3d("rectangle", [20.0, 50.0])


def cantilever(n_el: int, *, axis=(1.0, 0.0, 0.0), mass: str = "lumped", loads: list | None = None,
               section: dict = RECT, orientation: list | None = None, **extra) -> dict:
    """A cantilever from the clamped node n0 along ``axis`` to the tip n{n_el} (mm, s, t, N, MPa)."""
    ax = np.asarray(axis) / np.linalg.norm(axis)
    nodes = {f"n{i}": {"coords": list(L * i / n_el * ax)} for i in range(n_el + 1)}
    nodes["n0"]["fixed"] = "all"
    elements = [{"type": "beam", "name": f"b{i}", "nodes": [f"n{i}", f"n{i + 1}"], "E": E, "G": G, "density": RHO,
                 "section": dict(section), "mass": mass} for i in range(n_el)]
    if orientation is not None:
        for el in elements:
            el["orientation"] = orientation
    raw = {"name": "cantilever3d", "design": {"variables": []},
           "model": {"type": "structural", "dim": 3, "nodes": nodes, "elements": elements, "loads": loads or []},
           "integrator": {"dt": 1e-3, "t_end": 1e-3}, "sensitivity": {"enabled": False}}
    raw.update(extra)
    return raw


def static(case) -> dict[str, float]:
    """Static displacements K⁻¹ f_ext (the element is linear), by DOF name."""
    model = case.model
    params = model.parameters(case.x0)
    n = model.traits.n_q
    z = np.zeros(n)
    K = as_dense(model.linearize(0.0, StepState(z, z, z, np.zeros(0), np.zeros(0), np.zeros(0)), params).R_q)
    q = np.linalg.solve(K, model.external_force(0.0, params))
    s = StepState(q, z, z, np.zeros(0), np.zeros(0), np.zeros(0))
    # the residual f_int(q) − f_ext vanishes: the tangent is the internal force's own
    assert np.linalg.norm(model.residual(0.0, s, params)) <= 1e-9 * np.abs(model.external_force(0.0, params)).max()
    return dict(zip(model.dof_labels(), q))


def test_cantilever_static_tip_deflection_rotation_and_twist() -> None:
    P, T = 10.0, 5000.0
    tip = "n4"
    # load along global z = local y: bending about local z (I_z); the tip turns about −y
    u = static(load_case_dict(cantilever(4, loads=[{"node": tip, "direction": "z", "value": P}])))
    assert u[f"{tip}.z"] == pytest.approx(P * L ** 3 / (3 * E * IZ_R), rel=1e-10)
    assert u[f"{tip}.ry"] == pytest.approx(-P * L ** 2 / (2 * E * IZ_R), rel=1e-10)
    assert abs(u[f"{tip}.y"]) + abs(u[f"{tip}.rx"]) < 1e-12
    # along global y (= −local z): bending about local y (I_y); the tip turns about +z
    u = static(load_case_dict(cantilever(4, loads=[{"node": tip, "direction": "y", "value": P}])))
    assert u[f"{tip}.y"] == pytest.approx(P * L ** 3 / (3 * E * IY_R), rel=1e-10)
    assert u[f"{tip}.rz"] == pytest.approx(P * L ** 2 / (2 * E * IY_R), rel=1e-10)
    # a torque and an axial force
    u = static(load_case_dict(cantilever(4, loads=[{"node": tip, "direction": "rx", "value": T},
                                                   {"node": tip, "direction": "x", "value": P}])))
    assert u[f"{tip}.rx"] == pytest.approx(T * L / (G * J_R), rel=1e-12)
    assert u[f"{tip}.x"] == pytest.approx(P * L / (E * A_R), rel=1e-12)
    # an end moment about y: δ_z = −ML²/(2EI_z)... (moment about global y turns the tip about y)
    u = static(load_case_dict(cantilever(4, loads=[{"node": tip, "direction": "ry", "value": T}])))
    assert u[f"{tip}.ry"] == pytest.approx(T * L / (E * IZ_R), rel=1e-12)
    assert u[f"{tip}.z"] == pytest.approx(-T * L ** 2 / (2 * E * IZ_R), rel=1e-10)


def test_skew_cantilever_matches_the_closed_forms_in_its_own_frame() -> None:
    """Along (1, 2, 2)/3 with local y set by ``orientation``: a load along local y deflects the
    tip by PL³/(3EI_z) along local y; one along local z by PL³/(3EI_y); a torque twists it by TL/GJ."""
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    ey = np.array([2.0, -2.0, 1.0]) / 3.0                   # ⟂ axis
    ez = np.cross(axis, ey)
    P, T = 10.0, 5000.0
    for direction, I_b in ((ey, IZ_R), (ez, IY_R)):
        loads = [{"node": "n5", "direction": a, "value": float(P * c)} for a, c in zip("xyz", direction)]
        u = static(load_case_dict(cantilever(5, axis=axis, loads=loads, orientation=list(ey + 0.3 * axis))))
        d = np.array([u[f"n5.{a}"] for a in "xyz"])
        np.testing.assert_allclose(d, P * L ** 3 / (3 * E * I_b) * direction, rtol=1e-9, atol=1e-12)
    loads = [{"node": "n5", "direction": a, "value": float(T * c)} for a, c in zip(("rx", "ry", "rz"), axis)]
    u = static(load_case_dict(cantilever(5, axis=axis, loads=loads, orientation=list(ey))))
    np.testing.assert_allclose([u[f"n5.{a}"] for a in ("rx", "ry", "rz")], T * L / (G * J_R) * axis, rtol=1e-10)


def test_simply_supported_beam_with_free_rotations_at_the_supports() -> None:
    raw = cantilever(4, loads=[{"node": "n2", "direction": "z", "value": 100.0}])
    raw["model"]["nodes"]["n0"]["fixed"] = ["x", "y", "z", "rx"]      # a pin that also stops the twist
    raw["model"]["nodes"]["n4"]["fixed"] = ["y", "z"]                 # a roller
    u = static(load_case_dict(raw))
    assert u["n2.z"] == pytest.approx(100.0 * L ** 3 / (48 * E * IZ_R), rel=1e-10)
    assert u["n0.ry"] == pytest.approx(-100.0 * L ** 2 / (16 * E * IZ_R), rel=1e-10)
    assert u["n4.ry"] == pytest.approx(100.0 * L ** 2 / (16 * E * IZ_R), rel=1e-10)


def frequencies(case) -> np.ndarray:
    model = case.model
    params = model.parameters(case.x0)
    z = np.zeros(model.traits.n_q)
    lin = model.linearize(0.0, StepState(z, z, z, np.zeros(0), np.zeros(0), np.zeros(0)), params)
    return np.sqrt(sla.eigh(as_dense(lin.R_q), as_dense(lin.R_z), eigvals_only=True))


@pytest.mark.parametrize("mass, n_el, tol", [("consistent", 20, 2e-5), ("lumped", 20, 1.2e-2), ("lumped", 40, 3e-3)])
def test_cantilever_frequencies_in_both_planes_and_in_torsion(mass: str, n_el: int, tol: float) -> None:
    omega = frequencies(load_case_dict(cantilever(n_el, mass=mass)))
    b1 = 1.875104069 ** 2
    weak = b1 * np.sqrt(E * IY_R / (RHO * A_R * L ** 4))      # bending along global y (b = 20 mm)
    strong = b1 * np.sqrt(E * IZ_R / (RHO * A_R * L ** 4))    # along global z (h = 50 mm)
    torsion = np.pi / (2 * L) * np.sqrt(G * J_R / (RHO * (IY_R + IZ_R)))
    assert omega[0] == pytest.approx(weak, rel=tol) and omega[1] == pytest.approx(strong, rel=tol)
    # linear twist interpolation: the rod's discretization error (βh)²/24, βh = π/(2n) (2.6e-4 for n = 20)
    rod = (np.pi / (2 * n_el)) ** 2 / 24
    assert np.min(np.abs(omega / torsion - 1)) < max(tol, 1.05 * rod), (torsion, omega[:8])


def test_tube_cantilever_torsion_frequency_and_section_constants() -> None:
    omega = frequencies(load_case_dict(cantilever(20, mass="consistent", section={"shape": "tube", "D": 60.0,
                                                                                  "t": 4.0})))
    # J = I_p for a tube; consistent linear twist: ω_h/ω − 1 = (π/40)²/24 to leading order
    assert np.min(np.abs(omega / (np.pi / (2 * L) * np.sqrt(G / RHO)) - 1 - (np.pi / 40) ** 2 / 24)) < 1e-6
    A, Iy, Iz, J, cy, cz = section_properties_3d("tube", [60.0, 4.0])
    assert Iy == Iz == pytest.approx(np.pi * (60 ** 4 - 52 ** 4) / 64) and J == pytest.approx(2 * Iy)
    # rectangle h/b = 2.5: Timoshenko's table J = 0.249 h b³
    assert J_R == pytest.approx(0.249 * 50 * 20 ** 3, rel=3e-3) and (CY_R, CZ_R) == (25.0, 10.0)
    assert section_properties_3d("rectangle", [50.0, 20.0])[3] == pytest.approx(J_R)
    # a thin box: Bredt 4A_m²t/perimeter, and its walls' second moments t h_m²(h_m/6 + b_m/2)
    A, Iy, Iz, J, _, _ = section_properties_3d("box", [100.0, 200.0, 0.5])
    assert J == pytest.approx(4 * (99.5 * 199.5) ** 2 * 0.5 / (2 * (99.5 + 199.5)), rel=1e-12)
    assert Iz == pytest.approx(0.5 * 199.5 ** 2 * (199.5 / 6 + 99.5 / 2), rel=1e-4)     # mid-wall thin-wall formula
    assert Iy == pytest.approx(0.5 * 99.5 ** 2 * (99.5 / 6 + 199.5 / 2), rel=1e-4)


def test_extreme_fibre_stresses_under_biaxial_bending_and_tension() -> None:
    Pz, Py, N = 20.0, 5.0, 3000.0
    case = load_case_dict(cantilever(2, loads=[{"node": "n2", "direction": "z", "value": Pz},
                                               {"node": "n2", "direction": "y", "value": Py},
                                               {"node": "n2", "direction": "x", "value": N}]))
    u = static(case)
    q = np.array([u[d] for d in case.model.dof_labels()])
    pc = ProblemCollector("test")
    stress = case.model.output({"element": "all", "kind": "stress"}, "q", pc)
    forces = case.model.output({"element": "b0", "kind": "force"}, "q", pc)
    assert not pc.problems and stress.labels[:4] == ("b0.stress.1+", "b0.stress.1-", "b0.stress.2+", "b0.stress.2-")
    s = StepState(q, 0 * q, 0 * q, np.zeros(0), np.zeros(0), np.zeros(0))
    params = case.model.parameters(case.x0)
    sig = stress.fn(0.0, s, params)
    Wz, Wy = IZ_R / CY_R, IY_R / CZ_R
    root = N / A_R + Pz * L / Wz + Py * L / Wy
    mid = N / A_R + Pz * L / 2 / Wz + Py * L / 2 / Wy
    np.testing.assert_allclose(sig[:4], [root, 2 * N / A_R - root, mid, 2 * N / A_R - mid], rtol=1e-9)
    n_, t_, my1, mz1, my2, mz2 = forces.fn(0.0, s, params)
    assert n_ == pytest.approx(N) and abs(t_) < 1e-9
    assert (abs(mz1), abs(my1), abs(mz2), abs(my2)) == pytest.approx((Pz * L, Py * L, Pz * L / 2, Py * L / 2))


def space_frame() -> dict:
    """A 3D L-frame: a tube column and a box arm (clamped foot, arm out along y), a tip mass,
    a sideways impact and a torque at the tip; design in section dimensions, a coordinate, G."""
    return {
        "name": "space_frame",
        "design": {"variables": [
            {"name": "D", "value": 80.0, "lower": 30.0, "upper": 200.0},
            {"name": "t", "value": 5.0, "lower": 1.0, "upper": 20.0},
            {"name": "h", "value": 100.0, "lower": 50.0, "upper": 300.0},
            {"name": "H", "value": 1500.0, "lower": 1000.0, "upper": 3000.0},
            {"name": "G_arm", "value": 81000.0, "lower": 5e4, "upper": 1e5},
        ]},
        "model": {
            "type": "structural", "dim": 3,
            "nodes": {"a": {"coords": [0.0, 0.0, 0.0], "fixed": "all"}, "c": {"coords": [0.0, 0.0, "H"]},
                      "m": {"coords": [0.0, 600.0, "H"]}, "d": {"coords": [0.0, 1200.0, "H"]}},
            "elements": [
                {"type": "beam", "name": "col", "nodes": ["a", "c"], "E": E, "G": G, "density": RHO,
                 "section": {"shape": "tube", "D": "D", "t": "t"}, "mass": "consistent"},
                {"type": "beam", "name": "arm_1", "nodes": ["c", "m"], "E": E, "G": "G_arm", "density": RHO,
                 "section": {"shape": "box", "b": 60.0, "h": "h", "t": 4.0}, "orientation": [0, 0, 1]},
                {"type": "beam", "name": "arm_2", "nodes": ["m", "d"], "E": E, "G": "G_arm", "density": RHO,
                 "section": {"shape": "rectangle", "b": 30.0, "h": "h"}, "mass": "consistent"},
                {"type": "mass", "name": "tip_mass", "node": "d", "mass": 0.05},
            ],
            "damping": {"rayleigh": {"alpha": 2.0, "beta": 1e-4}},
            "loads": [{"node": "d", "direction": "x", "value": 3.0e3,
                       "function": {"type": "pulse", "t0": 0.0, "duration": 0.02}},
                      {"node": "d", "direction": "ry", "value": 1.0e6,
                       "function": {"type": "ramp", "t0": 0.0, "t1": 0.03}}],
        },
        "integrator": {"dt": 2e-3, "t_end": 0.05},
        "sensitivity": {"partials": "complex"},
        "responses": [
            {"name": "mass", "type": "mass"},
            {"name": "stress_ks", "type": "stress_ratio", "limit": 235.0, "rho": 50.0},
            {"name": "stress_max", "type": "stress_ratio", "limit": 235.0, "aggregate": "max"},
            {"name": "tip_drift", "type": "displacement_limit", "nodes": ["d", "m"], "limit": 10.0, "rho": 20.0},
            {"name": "twist_end", "type": "value", "quantity": {"dof": "d.ry"}},
            {"name": "torque_ks", "type": "ks", "quantity": {"element": "arm_1", "kind": "force"},
             "components": ["arm_1.T"], "absolute": True, "rho": 1e-5},
        ],
    }


@pytest.fixture(scope="module")
def frame_run():
    case = load_case_dict(space_frame())
    return case, dynsens.run_case(case)


def test_space_frame_sensitivities_equal_complex_step_of_the_whole_run(frame_run) -> None:
    case, res = frame_run
    assert res.status == "completed"
    drift = float(np.real(res.responses["tip_drift"].value))
    assert 0.05 < drift < 20.0                                   # a real, not destructive, motion
    assert abs(float(np.real(res.responses["twist_end"].value))) > 1e-4
    cs = complex_step_gradients(case)
    for name, rv in res.responses.items():
        np.testing.assert_allclose(np.real(rv.gradient), cs[name], rtol=1e-8,
                                   atol=1e-10 * np.abs(cs[name]).max(), err_msg=name)


def test_space_frame_adjoint_equals_direct(frame_run) -> None:
    case, direct = frame_run
    c = copy.copy(case)
    c.plan = replace(case.plan, method="adjoint")
    adjoint = dynsens.run_case(c)
    assert adjoint.method == "adjoint"
    for name, rv in direct.responses.items():
        np.testing.assert_allclose(adjoint.responses[name].gradient, rv.gradient, rtol=1e-10,
                                   atol=1e-12 * np.abs(rv.gradient).max(), err_msg=name)


def test_space_frame_mass_is_the_sum_of_rho_A_L(frame_run) -> None:
    case, _ = frame_run
    params = case.model.parameters(case.x0)
    A_col = section_properties_3d("tube", [80.0, 5.0])[0]
    A_1 = section_properties_3d("box", [60.0, 100.0, 4.0])[0]
    expected = RHO * (A_col * 1500.0 + (A_1 + 30.0 * 100.0) * 600.0) + 0.05
    assert float(case.model.structural_mass(params)) == pytest.approx(expected, rel=1e-12)
    # the consistent and lumped element masses of the free frame moved rigidly: the whole mass
    raw = space_frame()
    raw["model"]["nodes"]["a"]["fixed"] = []
    free = load_case_dict(raw).model
    z = np.zeros(free.traits.n_q)
    M = as_dense(free.linearize(0.0, StepState(z, z, z, np.zeros(0), np.zeros(0), np.zeros(0)),
                                free.parameters(case.x0)).R_z)
    for a in "xyz":
        rigid = np.array([1.0 if d.endswith(f".{a}") else 0.0 for d in free.dof_labels()])
        assert rigid @ M @ rigid == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("change, path, needle", [
    (lambda el: el.pop("G"), "model.elements[0].G", "missing"),
    (lambda el: el.update(section={"shape": "properties", "A": 1.0, "I": 2.0, "c": 1.0}), "model.elements[0].section",
     "Iy"),
    (lambda el: el.update(orientation=[0, 0]), "model.elements[0].orientation", "non-zero vector"),
    (lambda el: el.update(mass="diagonal"), "model.elements[0].mass", "lumped or consistent"),
    (lambda el: el.update(orientation=[-2.0, 0.0, 0.0]), "model.elements[0].orientation", "parallel"),
])
def test_bad_3d_beam_entries_are_reported_with_their_path(change, path, needle) -> None:
    raw = cantilever(2)
    change(raw["model"]["elements"][0])
    with pytest.raises(CaseError) as err:
        load_case_dict(raw)
    assert any(p.path == path and needle in p.message for p in err.value.problems), \
        [str(p) for p in err.value.problems]


def test_plane_beams_refuse_3d_keys() -> None:
    raw = cantilever(2)
    raw["model"]["dim"] = 2
    for nd in raw["model"]["nodes"].values():
        nd["coords"] = nd["coords"][:2]
    with pytest.raises(CaseError) as err:
        load_case_dict(raw)
    assert any(p.path == "model.elements[0].G" for p in err.value.problems)


# ---------------------------------------------------------------------- co-rotational (large rotations)
def corot(n_el: int, **kw) -> dict:
    raw = cantilever(n_el, **kw)
    for el in raw["model"]["elements"]:
        el["kinematics"] = "corotational"
    return raw


def _tangent_at(case, q):
    model = case.model
    params = model.parameters(case.x0)
    z = np.zeros_like(q)
    return as_dense(model.linearize(0.0, StepState(q, z, z, np.zeros(0), np.zeros(0), np.zeros(0)), params).R_q)


def test_corotational_beam_at_rest_is_the_small_rotation_beam() -> None:
    for axis in ((1.0, 0.0, 0.0), (1.0, 2.0, 2.0)):
        small, large = (load_case_dict(f(4, axis=axis)) for f in (cantilever, corot))
        K_small = _tangent_at(small, np.zeros(small.model.traits.n_q))
        np.testing.assert_allclose(_tangent_at(large, np.zeros(large.model.traits.n_q)), K_small,
                                   rtol=1e-12, atol=1e-12 * np.abs(K_small).max())


def test_corotational_tangent_equals_complex_step_of_the_residual_at_a_large_rotation_state() -> None:
    case = load_case_dict(corot(3, axis=(1.0, 2.0, 2.0)))
    model = case.model
    params = model.parameters(case.x0)
    n = model.traits.n_q
    q = np.random.default_rng(4).normal(scale=[60.0, 60.0, 60.0, 1.0, 1.0, 1.0] * 3)   # rotations ~1 rad
    K = _tangent_at(case, q)
    h, e = 1e-30, np.zeros(0)
    cs = np.zeros((n, n))
    for j in range(n):
        qc = q.astype(complex)
        qc[j] += 1j * h
        zc = np.zeros(n, complex)
        cs[:, j] = np.imag(model.residual(0.0, StepState(qc, zc, zc, e, e, e), params)) / h
    np.testing.assert_allclose(K, cs, rtol=1e-11, atol=1e-11 * np.abs(cs).max())
    np.testing.assert_allclose(K, K.T, rtol=1e-10, atol=1e-10 * np.abs(K).max())     # a potential's Hessian


@pytest.mark.parametrize("direction, inertia, turns, n_el", [("ry", IZ_R, 0.5, 16), ("rz", IY_R, 0.75, 24)])
def test_corotational_cantilever_rolled_up_by_an_end_moment(direction, inertia, turns, n_el) -> None:
    """M = 2π·turns·EI/L bends the cantilever into an arc of radius R = EI/M through θ = ML/EI."""
    from test_beams import static_solution
    M = 2 * np.pi * turns * E * inertia / L
    case = load_case_dict(corot(n_el, loads=[{"node": f"n{n_el}", "direction": direction, "value": M}]))
    q = static_solution(case, load_steps=int(16 * turns))
    u = dict(zip(case.model.dof_labels(), q))
    theta, R = M * L / (E * inertia), E * inertia / M
    tip = f"n{n_el}"
    assert u[f"{tip}.{direction}"] == pytest.approx(theta, rel=1e-9)       # uniform curvature: exact rotations
    bend = "z" if direction == "ry" else "y"                                 # moment about y bends x into −z
    sign = -1.0 if direction == "ry" else 1.0
    err = np.hypot(L + u[f"{tip}.x"] - R * np.sin(theta), u[f"{tip}.{bend}"] - sign * R * (1 - np.cos(theta)))
    assert err < 2e-3 * L, err
    other = "y" if bend == "z" else "z"
    assert abs(u[f"{tip}.{other}"]) < 1e-9 * L


def test_corotational_frame_sensitivities_equal_complex_step_and_adjoint_equals_direct() -> None:
    raw = space_frame()
    for el in raw["model"]["elements"][:3]:
        el["kinematics"] = "corotational"
        el["mass"] = "lumped"
    # a large sway and twist: rotations up to ~1 rad (the co-rotated damping lets the frame
    # turn further than β K₀ did: 0.8 of the former loads keep it within the element's range)
    raw["model"]["loads"][0]["value"] = 2.4e5
    raw["model"]["loads"][1]["value"] = 1.6e7
    raw["responses"].append({"name": "roll", "type": "max", "quantity": {"dof": "d.rz"}, "absolute": True})
    case = load_case_dict(raw)
    res = dynsens.run_case(case)
    assert res.status == "completed"
    assert float(np.real(res.responses["roll"].value)) > 0.4
    assert_gradients_match_complex_step_and_adjoint(case, res)


def test_corotational_45_degree_bend_of_bathe_and_bolourchi() -> None:
    """A 45° arc of radius 100 in the x–y plane, clamped at the origin, 600 out of plane at the
    tip (E = 1e7, G = 5e6, A = 1, I = 1/12, J = 1/6; 8 elements, 10 load steps).  Bathe &
    Bolourchi (1979) report the tip displacement (−23.5, −13.4, 53.4) (tangent, in-plane
    normal, out of plane); agreement within 0.3 (0.5 % of |u|: their 8-element result, given
    to three figures, from a different formulation)."""
    from test_beams import static_solution
    R, n_el = 100.0, 8
    phi = np.linspace(0.0, np.pi / 4, n_el + 1)
    nodes = {f"n{i}": {"coords": [float(R * np.sin(p)), float(R * (1 - np.cos(p))), 0.0]} for i, p in enumerate(phi)}
    nodes["n0"]["fixed"] = "all"
    section = {"A": 1.0, "Iy": 1 / 12, "Iz": 1 / 12, "J": 1 / 6, "cy": 0.5, "cz": 0.5}
    elements = [{"type": "beam", "name": f"b{i}", "nodes": [f"n{i}", f"n{i + 1}"], "E": 1e7, "G": 5e6,
                 "density": 1e-3, "section": section, "kinematics": "corotational"} for i in range(n_el)]
    raw = {"name": "bend45", "model": {"type": "structural", "dim": 3, "nodes": nodes, "elements": elements,
                                       "loads": [{"node": f"n{n_el}", "direction": "z", "value": 600.0}]},
           "integrator": {"dt": 1e-3, "t_end": 1e-3}, "sensitivity": {"enabled": False}}
    case = load_case_dict(raw)
    u = dict(zip(case.model.dof_labels(), static_solution(case, load_steps=10)))
    np.testing.assert_allclose([u[f"n{n_el}.{a}"] for a in "xyz"], [-23.5, -13.4, 53.4], atol=0.3)


def test_corotational_range_is_checked_after_each_step() -> None:
    """A node turned by nearly a full turn, or an element bent by more than 0.5 rad: ModelError."""
    from dynsens.errors import ModelError
    case = load_case_dict(corot(2))
    model = case.model
    params = model.parameters(case.x0)
    names = model.dof_labels()
    e = np.zeros(0)

    def state(**values):
        q = np.zeros(len(names))
        for k, v in values.items():
            q[names.index(k.replace("_", "."))] = v
        return StepState(q, 0 * q, 0 * q, e, e, e)
    model.check_state(0.0, state(n1_ry=0.2, n2_ry=0.4), params)          # within range: no error
    with pytest.raises(ModelError, match="shorter elements"):
        model.check_state(0.0, state(n2_ry=1.5), params)
    with pytest.raises(ModelError, match="full turn"):
        model.check_state(0.0, state(n1_rx=6.1, n2_rx=6.1), params)     # a rigid twist: no local bending


def test_space_frame_on_sparse_storage_equals_dense(frame_run) -> None:
    # the pattern-kept sparse assembly carries the frames' forces, inertia and consistent mass
    case, dense = frame_run
    raw = space_frame()
    raw["model"]["linear_algebra"] = "sparse"
    sparse_case = load_case_dict(raw)
    assert sparse_case.model.traits.sparse and not case.model.traits.sparse
    sparse = dynsens.run_case(sparse_case)
    for name, rv in dense.responses.items():
        assert float(np.real(sparse.responses[name].value)) == pytest.approx(float(np.real(rv.value)), rel=1e-10)
        np.testing.assert_allclose(sparse.responses[name].gradient, rv.gradient, rtol=1e-9,
                                   atol=1e-12 * np.abs(rv.gradient).max(), err_msg=name)
