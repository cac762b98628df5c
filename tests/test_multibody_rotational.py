"""Rotational spring-damper between bodies (cases/torsional_pair.yaml): the damped relative
oscillation in closed form, its generalized force against complex step of the angle, whole-run
sensitivities against complex step, and its input/range errors."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

import dynsens
from conftest import CASES
from dynsens.errors import CaseError, ModelError, ProblemCollector
from dynsens.models.base import StepState
from dynsens.models.multibody.bodies import Ctx
from helpers import complex_step_gradients, rel_err


def _angle_output(case, kind="angle"):
    out = case.model.output({"element": "coupling", "kind": kind}, "q", ProblemCollector())
    assert out is not None
    return out


def test_relative_oscillation_matches_the_closed_form():
    """μ θ̈ + c θ̇ + k θ = 0, θ(0) = 0, θ̇(0) = −ω0: θ = −ω0/ω_d e^{−ζω_n t} sin(ω_d t); the
    trapezoidal rule's phase error at Δt = 2 ms keeps the difference below 2e-5 rad over 1 s."""
    case = dynsens.load_case(CASES / "torsional_pair.yaml", overrides=["integrator.dt=0.002", "integrator.t_end=1.0"])
    res = dynsens.run_case(case, sensitivities=False, history=("q", "qd"))
    prm = case.model.parameters(case.x0)
    out = _angle_output(case)
    z = np.zeros(case.model.traits.n_q)
    h = res.history
    th = np.array([out.fn(t, StepState(h["q"][i], h["qd"][i], z, z, z[:0], z[:0]), prm)[0]
                   for i, t in enumerate(res.time)])
    IA, IB, k, c, w0 = 0.2, 0.1, 2.0, 0.05, 2.0
    mu = IA * IB / (IA + IB)
    wn = np.sqrt(k / mu)
    zeta = c / (2 * mu * wn)
    wd = wn * np.sqrt(1 - zeta ** 2)
    ref = -w0 / wd * np.exp(-zeta * wn * res.time) * np.sin(wd * res.time)
    assert np.max(np.abs(th - ref)) < 2e-5


def test_generalized_force_is_the_torque_times_the_angle_gradient():
    """Q_ext of the element = T ∂θ/∂q with ∂θ/∂q by complex step of θ(q), and θ̇ = ∂θ/∂q · q̇,
    at random (not normalised) states."""
    case = dynsens.load_case(CASES / "torsional_pair.yaml")
    m = case.model
    el = next(f for f in m.rotational if f.name == "coupling")
    prm = m.parameters(case.x0)
    rng = np.random.default_rng(3)
    n = m.traits.n_q
    for _ in range(3):
        q = rng.normal(size=n) * 0.3
        for b in range(2):
            q[7 * b + 3] += 1.0
        qd = rng.normal(size=n)
        ctx = Ctx(q[:, None], qd[:, None], np.zeros((n, 1)), prm, 0.0)
        th, thd, T = el.state(ctx)
        Q = np.zeros((n, 1))
        el.add(ctx, Q)
        h = 1e-30
        grad = np.array([np.imag(el.state(Ctx((q + 1j * h * e)[:, None], qd[:, None].astype(complex),
                                                  np.zeros((n, 1)), prm, 0.0))[0][0, 0]) / h
                         for e in np.eye(n)])
        assert np.allclose(Q[:, 0], T[0, 0] * grad, rtol=1e-12, atol=1e-12 * np.max(np.abs(Q)))
        assert thd[0, 0] == pytest.approx(grad @ qd, rel=1e-12)


def test_rotational_sensitivities_match_complex_step():
    case = dynsens.load_case(CASES / "torsional_pair.yaml", overrides=["integrator.t_end=0.4", "integrator.dt=0.002"])
    res = dynsens.run_case(case)
    cs = complex_step_gradients(case)
    for name, r in res.responses.items():
        assert rel_err(r.gradient, cs[name]) < 1e-7, name


def test_rotation_beyond_the_measured_range_stops_the_run():
    case = dynsens.load_case(CASES / "torsional_pair.yaml",
                             overrides=["integrator.dt=0.005", "design.variables[0].lower=0.001",
                                                                        "design.variables[0].value=0.01",
                                                                        "model.forces[0].damping=0.0"])
    with pytest.raises(ModelError) as exc:
        dynsens.run_case(case, sensitivities=False)
    assert "rotational spring-damper 'coupling'" in str(exc.value) and "0.9π" in str(exc.value)


@pytest.mark.parametrize("edit, path", [
    (lambda f: f.update(body_2="A"), "model.forces[0].body_2"),
    (lambda f: f.pop("axis"), "model.forces[0].axis"),
    (lambda f: f.update(stiffnes=1.0), "model.forces[0]"),
])
def test_rotational_input_errors(edit, path):
    raw = yaml.safe_load((CASES / "torsional_pair.yaml").read_text())
    edit(raw["model"]["forces"][0])
    with pytest.raises(CaseError) as exc:
        dynsens.load_case_dict(raw, source="tp.yaml")
    assert "tp.yaml" in str(exc.value) and path in str(exc.value)
