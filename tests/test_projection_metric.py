"""The projection in the metric of the mass matrix (``model.projection.metric: mass``,
dynsens/models/multibody/projection_metric.py) on the light cart pole: cases/cart_pole.yaml with
a 1e-6 kg cart and no spring (scripts/projection_metric_report.py), whose horizontal momentum
P = M ẋ_cart + m ẋ_pole is a constant of the motion.

* The mass-weighted projection moves no momentum between the cart and the pole: P stays to
  round-off (measured 7e-17 kg m/s over 10 s at rtol 1e-8; the Euclidean projection drifts by
  2e-6, BENCHMARKS.md).  θ(10) against the minimal-coordinate reference (DOP853 at rtol 1e-12)
  at rtol 1e-8: measured 2.8e-3 rad (Euclidean 3.4e-3).  The test runs the first 5 s: θ(5)
  measured 7.7e-4 rad, bound 1.4e-3.  The 1e-3 of issue 38 (at
  10 s) is not reached at rtol 1e-8: the remaining error is the time integration's, not the projection's.
* Its derivative: direct and adjoint gradients of a short run (mode state, the projection fed
  back) against complex step of the whole run (1e-8), and direct against adjoint (1e-11).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import dynsens
import scripts_path  # noqa: F401  (puts scripts/ on the path)
from helpers import complex_step_gradients, rel_err
from projection_metric_report import CASE, measure, overrides, reference_theta


# the first 5 s of the report's 10 s (8626 of 16077 accepted steps, three crossings of the
# bottom): the projection keeps P at every step, so its drift is a per-step property (measured
# 5.1e-17 by 5 s, 6.4e-17 by 10 s; bound 1e-12 as before); θ's error is the integration's phase
# error, which grows with time (measured 7.7e-4 rad at 5 s, 2.8e-3 at 10 s): its bound is
# tightened in proportion, 5e-3 at 10 s -> 1.4e-3 at 5 s (the same margin, 1.8)
SHORTER = "integrator.t_end=5.0"


def test_mass_metric_keeps_the_momentum_and_theta_of_the_light_cart_pole():
    res = dynsens.run_case(dynsens.load_case(CASE, [*overrides("mass", 1e-8), SHORTER]), sensitivities=False)
    assert res.status == "completed" and res.time[-1] == pytest.approx(5.0, abs=1e-12)
    m = measure(res, reference_theta(5.0))
    assert m["drift"] < 1e-12, m
    assert m["theta_error"] < 1.4e-3, m


def test_mass_metric_moves_the_light_cart_less_than_the_euclidean_projection():
    """One projection of the same drifted state: in the mass metric the momentum is kept."""
    from dynsens.models.multibody.projection import project
    out = {}
    for metric in ("euclidean", "mass"):
        case = dynsens.load_case(CASE, overrides(metric, 1e-8))
        model = case.model
        params = model.parameters(case.x0)
        q, qd, _ = model.initial_state(params)
        from dynsens.models.base import StepState
        z = np.zeros(0)
        s = StepState(q + 1e-4 * np.sin(np.arange(q.size)), qd + 1e-3 * np.cos(np.arange(q.size)),
                      np.zeros_like(q), z, z, z)
        _, proj = project(model, model.projection, 0.0, s, params)
        P = lambda st: 1e-6 * st.qd[0] + 0.05 * st.qd[7]        # noqa: E731
        out[metric] = abs(P(proj.projected) - P(s))
    assert out["mass"] < 1e-15 and out["euclidean"] > 1e-6, out


SHORT = ["integrator.adaptive=null", "integrator.dt=2e-3", "integrator.t_end=0.1",
         "model.projection.mode=state", "model.projection.metric=mass",
         "design.variables[2].lower=1e-7", "design.variables[2].value=1e-3"]


@pytest.fixture(scope="module")
def short_gradients():
    case = dynsens.load_case(CASE, SHORT)
    grads = {}
    for method in ("direct", "adjoint"):
        c = dynsens.load_case(CASE, SHORT)
        c.plan = replace(c.plan, method=method)
        res = dynsens.run_case(c)
        assert res.method == method
        grads[method] = {k: r.gradient for k, r in res.responses.items()}
    return grads, complex_step_gradients(case)


def test_mass_metric_gradients_against_complex_step(short_gradients):
    grads, cs = short_gradients
    for method in ("direct", "adjoint"):
        for name, ref in cs.items():
            assert rel_err(grads[method][name], ref) < 1e-8, (method, name, grads[method][name], ref)


def test_mass_metric_direct_equals_adjoint(short_gradients):
    grads, _ = short_gradients
    for name, g in grads["direct"].items():
        assert rel_err(grads["adjoint"][name], g) < 1e-11, name
