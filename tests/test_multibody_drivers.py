"""General drivers: a joint angle, a body coordinate and a distance prescribed by expressions of
time and the design (cases/rheonomic.yaml) against their closed forms and complex step of the
whole run; driver input errors."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

import dynsens
from conftest import CASES
from dynsens.errors import CaseError
from helpers import complex_step_gradients, rel_err

G = 9.81


def test_driven_coordinates_and_driving_forces_match_closed_forms():
    """Positions follow the prescribed x(t) to the index-1 drift (< 1e-5); the driving forces
    are the closed forms: slider −m ẍ(t) to round-off (its acceleration constraint is exact and
    linear), cart −m L̈(t), crank I_O θ̈ + m g r cos θ (these two read the drifting pose)."""
    case = dynsens.load_case(CASES / "rheonomic.yaml")
    a, m = case.x0
    res = dynsens.run_case(case, sensitivities=False, history=("q", "lam"))
    assert res.status == "completed"
    t, q, lam = res.time, res.history["q"], res.history["lam"]
    lab = case.model.multiplier_labels()
    th = a * t ** 2 + 0.3 * np.sin(2 * t) ** 2
    thdd = 2 * a + 2.4 * np.cos(4 * t)
    I_O, m_c, r = 0.02 + 1.5 * 0.2 ** 2, 1.5, 0.2
    assert np.max(np.abs(np.unwrap(np.arctan2(q[:, 1], q[:, 0])) - th)) < 1e-5
    torque = I_O * thdd + m_c * G * r * np.cos(th)
    assert np.max(np.abs(lam[:, lab.index("crank_drive.drive")] - torque)) < 5e-5 * np.max(np.abs(torque))
    x = 0.5 + 0.5 * a * t ** 2 - 0.05 * np.exp(-t) * np.cos(5 * t) + 0.05
    xdd = a - 0.05 * np.exp(-t) * (-24 * np.cos(5 * t) + 10 * np.sin(5 * t))
    assert np.max(np.abs(q[:, 7] - x)) < 1e-5
    assert np.max(np.abs(lam[:, lab.index("slider_drive.drive")] + m * xdd)) < 1e-12 * np.max(np.abs(m * xdd))
    L = 0.5 + 0.2 * t + a * (np.sqrt(1 + t ** 2) - 1)
    Ldd = a * (1 + t ** 2) ** -1.5
    assert np.max(np.abs(q[:, 14] - L)) < 1e-5
    assert np.max(np.abs(lam[:, lab.index("cart_drive.drive")] + m * Ldd)) < 1e-5 * np.max(m * Ldd)


def test_driver_sensitivities_match_complex_step():
    case = dynsens.load_case(CASES / "rheonomic.yaml", overrides=["integrator.t_end=0.5"])
    res = dynsens.run_case(case, sensitivities=True)
    cs = complex_step_gradients(case)
    for name, r in res.responses.items():
        assert rel_err(r.gradient, cs[name]) < 1e-7, name


def _raw():
    return yaml.safe_load((CASES / "rheonomic.yaml").read_text())


@pytest.mark.parametrize("edit, path, words", [
    (lambda j: j[1].update(rate=1.0), "model.joints[1]", "either 'expression'"),
    (lambda j: j[1].update(expression="a*tt"), "model.joints[1].expression", "unknown symbol 'tt'"),
    (lambda j: j[1].update(expression="a*eval(t)"), "model.joints[1].expression", "not allowed"),
    (lambda j: j[3].update(joint="guide"), "model.joints[3]", "exactly one of"),
    (lambda j: j[5].update(distance=["cart.C", "cart.C"]), "model.joints[5].distance", "different bodies"),
    (lambda j: j[5].update(distance=["ground.G", "cart.X"]), "model.joints[5].distance[1]", "no marker"),
])
def test_driver_input_errors(edit, path, words):
    raw = _raw()
    edit(raw["model"]["joints"])
    with pytest.raises(CaseError) as exc:
        dynsens.load_case_dict(raw, source="rheo.yaml")
    msg = str(exc.value)
    assert "rheo.yaml" in msg and path in msg and words in msg, msg
