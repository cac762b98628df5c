"""3D pendulum (cases/pendulum_3d.yaml): closed-form period, energy, drift, sensitivities.

Closed form (compound pendulum released horizontally, I_pivot = I + m L²):
T = 4 sqrt(I_pivot / (m g L)) K(sin²(π/4)), K the complete elliptic integral of the first kind.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.special import ellipk

import dynsens
from conftest import CASES
from helpers import complex_step_gradients, rel_err

CASE = CASES / "pendulum_3d.yaml"
G, I_BOB = 9.81, 1.0e-6


def t_exact(L=1.0, m=1.0):
    return 4.0 * np.sqrt((I_BOB + m * L * L) / (m * G * L)) * ellipk(0.5)


def _period(dt, extra=()):
    case = dynsens.load_case(CASE, overrides=[f"integrator.dt={dt}", *extra])
    res = dynsens.run_case(case, sensitivities=False, history=("q", "qd"))
    return res, float(res.responses["period"].value)


def test_period_matches_closed_form_and_converges():
    """Newmark (β=¼, γ=½) period error: < 2e-7 at dt = 0.02 s, and it falls by > 8x per halving."""
    errs = [abs(_period(dt)[1] / t_exact() - 1.0) for dt in (0.02, 0.01)]
    assert errs[0] < 2e-7, errs
    assert errs[1] < errs[0] / 8.0, errs


def test_energy_bounded_and_drift_small():
    res, T = _period(1e-3)
    assert abs(T / t_exact() - 1.0) < 1e-9
    q, qd = res.history["q"], res.history["qd"]
    # E = ½ m v² + ½ I ω² + m g y  (ω = 2 E(p) ṗ; isotropic I)
    e, ed = q[:, 3:7], qd[:, 3:7]
    w = 2.0 * np.stack([-e[:, 1] * ed[:, 0] + e[:, 0] * ed[:, 1] - e[:, 3] * ed[:, 2] + e[:, 2] * ed[:, 3],
                        -e[:, 2] * ed[:, 0] + e[:, 3] * ed[:, 1] + e[:, 0] * ed[:, 2] - e[:, 1] * ed[:, 3],
                        -e[:, 3] * ed[:, 0] - e[:, 2] * ed[:, 1] + e[:, 1] * ed[:, 2] + e[:, 0] * ed[:, 3]], 1)
    E = 0.5 * np.sum(qd[:, :3] ** 2, 1) + 0.5 * I_BOB * np.sum(w ** 2, 1) + G * q[:, 1]
    assert np.max(np.abs(E - E[0])) < 1e-4 * G            # bounded: < 1e-4 of m g L
    assert abs(q[-1, 0] + 1.0) < 1e-8 and abs(q[-1, 2]) < 1e-12   # far side, in the plane
    assert res.monitors["constraint_position"].max() < 5e-6      # m, with L = 1 m
    assert res.monitors["constraint_velocity"].max() < 1e-5


def test_baumgarte_reduces_drift():
    res0, _ = _period(2e-3)
    res1, _ = _period(2e-3, ["model.stabilization={alpha: 10.0, beta: 10.0}"])
    d0 = res0.monitors["constraint_position"].max()
    d1 = res1.monitors["constraint_position"].max()
    assert d1 < 0.5 * d0, (d0, d1)


@pytest.mark.parametrize("partials", ["complex", "forward"])
def test_sensitivities_match_complex_step_of_whole_run(partials):
    """Event time, value at the event (interpolated) and KS against complex step of the
    whole simulation; 1e-9 relative with complex partials, 1e-6 with forward differences."""
    case = dynsens.load_case(CASE, overrides=["integrator.dt=5e-3", f"sensitivity.partials={partials}"])
    res = dynsens.run_case(case)
    cs = complex_step_gradients(case)
    tol = 1e-9 if partials == "complex" else 1e-6
    for name in ("half_period", "period", "pivot_force"):
        assert rel_err(res.responses[name].gradient, cs[name]) < tol, name
    # x_far: d/dL = −1, d/dm ≈ 0 (absolute check: the m-component is round-off)
    g = res.responses["x_far"].gradient
    assert abs(g[0] - cs["x_far"][0]) < tol and abs(g[1] - cs["x_far"][1]) < 1e-9
    # closed form: dT/dL = T/(2L) for the point-mass limit
    assert abs(res.responses["period"].gradient[0] / (t_exact() / 2.0) - 1.0) < 1e-5
