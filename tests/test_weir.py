"""The Tyrolean-weir case at x0: reference figures of weir_model.md and sensitivities
against complex step of the whole simulation (shortened runs)."""
import numpy as np
import pytest

import dynsens
from conftest import CASES
from helpers import complex_step_gradients, rel_err

WEIR = CASES / "tyrolean_weir.yaml"
# end the cycle early: the rack reaches −27.38° after ≈ 0.1 s (instead of −8° after 7.8 s)
SHORT = ["events[0].value=-0.4780", "output.history=[q, p]"]


def test_initial_state_and_start_transient_match_the_reference():
    res = dynsens.run_case(dynsens.load_case(WEIR, ["integrator.t_end=0.05", "output.history=[q, p]"]))
    r = res.responses
    assert r["opening_angle"].value == pytest.approx(27.5998, abs=1e-3)          # deg (§0)
    assert res.history["p"][0, 0] == pytest.approx(3.0662, abs=1e-4)               # p1(t0), MPa (§3.7)
    # the KS maximum is the valve-opening transient at ≈ 14 ms: the 50 ms run already has it;
    # reference: fixed-step trapezoidal sketch 29 794.15 N (§4), ±0.1 %
    assert r["ks_force"].value == pytest.approx(29794.15, rel=1e-3)
    # ∇g1 against the sketch's forward differences (§4), within their truncation error
    assert np.allclose(r["g1"].gradient, [1.50436, -5.3939e-4, -1.1987e-5, 0.0], rtol=1e-3, atol=1e-12)
    assert np.max(res.monitors["constraint_position"]) < 1e-6                     # mm


@pytest.mark.parametrize("location", ["interpolate", "step"])
def test_weir_sensitivities_match_complex_step(location):
    case = dynsens.load_case(WEIR, SHORT + [f"integrator.event_location={location}",
                                            "sensitivity.partials=complex"])
    res = dynsens.run_case(case)
    assert res.status == "terminated" and 0.05 < res.responses["t_F"].value < 0.2
    ref = complex_step_gradients(case)
    for name, r in res.responses.items():
        if location == "step" and name in ("t_F", "g3"):
            # step mode: the event time is a staircase of x; complex step (like FD) sees zero,
            # the semi-analytical implicit-function gradient does not
            assert np.all(ref[name] == 0.0) and np.linalg.norm(r.gradient) > 0
            continue
        if location == "step" and name in ("stroke", "g2"):
            # ... and the stroke "at the event" is read at a fixed step: the whole-run derivative
            # is the fixed-time one (as in the paper's Table 1)
            fixed = res.responses[f"{name}_fixed_time"].gradient
            assert rel_err(ref[name], fixed) < 1e-8, name
            continue
        if r.kind == "fixed_time" or name == "g2_fixed_time":
            continue
        assert rel_err(r.gradient, ref[name]) < 1e-8, name
    if location == "interpolate":
        # total vs fixed-time stroke gradients differ by ṡ dt_F/dx
        s_dot = 62.0                                                               # mm/s, roughly
        diff = res.responses["stroke"].gradient - res.responses["stroke_fixed_time"].gradient
        assert np.allclose(diff, s_dot * res.responses["t_F"].gradient, rtol=0.5)


@pytest.mark.parametrize("kernel", ["compiled", "numpy"])
def test_static_start_at_the_optimum_converges(kernel, monkeypatch):
    """At this design (met by the optimizer next to its optimum) the static start's accelerations
    are pure round-off (~1e-11 mm/s² against multipliers of 1e7): Newton stops at the residual's
    noise floor instead of failing after max_iterations (it did with the compiled kernel's
    round-off before the stagnation test)."""
    monkeypatch.setenv("DYNSENS_KERNEL", kernel)
    x = np.array([float.fromhex(h) for h in ("-0x1.1504c6385e156p+0", "0x1.d6eb159eee6c5p+10",
                                               "0x1.d78adcdf4c410p+10", "0x1.e024671700986p+18")])
    case = dynsens.load_case(WEIR, ["integrator.t_end=0.005", "output.history=none"])
    res = dynsens.run_case(case, x)
    assert res.status == "completed"
    assert res.counters["newton_iterations"] <= 25 + 2 * 5        # the start and five steps
