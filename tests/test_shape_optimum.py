"""Shape optimization against a closed form: cases/two_bar_shape.yaml, the two-bar truss whose node
depth H (a node coordinate) and bar area A are the design (Christensen & Klarbring, An
Introduction to Structural Optimization, Springer 2009, ch. 1–2).

Closed form.  Bars from (±B, 0) to (0, −H) under the load P: N = P L/(2H), L = √(B² + H²); the
fully stressed area A = N/σ_a gives the mass ρ P (B² + H²)/(σ_a H), least at H* = B, with
A* = P/(√2 σ_a) and m* = 2ρPB/σ_a.  The case solves the static problem by one long Newmark step of
a load scaled by 1e-6 (its header says why that is linear statics to ~1e-7), so the optimizers can
meet the closed form to their own tolerance: measured SLSQP and IPOPT within 3e-7, MMA (nlopt, ftol
1e-8) within 7e-5 in H and 3.5e-5 in A — its steps shrink slowly along the flat valley of the mass
in H (the mass error is quadratic in the H error)."""
from __future__ import annotations

import math

import numpy as np
import pytest

import dynsens
from conftest import CASES
from helpers import assert_gradients_match_complex_step_and_adjoint, ipopt_missing

B, P, SIGMA, RHO = 1000.0, 1.0e5, 100.0, 7.85e-9
H_STAR, A_STAR, M_STAR = B, P / (math.sqrt(2) * SIGMA), 2 * RHO * P * B / SIGMA
CASE = CASES / "two_bar_shape.yaml"


def test_the_shape_gradients_match_the_complex_step_and_the_closed_form():
    """d(mass, stress ratio)/d(H, A) through the node coordinate: direct = complex step of the whole
    run (1e-10) = adjoint (1e-10), and both equal the closed forms at the start design."""
    case = dynsens.load_case(CASE)
    res = dynsens.run_case(case)
    assert_gradients_match_complex_step_and_adjoint(case, res, rtol_cs=1e-10, rtol_adjoint=1e-10)
    H, A = case.x0
    L = math.hypot(B, H)
    np.testing.assert_allclose(res.responses["mass"].gradient, [2 * RHO * A * H / L, 2 * RHO * L], rtol=1e-12)
    # ratio r = P L/(2 H A σ_a): dr/dH = r (H/L² − 1/H), dr/dA = −r/A; linear statics up to the
    # step's inertia (~1e-7), which dr/dH, a difference of two terms, shows at 1.4e-6 (measured)
    r = P * L / (2 * H * A * SIGMA)
    assert abs(res.responses["stress_ratio"].value / r - 1) < 1e-6
    np.testing.assert_allclose(res.responses["stress_ratio"].gradient, [r * (H / L ** 2 - 1 / H), -r / A], rtol=1e-5)


@pytest.mark.parametrize("method, ftol, rtol", [
    ("SLSQP", None, 1e-5),
    ("MMA", 1e-8, 2e-4),
    pytest.param("IPOPT", None, 1e-5,
                 marks=pytest.mark.skipif(ipopt_missing(), reason="cyipopt / Ipopt not installed")),
])
def test_each_method_reaches_the_two_bar_shape_optimum(method, ftol, rtol):
    """From H = 1800 mm, A = 1000 mm²: every method ends at H* = B, A* = P/(√2 σ_a) and m* = 2ρPB/σ_a,
    with the stress constraint active; SLSQP's optimum passes the verification (dt/2, longer window)."""
    sets = [f"optimization.method={method}"] + ([f"optimization.ftol={ftol}"] if ftol else [])
    res = dynsens.optimize(dynsens.load_case(CASE, sets), verify=method == "SLSQP")
    assert res.success and res.feasible, res.message
    np.testing.assert_allclose(res.x, [H_STAR, A_STAR], rtol=rtol)
    np.testing.assert_allclose(res.fun, M_STAR, rtol=rtol * rtol + 1e-6)
    if method == "SLSQP":
        assert res.verified
