"""SLSQP, MMA and IPOPT on closed-form optima: the SDOF damping optimum and the tuned mass damper.

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

Tuned mass damper, H2 optimum.  An undamped primary (m₁, k₁) carries an absorber (m₂ = μm₁, k₂,
c₂).  For a white-noise force on the primary the variance of the primary displacement is least at
the tuning ratio f = ω₂/ω₁ = √(1+μ/2)/(1+μ) and the absorber damping ratio
ζ = c₂/(2m₂ω₂) = √(μ(1+3μ/4)/(4(1+μ)(1+μ/2)))  (G. B. Warburton, "Optimum absorber parameters
for various combinations of response and excitation parameters", Earthquake Eng. Struct. Dyn. 10
(1982) 381–401, the white-noise force / main-mass displacement case).  By Parseval the variance
under white noise is proportional to ∫₀^∞ x₁(t)² dt after a unit impulse on the primary (initial
velocity), so minimizing that integral over k₂ and c₂ reaches the same optimum.  With μ = 0.05,
ω₁ = 1 rad/s, dt = 0.1 s (ω·dt = 0.1) and a window of 120 s (the response has decayed; the
integral's truncation and Newmark's period error are each below 1e-4 in f and ζ) the optimizers
reach f and ζ to 3.4e-5 and 8e-6 (measured; at dt = 0.05 s, 200 s: 7e-6 and 1.5e-5, which
confirms the formulas independently of the discretization).  The test asks rtol 1e-3: Den Hartog's
H∞ tuning (f = 1/(1+μ), 1.3 % off) or a wrong damping fails it.
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


def with_method(case: dict, method: str) -> dict:
    """A copy of ``case`` optimized by ``method``."""
    raw = copy.deepcopy(case)
    raw["optimization"]["method"] = method
    return raw


def sdof(method: str) -> dict:
    return with_method(SDOF, method)


def test_the_sdof_gradient_matches_central_differences() -> None:
    rep = dynsens.check_gradients(sdof("SLSQP"), [1e-5], "central", workers=1)
    assert rep.passes(1e-5), rep


@pytest.mark.parametrize("method", _methods())
def test_each_method_reaches_the_sdof_damping_optimum(method: str) -> None:
    res = dynsens.optimize(sdof(method), verify=False)
    assert res.success and res.feasible, res.message
    np.testing.assert_allclose(res.x, [C_STAR], rtol=1e-3)
    assert res.history["x"].shape[0] == res.nit + 1


MU = 0.05
F_OPT = math.sqrt(1 + MU / 2) / (1 + MU)
ZETA_OPT = math.sqrt(MU * (1 + 3 * MU / 4) / (4 * (1 + MU) * (1 + MU / 2)))

TMD = {
    "name": "tuned_mass_damper_h2",
    "design": {"variables": [{"name": "k2", "value": 0.06, "lower": 0.02, "upper": 0.1},
                             {"name": "c2", "value": 0.02, "lower": 0.001, "upper": 0.05}]},
    "model": {"type": "structural", "dofs": ["u1", "u2"],
              "elements": [{"type": "mass", "name": "m1", "dof": "u1", "mass": 1.0},
                           {"type": "mass", "name": "m2", "dof": "u2", "mass": MU},
                           {"type": "spring", "name": "s1", "dofs": ["u1", "ground"], "k": 1.0},
                           {"type": "spring", "name": "s2", "dofs": ["u2", "u1"], "k": "k2"},
                           {"type": "damper", "name": "d2", "dofs": ["u2", "u1"], "c": "c2"}],
              "initial": {"velocity": {"u1": 1.0}}},
    "integrator": {"scheme": "newmark", "beta": 0.25, "gamma": 0.5, "dt": 0.1, "t_end": 120.0},
    "sensitivity": {"enabled": True, "partials": "forward"},
    "responses": [{"name": "x1_squared", "type": "integral", "expression": "x * x",
                   "symbols": {"x": {"quantity": {"dof": "u1", "kind": "displacement"}}}}],
    "optimization": {"objective": "x1_squared", "maxiter": 200, "ftol": 1e-12},
}


def tmd(method: str) -> dict:
    return with_method(TMD, method)


def test_the_tmd_gradient_matches_central_differences() -> None:
    rep = dynsens.check_gradients(tmd("SLSQP"), [1e-5], "central", workers=1)
    assert rep.passes(1e-5), rep


@pytest.mark.parametrize("method", _methods())
def test_each_method_reaches_the_h2_optimal_tuned_mass_damper(method: str) -> None:
    res = dynsens.optimize(tmd(method), verify=False)
    assert res.success and res.feasible, res.message
    k2, c2 = res.x
    f = math.sqrt(k2 / MU)                    # ω₂/ω₁ with ω₁ = 1 rad/s
    np.testing.assert_allclose([f, c2 / (2 * MU * f)], [F_OPT, ZETA_OPT], rtol=1e-3)
    assert res.history["x"].shape[0] == res.nit + 1
