"""SLSQP, MMA and IPOPT on the closed-form optimum of a damped single-degree-of-freedom system.

SDOF damping optimum.  A mass m on a spring k and a viscous damper c, at rest, under a suddenly
applied constant force F.  For ζ = c/(2√(km)) < 1 the displacement
u(t) = u_st[1 − e^(−ζωt)(cos ω_D t + ζ/√(1−ζ²) sin ω_D t)], u_st = F/k, peaks at t = π/ω_D with
u_max/u_st = 1 + exp(−ζπ/√(1−ζ²))  (Chopra, *Dynamics of Structures*, 4th ed., §4.3 "Step force",
Eq. 4.3.2 and Fig. 4.3.2).  Minimizing c subject to u_max ≤ a·u_st (1 < a < 2) therefore puts
the constraint on its bound: ζ* = −ln(a−1)/√(π² + ln²(a−1)), c* = 2ζ*√(km).

Time discretization: with m = 1, k = 100 (ω = 10 rad/s) and dt = 1e-3, ω·dt = 0.01.  Newmark's
average acceleration elongates the period by (ω·dt)²/12 ≈ 8e-6 and the sampled peak lies within
(ω·dt)²/8 ≈ 1.3e-5 of the continuous one, so c* is met to about that (measured: 1.3e-5 for each
method);
the test asks rtol 1e-3 — a wrong optimum (for example the undamped-peak answer or a constraint
off its bound) fails it.
"""
from __future__ import annotations

import copy
import math

import numpy as np
import pytest

import dynsens
from helpers import ipopt_missing

M, K, F, A = 1.0, 100.0, 10.0, 1.2
ZETA_STAR = -math.log(A - 1) / math.sqrt(math.pi ** 2 + math.log(A - 1) ** 2)
C_STAR = 2 * ZETA_STAR * math.sqrt(K * M)

SDOF = {
    "name": "sdof_damping_optimum",
    "design": {"variables": [{"name": "c", "value": 15.0, "lower": 1.0, "upper": 19.0}]},
    "model": {"type": "structural", "dofs": ["u"],
              "elements": [{"type": "mass", "name": "m", "dof": "u", "mass": M},
                           {"type": "spring", "name": "k", "dofs": ["u", "ground"], "k": K},
                           {"type": "damper", "name": "d", "dofs": ["u", "ground"], "c": "c"}],
              "loads": [{"dof": "u", "value": F, "function": "constant"}]},
    "integrator": {"scheme": "newmark", "beta": 0.25, "gamma": 0.5, "dt": 1.0e-3, "t_end": 1.0},
    "sensitivity": {"enabled": True, "partials": "forward"},
    "responses": [{"name": "u_max", "type": "max", "quantity": {"dof": "u", "kind": "displacement"}},
                  {"name": "cost", "type": "expression", "expression": "c"}],
    "optimization": {"objective": "cost", "constraints": [{"response": "u_max", "upper": A * F / K}],
                     "maxiter": 100, "ftol": 1e-10},
}


def _methods() -> list:
    ipopt = pytest.param("IPOPT", marks=pytest.mark.skipif(ipopt_missing(), reason="cyipopt / Ipopt not installed"))
    return ["SLSQP", "MMA", ipopt]


def sdof(method: str) -> dict:
    raw = copy.deepcopy(SDOF)
    raw["optimization"]["method"] = method
    return raw


def test_the_sdof_gradient_matches_central_differences() -> None:
    rep = dynsens.check_gradients(sdof("SLSQP"), [1e-5], "central", workers=1)
    assert rep.passes(1e-5), rep


@pytest.mark.parametrize("method", _methods())
def test_each_method_reaches_the_sdof_damping_optimum(method: str) -> None:
    res = dynsens.optimize(sdof(method), verify=False)
    assert res.success and res.feasible, res.message
    np.testing.assert_allclose(res.x, [C_STAR], rtol=1e-3)
    assert res.history["x"].shape[0] == res.nit + 1
