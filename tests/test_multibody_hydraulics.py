"""Hydraulic lever (cases/hydraulic_lever.yaml): static initial pressures, consistent
initial state and its exact gradient, event-based sensitivities against complex step of
the whole run, chamber-volume check."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

import dynsens
from conftest import CASES
from dynsens.errors import ModelError
from dynsens.derivatives.partials import DesignPartials
from helpers import complex_step_gradients, rel_err

CASE = CASES / "hydraulic_lever.yaml"
FAST = ["integrator.dt=0.01"]


@pytest.mark.parametrize("name", ["hydraulic_lever", "four_bar", "slider_crank", "tyrolean_weir"])
@pytest.mark.parametrize("method", ["complex", "central"])
def test_initial_state_gradient_is_exact(name, method):
    """Implicit differentiation of the assembly (+ velocities, static pressures; their state
    derivatives by batched complex step) against complex step of initial_state: 1e-12 (complex
    partials) / 1e-8 (central).  The gradient at the run's own assembly (kept by
    initial_state) is the same as at a fresh one."""
    case = dynsens.load_case(CASES / f"{name}.yaml")
    model, x0 = case.model, case.x0
    partials = DesignPartials(model, x0, method, scale=case.scale)
    dq, dqd, dp = model.initial_state_gradient(partials.params0, partials)
    model.initial_state(partials.params0)
    for a, b in zip(model.initial_state_gradient(partials.params0, partials), (dq, dqd, dp)):
        assert np.array_equal(a, b)
    ref = []
    for j in range(x0.size):
        h = 1e-20 * max(abs(x0[j]), 1.0)
        x = x0.astype(complex)
        x[j] += 1j * h
        ref.append([np.imag(v) / h for v in model.initial_state(model.parameters(x))])
    tol = 1e-12 if method == "complex" else 1e-8
    for k, d in enumerate((dq, dqd, dp)):
        r = np.stack([c[k] for c in ref], axis=1)
        assert np.linalg.norm(d - r) <= tol * max(np.linalg.norm(r), 1.0), (k, d, r)


def test_static_initial_state():
    """p1(t0) holds the load: q̈(t0) = 0, ṗ(t0) = 0, stroke 0 (|AB| = L0), p2 = tank."""
    case = dynsens.load_case(CASE, overrides=FAST + ["integrator.t_end=0.05"])
    res = dynsens.run_case(case, sensitivities=False, history=("q", "qdd", "p", "pd", "lam"))
    assert np.max(np.abs(res.history["qdd"][0])) < 1e-8
    assert np.max(np.abs(res.history["pd"][0])) < 1e-8
    p0 = res.history["p"][0]
    assert p0[1] == 0.0 and 3.0 < p0[0] < 6.0                    # MPa
    model = case.model
    prm = model.parameters(case.x0)
    q0, _, _ = model.initial_state(prm)
    from dynsens.errors import ProblemCollector
    out = model.output({"element": "cyl", "kind": "stroke"}, "q", ProblemCollector())
    s0 = dynsens.models.base.StepState(q0, 0 * q0, 0 * q0, res.history["lam"][0], p0, 0 * p0)
    assert abs(out.fn(0.0, s0, prm)[0]) < 1e-9                    # mm
    # the lever moves up once the valve opens
    assert res.history["q"][-1, 1] > res.history["q"][0, 1]


def test_event_sensitivities_match_complex_step_of_whole_run():
    """Event time, stroke/pressure at the event (interpolated, total derivative), KS of the
    pivot force, initial angle, and the state / multiplier / pressure sensitivities at the
    event step, against complex step of the whole simulation.

    Stated tolerance 1e-9 relative (complex-step partials; the agreement is ~1e-12 when every
    Newton solve is converged to round-off).  A modelling error shows up at 1e-3 or more."""
    case = dynsens.load_case(CASE, overrides=FAST + ["output.sensitivity_history=true",
                                                     "output.history=all"])
    res = dynsens.run_case(case)
    assert res.status == "terminated"
    cs = complex_step_gradients(case)
    for name, rv in res.responses.items():
        if name == "stroke_lift_fixed":
            continue
        assert rel_err(rv.gradient, cs[name]) < 1e-9, name
    # fixed-time stroke gradient differs from the total one by ṡ dt_F/dx
    fixed, total = res.responses["stroke_lift_fixed"].gradient, res.responses["stroke_lift"].gradient
    assert rel_err(fixed, total) > 0.5
    x0 = case.x0
    for j in range(x0.size):
        x = x0.astype(complex)
        h = 1e-20 * max(abs(x0[j]), 1.0)
        x[j] += 1j * h
        r = dynsens.run_case(case, x, history=("q", "lam", "p"))
        assert len(r.time) == len(res.time)
        for f in ("q", "lam", "p"):
            ref = np.imag(r.history[f][-1]) / h
            dd = res.sensitivity_history[f][-1][:, j]
            assert np.linalg.norm(dd - ref) <= 1e-9 * max(np.linalg.norm(ref), 1e-9), (f, j)


def test_chamber_volume_check_names_stroke_and_limit():
    raw = yaml.safe_load(CASE.read_text())
    raw["model"]["forces"][1]["stroke_max"] = 60.0
    raw["model"]["forces"][1]["dead_volume_2"] = 1.0e4
    raw["events"] = []
    raw["responses"] = [r for r in raw["responses"] if "event" not in r and r["type"] != "event_time"]
    raw["integrator"]["dt"] = 0.01
    case = dynsens.load_case_dict(raw)
    with pytest.raises(ModelError) as exc:
        dynsens.run_case(case, sensitivities=False)
    msg = str(exc.value)
    assert "rod-side volume V2 <= 0" in msg and "stroke s = " in msg and "limit s < 64.76" in msg
