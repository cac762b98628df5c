"""The integral of an expression of quantities (∫q² dt, a quadratic performance index): the
undamped oscillator's closed form, the gradient against complex step of the whole run, and
the plain integral it generalizes; input errors."""
from __future__ import annotations

import numpy as np
import pytest

import dynsens
from conftest import CASES
from dynsens.errors import CaseError
from helpers import complex_step_gradients, rel_err

DISP = {"dof": "u", "kind": "displacement"}


def _case(extra, over=()):
    import yaml
    raw = yaml.safe_load((CASES / "sdof_step.yaml").read_text())
    raw["responses"] = extra
    raw["integrator"]["t_end"] = 2.0
    raw["sensitivity"]["partials"] = "complex"
    return dynsens.load_case_dict(raw, source="sdof.yaml", overrides=list(over))


def test_integral_of_q_squared_matches_the_closed_form():
    """x = (F/k)(1 − cos ωt) without damping: ∫₀ᵀ x² dt = (F/k)²(3T/2 − 2 sin ωT/ω + sin 2ωT/(4ω));
    the trapezoidal sum over Newmark steps agrees to the scheme's O(Δt²) error: 2.5e-6
    relative at Δt = 1 ms, a quarter of it at 0.5 ms."""
    F, k, T = 10.0, 50.0, 2.0
    w = np.sqrt(k / 2.0)
    exact = (F / k) ** 2 * (1.5 * T - 2 * np.sin(w * T) / w + np.sin(2 * w * T) / (4 * w))
    errs = []
    for dt in (1e-3, 5e-4):
        case = _case([{"name": "J", "type": "integral", "expression": "x**2", "symbols": {"x": {"quantity": DISP}}}],
                     over=["design.variables[1].value=0.0", f"integrator.dt={dt}"])
        errs.append(abs(dynsens.run_case(case, sensitivities=False).responses["J"].value / exact - 1))
    assert errs[0] < 5e-6 and 3.5 < errs[0] / errs[1] < 4.5
    # the expression form with the identity integrand is the plain integral, bit for bit in value
    case2 = _case([{"name": "J", "type": "integral", "expression": "x", "symbols": {"x": {"quantity": DISP}}},
                   {"name": "I", "type": "integral", "quantity": DISP}])
    r2 = dynsens.run_case(case2)
    assert r2.responses["J"].value == pytest.approx(r2.responses["I"].value, rel=1e-14)
    assert rel_err(r2.responses["J"].gradient, r2.responses["I"].gradient) < 1e-14


def test_quadratic_index_gradient_matches_complex_step():
    case = _case([{"name": "J", "type": "integral", "expression": "x**2 + 0.01*v**2 + 0.3*sin(x)*v",
                   "symbols": {"x": {"quantity": DISP}, "v": {"quantity": {"dof": "u", "kind": "velocity"}}}}])
    res = dynsens.run_case(case)
    cs = complex_step_gradients(case)
    assert rel_err(res.responses["J"].gradient, cs["J"]) < 1e-9


@pytest.mark.parametrize("resp, path, words", [
    ({"name": "J", "type": "integral", "expression": "x**2 + y", "symbols": {"x": {"quantity": DISP}}},
     "responses[0].expression", "unknown symbol 'y'"),
    ({"name": "J", "type": "integral", "expression": "x**2"}, "responses[0]", "symbols"),
    ({"name": "J", "type": "integral", "expression": "x**2", "symbols": {"x": {"quantity": DISP, "comp": 0}}},
     "responses[0].symbols.x", "comp"),
])
def test_expression_integral_input_errors(resp, path, words):
    with pytest.raises(CaseError) as exc:
        _case([resp])
    msg = str(exc.value)
    assert "sdof.yaml" in msg and path in msg and words in msg, msg


def test_quadratic_index_adjoint_equals_direct():
    # the integrand's weights in the adjoint sweep: ∂f/∂v_j times the trapezoid weights
    resp = [{"name": "J", "type": "integral", "expression": "x**2 + 0.01*v**2 + 0.3*sin(x)*v",
             "symbols": {"x": {"quantity": DISP}, "v": {"quantity": {"dof": "u", "kind": "velocity"}}}}]
    direct = dynsens.run_case(_case(resp, over=["sensitivity.method=direct"]))
    adjoint = dynsens.run_case(_case(resp, over=["sensitivity.method=adjoint"]))
    assert adjoint.method == "adjoint"
    assert rel_err(adjoint.responses["J"].gradient, direct.responses["J"].gradient) < 1e-10


@pytest.mark.parametrize("method", ["direct", "adjoint"])
def test_constant_integrand_is_broadcast_to_the_samples(method):
    """An expression that reads none of its symbols (a constant c) integrates to c·T: on the
    point pendulum, which stops at its event, T is the event time and the gradient c·∇T; the
    same as the form that reads its symbol with a zero factor."""
    import yaml
    raw = yaml.safe_load((CASES / "point_pendulum.yaml").read_text())
    x = {"quantity": {"body": "bob", "kind": "position"}, "component": "bob.x"}
    raw["responses"] = [{"name": "half_period", "type": "event_time", "event": "far_side"},
                        {"name": "C", "type": "integral", "expression": "2", "symbols": {"x": x}},
                        {"name": "Z", "type": "integral", "expression": "2 + 0*x", "symbols": {"x": x}}]
    case = dynsens.load_case_dict(raw, source="pendulum.yaml", overrides=[f"sensitivity.method={method}"])
    res = dynsens.run_case(case).responses
    T = res["half_period"]
    assert res["C"].value == pytest.approx(2.0 * T.value, rel=1e-12)
    assert rel_err(res["C"].gradient, 2.0 * T.gradient) < 1e-12
    assert rel_err(res["C"].gradient, res["Z"].gradient) < 1e-14
    assert np.any(res["C"].gradient != 0.0)
