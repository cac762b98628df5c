"""The light pendulum on a cart (cases/cart_pole.yaml) with adaptive steps, against an
independent reference: the same system in minimal coordinates (cart position x, pole angle θ
from hanging down), integrated by scipy's DOP853 at rtol 1e-12 and checked against Radau at
rtol 1e-11 (they agree to 1e-8).

    (M + m) ẍ + m a (θ̈ cos θ − θ̇² sin θ) + k x = 0
    m a ẍ cos θ + (I_c + m a²) θ̈ + m g a sin θ = 0,      a = l/2, I_c = m l²/12

Tolerances (measured, see the report in BENCHMARKS.md): at rtol 1e-8 the cart position within
1e-3 m and the pole's angular velocity within 0.5 rad/s over 5 s (three fast crossings of the
bottom, two slow turning points 0.12 rad from upright, where errors grow at 5.4/s); the error
falls with rtol (factor 3..8 per decade); the fixed grid of 1 ms gives 5e-6 m and 1e-3 rad/s.
Gradients against complex step of the whole adaptive run (the same accepted steps): 1e-8.
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import dynsens
from helpers import complex_step_gradients, rel_err

CASE = Path(__file__).resolve().parent.parent / "cases" / "cart_pole.yaml"
G = 9.81


def rhs(t, y, m=0.05, l=0.5, M=1.0, k=1.0):
    """Minimal-coordinate equations of motion, y = (x, θ, ẋ, θ̇)."""
    x, th, v, w = y
    a, ic = l / 2, m * l * l / 12
    A = np.array([[M + m, m * a * np.cos(th)], [m * a * np.cos(th), ic + m * a * a]])
    b = np.array([m * a * np.sin(th) * w * w - k * x, -m * G * a * np.sin(th)])
    return [v, w, *np.linalg.solve(A, b)]


@lru_cache(maxsize=1)
def reference():
    y0 = [0.0, 3.0, 0.1, 0.0]
    dop = solve_ivp(rhs, (0, 5), y0, method="DOP853", rtol=1e-12, atol=1e-13, dense_output=True)
    radau = solve_ivp(rhs, (0, 5), y0, method="Radau", rtol=1e-11, atol=1e-12, dense_output=True)
    return dop.sol, radau.sol


def errors(res):
    sol = reference()[0](res.time)
    return (np.max(np.abs(res.quantities["cart_x"].value - sol[0])),
            np.max(np.abs(res.quantities["pole_rate"].value - sol[3])))


def run(*overrides, sensitivities=False):
    return dynsens.run_case(dynsens.load_case(CASE, list(overrides)), sensitivities=sensitivities)


def test_reference_is_independent_of_its_integrator():
    dop, radau = reference()
    t = np.linspace(0, 5, 1001)
    assert np.max(np.abs(dop(t) - radau(t))) < 1e-8
    th = dop(t)[1]
    assert np.sum(np.diff(np.sign(th)) != 0) == 3             # three crossings of the bottom
    assert np.max(np.abs(th)) > 3.0 and np.max(np.abs(dop(t)[3])) > 10.0


def test_adaptive_steps_follow_the_crossings_and_the_error_falls_with_rtol():
    errs = []
    for rtol in (1e-6, 1e-7, 1e-8):
        res = run(f"integrator.adaptive.rtol={rtol}", f"integrator.adaptive.atol={rtol * 1e-3}")
        assert res.status == "completed" and res.time[-1] == pytest.approx(5.0, abs=1e-12)
        errs.append(errors(res))
    ex = [e[0] for e in errs]
    assert all(3.0 < ex[k] / ex[k + 1] < 8.0 for k in range(2)), ex
    assert errs[-1][0] < 1e-3 and errs[-1][1] < 0.5
    # small steps through the fast crossings of the bottom, long ones at the slow turning points
    th = reference()[0](res.time)[1]
    h = np.diff(res.time)
    crossing = h[np.abs(th[:-1]) < 0.3]
    turning = h[np.abs(th[:-1]) > 2.95]
    assert np.median(turning) > 3 * np.median(crossing)


def test_fixed_grid_of_the_same_case_against_the_reference():
    # the model itself: the grid of 1 ms (index-1 drift cancels on a uniform grid; on adaptive
    # steps it does not, which is what limits the adaptive runs above)
    ex, ew = errors(run("integrator.adaptive=null", "integrator.dt=1e-3"))
    assert ex < 5e-6 and ew < 1e-3


def test_gradients_against_complex_step_of_the_whole_adaptive_run():
    case = dynsens.load_case(CASE, ["integrator.t_end=2.0"])
    res = dynsens.run_case(case)
    cs = complex_step_gradients(case)
    for name, r in res.responses.items():
        assert rel_err(r.gradient, cs[name]) < 1e-8, name
