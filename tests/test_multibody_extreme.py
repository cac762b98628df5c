"""Extreme multibody runs: a fast spinning top (large rotations), a stiff oil column."""
import warnings

import numpy as np
import pytest

import dynsens
from conftest import CASES
from dynsens.case.load import load_case_dict
from dynsens.errors import ModelError


def spinning_top(spin, dt, t_end, scheme="newmark", rho_inf=None, baumgarte=0.0):
    """Symmetric top (disc on a massless stem) on a spherical joint at its tip, tilted 30°."""
    tilt = np.radians(30.0)
    axis = [np.sin(tilt), np.cos(tilt), 0.0]
    integ = {"scheme": scheme, "dt": dt, "t_end": t_end}
    if rho_inf is not None:
        integ["rho_inf"] = rho_inf
    return dynsens.load_case_dict({
        "model": {"type": "multibody", "gravity": [0, -9.81, 0],
                  "stabilization": {"alpha": baumgarte, "beta": baumgarte},
                  "bodies": {"top": {
                      "mass": 1.0, "inertia": [0.0025, 0.005, 0.0025],   # spin axis = body y
                      "position": [0.1 * a for a in axis],
                      "orientation": {"axis": [0, 0, 1], "angle": -tilt},
                      "angular_velocity": [spin * a for a in axis],
                      "markers": {"tip": [0, -0.1, 0]}}},
                  "joints": [{"name": "tip", "type": "spherical", "body_1": "ground", "body_2": "top",
                              "point": [0, 0, 0]}]},
        "integrator": integ, "sensitivity": {"enabled": False},
        "output": {"history": ["q", "qd"]}})


@pytest.mark.parametrize("baumgarte,drift_bound", [(0.0, 1e-4), (50.0, 1e-5)])
def test_fast_spinning_top_keeps_normalization_and_energy(baumgarte, drift_bound):
    """200 rad/s spin, 0.5 s (≈ 16 revolutions), Δt = 1 ms: ω Δt = 0.2 per step.  Stated bounds
    on the index-1 drift of the tip joint (m, stem 0.1 m): 1e-4 plain, 1e-5 with Baumgarte 50/s."""
    case = spinning_top(200.0, 1e-3, 0.5, baumgarte=baumgarte)
    res = dynsens.run_case(case)
    q, qd = res.history["q"], res.history["qd"]
    e = q[:, 3:7]
    assert np.max(np.abs(np.sum(e * e, axis=1) - 1.0)) < 2e-7         # Euler-parameter normalization
    assert np.max(res.monitors["constraint_position"]) < drift_bound
    # energy: translational + rotational (body frame ω' = 2 G(e) ė) + potential
    m, J = 1.0, np.array([0.0025, 0.005, 0.0025])
    energy = []
    for k in range(len(res.time)):
        e0, e1, e2, e3 = e[k]
        G = np.array([[-e1, e0, e3, -e2], [-e2, -e3, e0, e1], [-e3, e2, -e1, e0]])
        w = 2 * G @ qd[k, 3:7]
        energy.append(0.5 * m * qd[k, :3] @ qd[k, :3] + 0.5 * w @ (J * w) + m * 9.81 * q[k, 1])
    energy = np.array(energy)
    assert np.max(np.abs(energy - energy[0])) < 1e-4 * abs(energy[0])
    # the top precesses instead of falling: its COM height stays close to the start
    assert np.min(q[:, 1]) > 0.08


def test_stiff_oil_column_stays_stable():
    """Hydraulic lever with a 100× stiffer oil column and 20× smaller dead volumes
    (hydraulic mode far above 1/Δt): no blow-up; generalized-α damps the oil-column ringing."""
    over = ["model.forces[1].bulk_modulus=1.0e5", "model.forces[1].dead_volume_1=1.0e4",
            "model.forces[1].dead_volume_2=1.0e4", "integrator.t_end=0.3", "sensitivity.enabled=false",
            "output.history=[p]"]
    ring = {}
    for label, extra in (("newmark", []),
                         ("galpha", ["integrator.scheme=generalized_alpha", "integrator.rho_inf=0.2"])):
        res = dynsens.run_case(dynsens.load_case(CASES / "hydraulic_lever.yaml", over + extra))
        p1 = res.history["p"][:, 0]
        assert np.all(np.isfinite(p1)) and np.max(p1) < 50.0            # MPa: bounded
        ring[label] = np.std(np.diff(p1[-50:]))                          # step-to-step ringing
    assert ring["galpha"] < 0.5 * ring["newmark"]


# ---------------------------------------------------------------- a spring whose two ends meet
def _tether(bodies: dict, spring: dict, dt: float = 1.0e-3) -> dict:
    """A free body and a spring-damper from a ground marker to it, no gravity."""
    return {"name": "tether", "design": {"variables": [{"name": "m", "value": 1.0, "lower": 0.5, "upper": 2.0}]},
            "model": {"type": "multibody", "gravity": [0, 0, 0], "bodies": bodies,
                      "forces": [{"type": "spring_damper", "name": "tether", **spring}]},
            "integrator": {"scheme": "newmark", "dt": dt, "t_end": 2.0},
            "sensitivity": {"enabled": False},
            "responses": [{"name": "x_end", "type": "value", "quantity": {"body": "bob", "kind": "position"},
                           "component": "bob.x"}]}


BOB = {"mass": "m", "inertia": [1.0, 1.0, 1.0], "position": [1.0, 0, 0], "markers": {"A": [0, 0, 0]}}


@pytest.mark.parametrize("bodies, spring, needle", [
    # the same marker of the same body at both ends: refused before anything is evaluated
    ({"bob": BOB}, {"body_1": "bob", "point_1": "A", "body_2": "bob", "point_2": "A", "stiffness": 10.0},
     "expected two distinct points, found point_1 and point_2 both 'A' of body 'bob'"),
    # two bodies' points at one place at the initial pose: the length is zero there
    ({"ground": {"markers": {"P": [1.0, 0, 0]}}, "bob": BOB},
     {"body_1": "ground", "point_1": "P", "body_2": "bob", "point_2": "A", "stiffness": 10.0},
     "expected two points apart at the initial pose, found both at [1.0, 0.0, 0.0]"),
], ids=["same_point", "coincide_at_start"])
def test_a_spring_of_zero_length_is_refused_at_load(bodies, spring, needle):
    # both raised ZeroDivisionError in the compiled kernel (the spring's direction d/L)
    with pytest.raises(dynsens.CaseError) as err:
        load_case_dict(_tether(bodies, spring))
    msgs = [p.message for p in err.value.problems if p.path == "model.forces[0]"]
    assert any(needle in m for m in msgs), str(err.value)
    assert "zero" in str(err.value)


def test_a_spring_whose_ends_meet_during_the_run_stops_it_naming_the_force():
    # the body glides (no force: k = 0) through the ground marker, exactly at t = 1 s
    bodies = {"ground": {"markers": {"P": [0.0, 0, 0]}}, "bob": {**BOB, "velocity": [-1.0, 0, 0]}}
    spring = {"body_1": "ground", "point_1": "P", "body_2": "bob", "point_2": "A", "stiffness": 0.0,
              "free_length": 1.0}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        case = load_case_dict(_tether(bodies, spring, dt=0.25))
    with pytest.raises(ModelError, match=r"at t = 1 s the two points of force 'tether' coincide: its length is zero"):
        dynsens.run_case(case, sensitivities=False)
