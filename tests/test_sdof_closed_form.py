"""SDOF step response and its m, c, k sensitivities against the closed-form solution."""
import numpy as np

import dynsens
from conftest import CASES


def closed_form(x, t=10.0, F=10.0):
    """Displacement of a damped oscillator under a constant force from rest (complex-safe)."""
    m, c, k = x
    wn = np.sqrt(k / m)
    zeta = c / (2 * np.sqrt(k * m))
    wd = wn * np.sqrt(1 - zeta ** 2)
    return F / k * (1 - np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta * wn / wd * np.sin(wd * t)))


def test_value_and_sensitivities_match_closed_form():
    case = dynsens.load_case(CASES / "sdof_step.yaml", ["sensitivity.partials=complex"])
    res = dynsens.run_case(case)
    x = case.x0
    exact = closed_form(x)
    grad = np.array([np.imag(closed_form(x + 1j * 1e-20 * np.eye(3)[j])) / 1e-20 for j in range(3)])
    r = res.responses["q_end"]
    # discretization error of the trapezoidal rule: period error ~ (ω Δt)²/12 over 10 s
    assert abs(r.value - exact) < 2e-4 * abs(exact)
    assert np.linalg.norm(r.gradient - grad) < 2e-3 * np.linalg.norm(grad)
    # and the error falls with Δt²: halve the step, error / 4
    fine = dynsens.run_case(dynsens.load_case(CASES / "sdof_step.yaml",
                                              ["sensitivity.partials=complex", "integrator.dt=5e-4"]))
    e1 = np.linalg.norm(r.gradient - grad)
    e2 = np.linalg.norm(fine.responses["q_end"].gradient - grad)
    assert 3.0 < e1 / e2 < 5.0
