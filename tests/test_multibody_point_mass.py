"""Point masses (cases/point_pendulum.yaml): a true point mass on a distance joint against the
simple pendulum's closed forms (period, rod tension), zero orientation-lock moments, complex
step of the whole run, and the rules for what may attach to a point mass."""
from __future__ import annotations

import numpy as np
import pytest
import yaml
from scipy.special import ellipk

import dynsens
from conftest import CASES
from dynsens.errors import CaseError, ModelError
from helpers import complex_step_gradients, rel_err

G = 9.81


def test_point_mass_pendulum_period_and_rod_tension():
    """T = 4 sqrt(L/g) K(1/2) (no inertia invented: the bob is a point); the rod tension of a
    pendulum released horizontally is 3 m g sin φ (φ below the horizontal, read from the computed
    pose; the difference is the scheme's O(Δt²) error in λ); the lock's moments
    vanish and the bob's Euler parameters stay the identity."""
    case = dynsens.load_case(CASES / "point_pendulum.yaml", overrides=["integrator.dt=0.005"])
    res = dynsens.run_case(case, sensitivities=False, history=("q", "lam"))
    T = 4 * np.sqrt(1.0 / G) * ellipk(0.5)
    assert abs(res.responses["period"].value / T - 1) < 1e-8
    lab = case.model.multiplier_labels()
    lam, q = res.history["lam"], res.history["q"]
    assert np.max(np.abs(lam[:, [lab.index(f"bob.orientation.{c}") for c in ("u.w", "v.w", "u.v")]])) < 1e-12
    assert np.max(np.abs(q[:, 3:7] - [1.0, 0, 0, 0])) < 1e-12
    tension = 3 * 1.0 * G * (-q[:, 1])                      # L = 1: sin φ = −y
    rod = lam[:, lab.index("rod.rod")]
    assert np.max(np.abs(np.abs(rod) - tension)) < 1e-3 * 3 * G     # 2.5e-4 of it at Δt = 5 ms: O(Δt²)


def test_point_mass_sensitivities_match_complex_step():
    case = dynsens.load_case(CASES / "point_pendulum.yaml", overrides=["integrator.dt=0.005"])
    res = dynsens.run_case(case)
    cs = complex_step_gradients(case)
    for name, r in res.responses.items():
        assert rel_err(r.gradient, cs[name]) < 1e-7, name


def _raw():
    return yaml.safe_load((CASES / "point_pendulum.yaml").read_text())


@pytest.mark.parametrize("edit, path, words", [
    (lambda r: r["model"]["bodies"]["bob"].update(inertia=[1, 1, 1]), "model.bodies.bob.inertia", "point mass"),
    (lambda r: r["model"]["bodies"]["bob"].update(orientation={"angle": 0.1}), "model.bodies.bob.orientation",
     "point mass"),
    (lambda r: r["model"]["joints"].append({"name": "hinge", "type": "revolute", "body_1": "ground", "body_2": "bob",
                                            "point": [0, 0, 0], "axis": [0, 0, 1]}),
     "model.joints[1].body_2", "carries no moment"),
    (lambda r: r["model"].update(forces=[{"type": "torque", "name": "t", "body": "bob", "torque": [0, 0, 1]}]),
     "model.forces[0].type", "point mass"),
    (lambda r: r["model"]["bodies"]["bob"].update(point_mass="yes"), "model.bodies.bob.point_mass", "true or false"),
])
def test_point_mass_input_errors(edit, path, words):
    raw = _raw()
    edit(raw)
    with pytest.raises(CaseError) as exc:
        dynsens.load_case_dict(raw, source="pp.yaml")
    msg = str(exc.value)
    assert "pp.yaml" in msg and path in msg and words in msg, msg


def test_attachment_off_the_mass_point_is_refused():
    raw = _raw()
    raw["model"]["bodies"]["bob"]["markers"]["c"] = ["0.1*L", 0, 0]     # a design expression: checked per design
    case = dynsens.load_case_dict(raw, source="pp.yaml")
    with pytest.raises(ModelError) as exc:
        dynsens.run_case(case, sensitivities=False)
    msg = str(exc.value)
    assert "point mass 'bob'" in msg and "marker_2 of joint 'rod'" in msg and "from its mass point" in msg
