"""The light pendulum on a cart (cases/cart_pole.yaml) with adaptive steps, against an
independent reference: the same system in minimal coordinates (scripts/adaptive_report.py:
cart position x, pole angle θ from hanging down) integrated by scipy's DOP853 at rtol 1e-12 and
checked here against Radau at rtol 1e-11 (they agree to 1e-8).

The case continues from the state projected onto the joints (model.projection, mode state).
Tolerances (measured, see BENCHMARKS.md): at rtol 1e-8 the cart position within 2e-5 m and the
pole's angular velocity within 5e-3 rad/s over 5 s (three fast crossings of the bottom, two slow
turning points 0.12 rad from upright, where errors grow at 5.4/s); the error falls with rtol
(factor 3..8 per decade); the plain index-1 form on the fixed grid of 1 ms gives 5e-6 m and
1e-3 rad/s.  Gradients against complex step of the whole adaptive run (which takes the same
accepted steps): 1e-8.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

import dynsens
import scripts_path  # noqa: F401  (puts scripts/ on the path)
from adaptive_report import CASE, errors, reference
from helpers import complex_step_gradients, rel_err


@lru_cache(maxsize=1)
def references():
    return reference(5.0), reference(5.0, "Radau", 1e-11)


def run(*overrides, sensitivities=False):
    return dynsens.run_case(dynsens.load_case(CASE, list(overrides)), sensitivities=sensitivities)


def test_reference_is_independent_of_its_integrator():
    dop, radau = references()
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
        errs.append(errors(res, references()[0]))
    ex = [e[0] for e in errs]
    assert all(3.0 < ex[k] / ex[k + 1] < 8.0 for k in range(2)), ex
    assert errs[-1][0] < 2e-5 and errs[-1][1] < 5e-3
    # small steps through the fast crossings of the bottom, long ones at the slow turning points
    th = references()[0](res.time)[1]
    h = np.diff(res.time)
    crossing = h[np.abs(th[:-1]) < 0.3]
    turning = h[np.abs(th[:-1]) > 2.95]
    assert np.median(turning) > 3 * np.median(crossing)


def test_fixed_grid_of_the_same_case_against_the_reference():
    # the model itself: the grid of 1 ms (index-1 drift cancels on a uniform grid; on adaptive
    # steps it does not, which is what limits the adaptive runs above)
    ex, ew = errors(run("integrator.adaptive=null", "integrator.dt=1e-3", "model.projection.enabled=false"),
                    references()[0])
    assert ex < 5e-6 and ew < 1e-3


def test_gradients_against_complex_step_of_the_whole_adaptive_run():
    # 1.6 s: the slow start near upright, the fast crossing of the bottom (0.73 s, short and
    # rejected steps) and the slow turning point (1.34-1.57 s), every step size the controller
    # takes; the 0.4 s more to 2.0 s were the next fall, the same regime again (912 accepted
    # steps instead of 1113 per run, five runs)
    case = dynsens.load_case(CASE, ["integrator.t_end=1.6"])
    res = dynsens.run_case(case)
    cs = complex_step_gradients(case)
    for name, r in res.responses.items():
        assert rel_err(r.gradient, cs[name]) < 1e-8, name
