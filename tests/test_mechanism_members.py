"""Flexible members inside a mechanism (dynsens/models/multibody/members.py, issue 33): a bar
between node bodies against the closed form of a hanging mass, the rigid limit (a point mass
on a very stiff bar against the distance-joint pendulum of cases/point_pendulum.yaml), the
coupled sensitivities of cases/mechanism_members.yaml against the complex step of the whole run
and the adjoint, and the input errors."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

import dynsens
from conftest import CASES
from dynsens.case.load import load_case_dict
from dynsens.errors import CaseError
from helpers import assert_gradients_match_complex_step_and_adjoint

G = 9.81


def _hanging(E=2.0e9, m=2.0, L=1.0, rho=7800.0, A=1.0e-6):
    """A point mass m hanging from the ground on a bar (E, A, ρ, length L), released unstretched
    and settling under a critically damped axial dashpot."""
    k = E * A / L
    m_node = m + rho * A * L / 2
    return {
        "name": "hanging_bar",
        "design": {"variables": [{"name": "A", "value": A, "lower": A / 10, "upper": 10 * A}]},
        "model": {
            "type": "multibody", "gravity": [0, -G, 0],
            "bodies": {"ground": {"markers": {"O": [0, 0, 0]}},
                       "bob": {"point_mass": True, "mass": m, "position": [0, -L, 0]}},
            "members": [{"name": "bar", "type": "bar", "nodes": ["ground.O", "bob"], "E": E, "area": "A",
                         "density": rho, "damping": 2 * np.sqrt(k * m_node)}],
        },
        "integrator": {"scheme": "newmark", "dt": 1e-3, "t_end": 1.0},
        "sensitivity": {"enabled": True, "partials": "complex"},
        "responses": [
            {"name": "y_end", "type": "value", "quantity": {"body": "bob", "kind": "position"},
             "component": "bob.y"},
            {"name": "force_end", "type": "value", "quantity": {"element": "bar", "kind": "force"}},
            {"name": "stress_end", "type": "value", "quantity": {"element": "bar", "kind": "stress"}},
            {"name": "strain_end", "type": "value", "quantity": {"element": "bar", "kind": "strain"}},
            {"name": "mass", "type": "mass"},
        ],
    }


def test_hanging_mass_stretches_the_bar_by_m_g_L_over_E_A():
    """Static elongation δ = (m + ρAL/2) g L/(EA): the tip mass plus the bar's own weight, whose
    end displacement ρ g L²/(2E) the half-mass lumped on the tip reproduces exactly (Timoshenko &
    Goodier, a bar hanging under its own weight); the damped run settles to it (critically damped
    axial mode, 1 s ≈ 20 time constants).  Force m_node g, stress force/A, strain δ/L; the mass
    response counts the whole bar (ρAL, half of it on the ground); dδ/dA closed form too."""
    E, m, L, rho, A = 2.0e9, 2.0, 1.0, 7800.0, 1.0e-6
    res = dynsens.run_case(load_case_dict(_hanging(E, m, L, rho, A)))
    r = {n: v for n, v in res.responses.items()}
    m_node = m + rho * A * L / 2
    delta = m_node * G * L / (E * A)
    assert abs(-r["y_end"].value - (L + delta)) < 1e-9 * delta
    assert abs(r["force_end"].value / (m_node * G) - 1) < 1e-9
    assert abs(r["stress_end"].value / (m_node * G / A) - 1) < 1e-9
    assert abs(r["strain_end"].value / (delta / L) - 1) < 1e-9
    assert abs(r["mass"].value - (m + rho * A * L)) < 1e-15
    # y = −(L + δ(A)), δ = m g L/(EA) + ρ g L²/(2E): dy/dA = m g L/(E A²)
    assert abs(r["y_end"].gradient[0] / (m * G * L / (E * A * A)) - 1) < 1e-7
    assert abs(r["mass"].gradient[0] / (rho * L) - 1) < 1e-14


def test_a_bar_given_its_static_initial_force_starts_in_equilibrium():
    """``initial_force: N0`` sets the free length L0 = Li E A/(E A + N0): with N0 = m_node g (an
    expression of the design A, as a case written for a static start gives it) the hanging mass
    holds at its initial pose −L for the whole second, at every A, so y, force and strain are the
    closed forms y = −L, N = m_node g, ε = N/(EA) and dy/dA = 0; the mass counts the bar at its
    initial length.  (Without ``initial_force`` the same bar stretches by δ, the test above.)"""
    E, m, L, rho, A = 2.0e9, 2.0, 1.0, 7800.0, 1.0e-6
    raw = _hanging(E, m, L, rho, A)
    raw["model"]["members"][0].update(damping=0.0, initial_force=f"({m} + {rho}*A*{L}/2)*{G}")
    res = dynsens.run_case(load_case_dict(raw))
    r = res.responses
    m_node = m + rho * A * L / 2
    assert abs(r["y_end"].value + L) < 1e-12 * L
    assert abs(r["y_end"].gradient[0]) < 1e-12 * m * G * L / (E * A * A)
    assert abs(r["force_end"].value / (m_node * G) - 1) < 1e-12
    assert abs(r["strain_end"].value / (m_node * G / (E * A)) - 1) < 1e-9
    assert abs(r["mass"].value - (m + rho * A * L)) < 1e-15


def test_gradients_through_a_bar_pretension():
    """A pretension that does not balance the load (half the weight, an expression of A) makes
    the mass oscillate: the gradients through the free length L0(A, N0(A)) against the complex
    step of the whole run (1e-8) and the adjoint (1e-10)."""
    raw = _hanging()
    raw["integrator"]["t_end"] = 0.05
    raw["model"]["members"][0].update(initial_force=f"0.5*(2.0 + 7800.0*A/2)*{G}*A/1.0e-6")
    case = load_case_dict(raw)
    res = dynsens.run_case(case)
    assert abs(res.responses["y_end"].value + 1.0) > 1e-7          # it moved
    assert_gradients_match_complex_step_and_adjoint(case, res, rtol_cs=1e-8, rtol_adjoint=1e-10)


def _pendulum(dt, rod):
    """cases/point_pendulum.yaml at step dt with its distance joint ('joint') or a bar of E A = 1e12 N
    ('bar') as the rod; the rod force response reads the joint's multiplier or the bar's tension."""
    raw = yaml.safe_load((CASES / "point_pendulum.yaml").read_text(encoding="utf-8"))
    raw["integrator"]["dt"] = dt
    if rod == "bar":
        raw["model"].pop("joints")
        raw["model"]["members"] = [{"name": "rod", "type": "bar", "nodes": ["ground.O", "bob"],
                                    "E": 1.0e12, "area": 1.0}]
        raw["responses"][-1]["quantity"] = {"element": "rod", "kind": "force"}
    return dynsens.run_case(load_case_dict(raw))


def test_a_very_stiff_bar_reproduces_the_rigid_pendulum_and_its_gradients():
    """Rigid limit: a point mass on a bar of EA/L = 1e12 N/m (ω Δt ≈ 5e3) against the distance
    joint. At Δt = 2.5 ms the responses (half period, far-side position, KS of the rod force) agree
    within 5e-5 and their gradients (by L and m) within 1e-4 of the largest entry; halving Δt cuts the
    half-period difference about four times (3 to 5: both are second-order in Δt and tend to the same
    limit, so the difference is the scheme's error, not the bar's compliance)."""
    diffs = {}
    for dt in (5e-3, 2.5e-3):
        rigid, flex = _pendulum(dt, "joint"), _pendulum(dt, "bar")
        diffs[dt] = abs(flex.responses["half_period"].value / rigid.responses["half_period"].value - 1)
    for name, r in rigid.responses.items():
        f = flex.responses[name]
        assert abs(f.value / r.value - 1) < 5e-5, name
        assert np.max(np.abs(f.gradient - r.gradient)) < 1e-4 * np.max(np.abs(r.gradient)), name
    assert 3.0 < diffs[5e-3] / diffs[2.5e-3] < 5.0, diffs


def test_coupled_sensitivities_of_a_member_in_a_mechanism():
    """cases/mechanism_members.yaml: the rope's section A (stiffness and lumped mass) and the drive
    torque; the KS of the rope stress and of the hinge reaction, the mass and the arm angle against
    the complex step of the whole run (1e-8) and the adjoint (1e-10)."""
    case = dynsens.load_case(CASES / "mechanism_members.yaml")
    res = dynsens.run_case(case)
    assert res.status == "completed"
    assert_gradients_match_complex_step_and_adjoint(case, res, rtol_cs=1e-8, rtol_adjoint=1e-10)
    # the rope's mass is in the system: ρ A L0 with L0 the initial tip-to-payload distance 0.8 m
    assert abs(res.responses["mass"].gradient[0] - 1200.0 * 0.8) < 1e-9


def _raw():
    return yaml.safe_load((CASES / "mechanism_members.yaml").read_text(encoding="utf-8"))


@pytest.mark.parametrize("edit, path, words", [
    (lambda m: m[0].update(type="cable"), "model.members[0].type", "unknown member type"),
    (lambda m: m[0].update(nodes=["arm.tip"]), "model.members[0].nodes", "[node_1, node_2]"),
    (lambda m: m[0].update(nodes=["arm.tip", "payloda"]), "model.members[0].nodes[1]", "unknown body"),
    (lambda m: m[0].update(nodes=["arm.tipp", "payload"]), "model.members[0].nodes[0]", "no marker"),
    (lambda m: m[0].update(nodes=["ground", "payload"]), "model.members[0].nodes[0]", "ground.MARKER"),
    (lambda m: m[0].update(nodes=["payload", "payload"]), "model.members[0].nodes", "two different"),
    (lambda m: m[0].pop("area"), "model.members[0].area", "missing"),
    (lambda m: m[0].update(E=-1.0), "model.members[0].E", ""),
    (lambda m: m[0].update(aera=1.0), "model.members[0].aera", "did you mean 'area'"),
    (lambda m: m[0].update(initial_force=-1e15), "model.members[0].initial_force", "initial force > -E A"),
    (lambda m: m.append(dict(m[0])), "model.members[1].name", "duplicate"),
    (lambda m: m[0].update(type="beam", G=1.0, Iy=1.0, Iz=1.0, J=1.0), "model.members[0].nodes[1]",
     "no orientation"),
    (lambda m: m[0].update(type="beam", G=1.0, Iy=1.0, Iz=1.0), "model.members[0].J", "missing"),
])
def test_member_input_errors(edit, path, words):
    raw = _raw()
    edit(raw["model"]["members"])
    with pytest.raises(CaseError) as exc:
        load_case_dict(raw)
    text = str(exc.value)
    assert path in text and words in text, text


def test_unknown_member_quantity_is_reported():
    raw = _raw()
    raw["responses"][0]["quantity"]["kind"] = "stres"
    with pytest.raises(CaseError, match=r"did you mean 'stress'"):
        load_case_dict(raw)


# ---------------------------------------------------------------------------------- beams
BEAM = {"E": 2.0e11, "G": 8.0e10, "area": 1.0e-4, "Iy": 2.0e-9, "Iz": 8.0e-9, "J": 3.0e-9}


def _cantilever(force, torque):
    """A beam member clamped to the ground (node ground.O) with a small rigid tip body (its COM the
    node) at L = 1 along x, loaded at the tip; β = 0.05 s damps every mode (the slowest decays as
    e^(−t/β)), so 1 s settles to the static state."""
    raw = {
        "name": "cantilever",
        "design": {"variables": [{"name": "A", "value": BEAM["area"], "lower": 1e-5, "upper": 1e-3}]},
        "model": {
            "type": "multibody",
            "bodies": {"ground": {"markers": {"O": [0, 0, 0]}},
                       "tip": {"mass": 1.0, "inertia": [0.01, 0.01, 0.01], "position": [1.0, 0, 0]}},
            "members": [{"name": "beam", "type": "beam", "nodes": ["ground.O", "tip"], **BEAM, "area": "A",
                         "damping": 0.05}],
            "forces": [{"type": "point_force", "name": "P", "body": "tip", "force": list(force)},
                       {"type": "torque", "name": "T", "body": "tip", "torque": list(torque)}],
        },
        "integrator": {"scheme": "newmark", "dt": 5e-3, "t_end": 1.0},
        "sensitivity": {"enabled": False},
    }
    return dynsens.run_case(load_case_dict(raw), history=("q",)).history["q"][-1]


def test_beam_member_cantilever_static_closed_forms():
    """Tip of a cantilever (Euler–Bernoulli, small deflections; local y = global z by the default
    orientation, so a load along global y bends about local y): axial δ = PL/(EA), twist
    φ = TL/(GJ) (φ = 2 e₁ of the tip's Euler parameters), lateral w = PL³/(3EI) and end slope
    PL²/(2EI) in both planes.  Loads small (w/L ~ 1e-5) so the co-rotational element's geometric
    terms stay below 1e-9; the axial check is limited by the absolute settling of the position
    (~2e-10 of L = 1 against δ = 1e-5)."""
    E, G, A, Iy, Iz, J = (BEAM[k] for k in ("E", "G", "area", "Iy", "Iz", "J"))
    q = _cantilever([200.0, 0, 0], [0.05, 0, 0])
    assert abs((q[0] - 1.0) / (200.0 / (E * A)) - 1) < 1e-4
    assert abs(2 * q[4] / (0.05 / (G * J)) - 1) < 1e-7
    Py, Pz = -0.012, 0.05
    q = _cantilever([0, Py, Pz], [0, 0, 0])
    assert abs(q[1] / (Py / (3 * E * Iy)) - 1) < 1e-8
    assert abs(q[2] / (Pz / (3 * E * Iz)) - 1) < 1e-8
    assert abs(2 * q[6] / (Py / (2 * E * Iy)) - 1) < 1e-8           # slope about z of the y deflection
    assert abs(2 * q[5] / (-Pz / (2 * E * Iz)) - 1) < 1e-6          # about y of the z deflection


def _arm_with_beam(method="direct", raw_only=False):
    """A rigid arm hinged to the ground (revolute about z) and driven by a torque T carries a tip body
    on a flexible square-section beam (side a, A = a², I = a⁴/12, J = 2.25 (a/2)⁴) off the arm's tip,
    under gravity; the design is the beam's side a (stiffness, mass and rotary inertia) and T."""
    raw = {
        "name": "arm_with_beam",
        "design": {"variables": [{"name": "a", "value": 0.01, "lower": 0.005, "upper": 0.02},
                                 {"name": "T", "value": 40.0, "lower": 20.0, "upper": 60.0}]},
        "model": {
            "type": "multibody", "gravity": [0, -9.81, 0],
            "bodies": {"arm": {"mass": 4.0, "inertia": [0.01, 0.34, 0.34], "position": [0.5, 0, 0],
                               "markers": {"tip": [0.5, 0, 0]}},
                       "head": {"mass": 1.0, "inertia": [0.002, 0.002, 0.002], "position": [1.5, 0, 0]}},
            "joints": [{"name": "hinge", "type": "revolute", "body_1": "ground", "body_2": "arm",
                        "point": [0, 0, 0], "axis": [0, 0, 1]}],
            "members": [{"name": "beam", "type": "beam", "nodes": ["arm.tip", "head"], "E": 7.0e10,
                         "G": 2.6e10, "area": "a**2", "Iy": "a**4/12", "Iz": "a**4/12", "J": "0.1406*a**4",
                         "density": 2700.0, "damping": 1.0e-3}],
            "forces": [{"type": "torque", "name": "drive", "body": "arm", "torque": [0, 0, "T"]}],
        },
        "integrator": {"scheme": "newmark", "dt": 5e-3, "t_end": 0.2},
        "sensitivity": {"enabled": True, "partials": "complex", "method": method},
        "responses": [
            {"name": "hinge_force", "type": "ks", "quantity": {"joint": "hinge", "kind": "reaction_force_norm"},
             "rho": 0.05},
            {"name": "root_moment", "type": "ks", "quantity": {"element": "beam", "kind": "moments"},
             "rho": 0.1},
            {"name": "head_y", "type": "value", "quantity": {"body": "head", "kind": "position"},
             "component": "head.y"},
            {"name": "mass", "type": "mass"},
        ],
    }
    return raw if raw_only else load_case_dict(raw)


def test_coupled_sensitivities_through_a_beam_member():
    """Direct gradients through the beam member (its section a sets EA, EI, GJ, the lumped mass and
    rotary inertia) and the drive torque against the complex step of the whole run (1e-7, set when
    the element's Jacobian inside a complex run was by central differences; it is exact now) and
    the adjoint (1e-9)."""
    case = _arm_with_beam()
    res = dynsens.run_case(case)
    assert res.status == "completed"
    assert_gradients_match_complex_step_and_adjoint(case, res, rtol_cs=1e-7, rtol_adjoint=1e-9)
    # mass: arm + head + ρ a² L (L = 0.5 m, arm tip to head)
    assert abs(res.responses["mass"].value - (5.0 + 2700.0 * 1e-4 * 0.5)) < 1e-12


def test_a_very_stiff_beam_reproduces_a_welded_tip():
    """Rigid limit of the beam: with E = 7e15 Pa (massless, β = 1 ms) the head on the beam moves as
    the head welded to the arm by a fixed joint: its end height within 1e-6 and its gradient by the
    torque within 1e-5; by the section a (which the welded model does not have) the gradient is
    the compliance's, ∝ 1/E, below 1e-2 of the torque's.  (The hinge reaction's KS is not compared:
    it includes the stiff transient of the release, whose force amplitude does not vanish with E.)"""
    raw = _arm_with_beam(raw_only=True)
    raw["model"]["members"][0].update(E=7.0e15, G=2.6e15, density=0.0)
    raw["responses"] = [r for r in raw["responses"] if r["name"] == "head_y"]
    welded = yaml.safe_load(yaml.safe_dump(raw))
    welded["model"].pop("members")
    welded["model"]["joints"].append({"name": "weld", "type": "fixed", "body_1": "arm", "body_2": "head",
                                      "point": [1.0, 0, 0]})
    welded["design"]["variables"] = welded["design"]["variables"][1:]         # no section a
    flex = dynsens.run_case(load_case_dict(raw)).responses["head_y"]
    rigid = dynsens.run_case(load_case_dict(welded)).responses["head_y"]
    assert abs(flex.value / rigid.value - 1) < 1e-6
    assert abs(flex.gradient[1] / rigid.gradient[0] - 1) < 1e-5
    assert abs(flex.gradient[0]) < 1e-2 * abs(rigid.gradient[0])


def test_beam_member_sparse_equals_dense():
    """The beam member acts outside the kernel; the sparse linearization places its exact
    Jacobian by its node bodies (sparse.element_bodies): same responses and gradients as dense."""
    out = {}
    for la in ("dense", "sparse"):
        raw = _arm_with_beam(raw_only=True)
        raw["model"]["linear_algebra"] = la
        raw["integrator"]["t_end"] = 0.05
        out[la] = dynsens.run_case(load_case_dict(raw)).responses
    for name, r in out["dense"].items():
        s = out["sparse"][name]
        assert abs(s.value - r.value) <= 1e-12 * abs(r.value), name
        np.testing.assert_allclose(s.gradient, r.gradient, rtol=1e-10, atol=1e-12 * np.abs(r.gradient).max(),
                                   err_msg=name)


def test_beam_member_exact_jacobians_equal_the_complex_step():
    """The beam member's exact ∂Q/∂q and ∂Q/∂q̇ (second-order jets, BeamMember.add_jacobians) equal
    the complex step of its generalized force Q (1e-9 of the largest entry) at a deformed, moving
    state of cases like _arm_with_beam (one node on a body marker, one at a body's COM, damping on)
    and of the cantilever's ground node.  Before the exact Jacobians the element had none
    (add_jacobians raised NotImplementedError)."""
    from dynsens.models.multibody.assembly import _jac
    from dynsens.models.multibody.residual import other_forces_q
    rng = np.random.default_rng(33)
    for ground in (False, True):
        raw = _arm_with_beam(raw_only=True)
        if ground:
            raw["model"]["members"][0]["nodes"] = ["ground.O", "head"]
            raw["model"]["bodies"]["ground"] = {"markers": {"O": [0.5, 0.2, 0.1]}}
        raw["model"]["members"][0]["damping"] = 0.02
        model = load_case_dict(raw).model
        prm = model.parameters(np.array([0.01, 40.0]))
        beam = [el for el in model.other_forces if el.name == "beam"]
        assert len(beam) == 1 and beam[0].exact_jacobians
        n = model.traits.n_q
        q = np.zeros(n)
        for b in range(n // 7):                   # arm at 0.3 rad about z, head displaced and turned
            ang = np.array([0.3, 0.35])[b] if b < 2 else 0.0
            q[7 * b + 3:7 * b + 7] = [np.cos(ang / 2), 0.01 * rng.standard_normal(), 0.02, np.sin(ang / 2)]
            q[7 * b + 3:7 * b + 7] /= np.linalg.norm(q[7 * b + 3:7 * b + 7])
        q[0:3] = [0.5 * np.cos(0.3), 0.5 * np.sin(0.3), 0.0]
        q[7:10] = [1.5 * np.cos(0.3) + 0.01, 1.5 * np.sin(0.3) - 0.02, 0.005]
        qd = rng.standard_normal(n)
        Kq, Kqd = np.zeros((n, n)), np.zeros((n, n))
        beam[0].add_jacobians(0.0, q, qd, prm, Kq, Kqd)
        def force(qb, qdb, model=model, prm=prm, beam=beam):
            return other_forces_q(model, 0.0, qb, qdb, [prm], beam).T
        cq = _jac(lambda qb: force(qb.T, qd[None]), q, True)            # noqa: B023 (used at once)
        cqd = _jac(lambda qb: force(q[None], qb.T), qd, True)           # noqa: B023
        scale = np.abs(cq).max()
        assert scale > 1.0 and np.abs(cqd).max() > 0.0
        np.testing.assert_allclose(Kq, cq, rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(Kqd, cqd, rtol=0, atol=1e-9 * np.abs(cqd).max())
