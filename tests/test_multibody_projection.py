"""Projection of each step's end state onto the constraint manifolds (``model.projection``).

The IFToMM benchmark's simple pendulum (cases/pendulum_projection.yaml, the same mechanism as
cases/point_pendulum.yaml: a 1 kg point mass on a massless 1 m rod, g = 9.81 m/s², released at
rest with the rod horizontal) over 10 s against an independent reference — the angle's equation
θ̈ = −(g/L) sin θ integrated by DOP853 at rtol 1e-13 — and the sensitivities of projected runs
against complex step of the whole run, direct against adjoint.
"""
from __future__ import annotations

import copy
import warnings
from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import dynsens
from conftest import CASES
from dynsens.errors import CaseError
from helpers import complex_step_gradients, rel_err

G, L = 9.81, 1.0
LONG = CASES / "pendulum_projection.yaml"
POSITION = ["responses=[{name: x_end, type: value, quantity: {body: bob, kind: position}, component: bob.x}]"]


def reference_positions(t: np.ndarray) -> np.ndarray:
    """(x, y) (len(t), 2) of the bob from the angle from the downward vertical, θ(0) = π/2."""
    sol = solve_ivp(lambda _, y: [y[1], -G / L * np.sin(y[0])], (0.0, t[-1]), [np.pi / 2, 0.0],
                    method="DOP853", rtol=1e-13, atol=1e-14, t_eval=t)
    return np.stack([L * np.sin(sol.y[0]), -L * np.cos(sol.y[0])], axis=1)


def _long_run(stabilization: list[str]):
    case = dynsens.load_case(LONG, ["model.projection.enabled=false", *POSITION, *stabilization])
    res = dynsens.run_case(case, sensitivities=False, history=("q",))
    err = np.linalg.norm(res.history["q"][:, :2] - reference_positions(res.time), axis=1)
    return res, err


def _with_method(case, method, **plan):
    c = copy.copy(case)
    c.plan = replace(case.plan, method=method, **plan)
    return c


def test_pendulum_over_10_s_constraints_at_round_off_and_the_phase_kept():
    """Δt = 5 ms, 10 s (about 5 periods).  Measured: without stabilization the position error is
    1.2e-4 m (the radial drift: ‖Φ‖ = 1.2e-4 m); Baumgarte α = β = 1e3 /s holds ‖Φ‖ at 3e-7 but
    the error grows to 3.0e-3 m (25×: the phase); the projection (mode output) holds ‖Φ‖, ‖Φ̇‖ at
    2e-16 and the error is 5e-8 m; mode state also holds them but its error is 2.3e-3 m (the
    projected steps lose the index-1 form's phase accuracy: Newmark's O(Δt²) phase error)."""
    plain, e_plain = _long_run([])
    strong, e_strong = _long_run(["model.stabilization={alpha: 1000.0, beta: 1000.0}"])
    out, e_out = _long_run(["model.projection={mode: output}"])
    state, e_state = _long_run(["model.projection={mode: state}"])
    assert plain.time[-1] == pytest.approx(10.0) and out.time.size == plain.time.size == 2001
    for res in (out, state):
        assert res.monitors["constraint_position"].max() <= 1e-10
        assert res.monitors["constraint_velocity"].max() <= 1e-10
    # the solved (index-1) state drifts as without projection in mode output, per step in mode state
    assert out.monitors["constraint_position_solved"].max() == pytest.approx(
        plain.monitors["constraint_position"].max(), rel=1e-12)
    assert state.monitors["constraint_position_solved"].max() < 1e-5
    assert 5e-5 < plain.monitors["constraint_position"].max() < 5e-4
    assert strong.monitors["constraint_position"].max() < 1e-6
    # errors against the reference
    assert e_out.max() <= e_plain.max()                  # no worse than without stabilization ...
    assert e_out.max() < 1e-3 * e_plain.max()            # ... far better: the drift was the error
    assert e_out.max() < 1e-4 * e_strong.max()           # much better than strong Baumgarte
    assert e_strong.max() > 10.0 * e_plain.max()         # (strong Baumgarte loses the phase)
    assert e_state.max() < e_strong.max()


def test_projection_switched_off_changes_nothing():
    """``enabled: false`` is the plain index-1 run, bit for bit (and its monitors)."""
    base = ["integrator.t_end=1.5", "integrator.dt=5e-3"]
    a = dynsens.run_case(dynsens.load_case(CASES / "point_pendulum.yaml", base))
    b = dynsens.run_case(dynsens.load_case(CASES / "point_pendulum.yaml", [*base, "model.projection={enabled: false}"]))
    assert set(a.monitors) == set(b.monitors) == {"constraint_position", "constraint_velocity"}
    for name, rv in a.responses.items():
        assert b.responses[name].value == rv.value
        assert np.array_equal(b.responses[name].gradient, rv.gradient)


@pytest.mark.parametrize("mode", ["output", "state"])
def test_pendulum_sensitivities_against_complex_step_direct_and_adjoint(mode):
    """The half period (event time, interpolated), the position at the far side and the KS of
    the rod force with projection on: direct against complex step of the whole run (1e-10),
    adjoint against direct (1e-12)."""
    case = dynsens.load_case(CASES / "point_pendulum.yaml",
                             ["integrator.dt=5e-3", f"model.projection={{mode: {mode}}}"])
    direct = dynsens.run_case(_with_method(case, "direct"))
    adjoint = dynsens.run_case(_with_method(case, "adjoint"))
    cs = complex_step_gradients(case)
    assert direct.monitors["constraint_position"].max() <= 1e-10
    for name in ("half_period", "x_far", "rod_force"):
        g = direct.responses[name].gradient
        assert rel_err(g, cs[name]) < 1e-10, (name, rel_err(g, cs[name]))
        assert rel_err(adjoint.responses[name].gradient, g) < 1e-12, name
    # the far side with projection is at |x| = L to round-off (the index-1 run: 3e-9 off)
    assert abs(direct.responses["x_far"].value + 1.0) < 1e-8
    assert direct.responses["x_far"].gradient[0] == pytest.approx(-1.0, abs=1e-7)


def test_long_pendulum_gradients_against_complex_step():
    """The shipped case over 2 s (400 steps, mode output): direct against complex step of the whole
    run (1e-10), adjoint against direct (1e-12)."""
    case = dynsens.load_case(LONG, ["integrator.t_end=2"])
    direct = dynsens.run_case(_with_method(case, "direct"))
    adjoint = dynsens.run_case(_with_method(case, "adjoint"))
    cs = complex_step_gradients(case)
    for name, rv in direct.responses.items():
        assert rel_err(rv.gradient, cs[name]) < 1e-10, (name, rel_err(rv.gradient, cs[name]))
        assert rel_err(adjoint.responses[name].gradient, rv.gradient) < 1e-12, name


@pytest.mark.parametrize("mode", ["output", "state"])
def test_sensitivity_constraint_residual_at_round_off_with_projection(mode):
    """J_Φ ∇q_j + ∂Φ/∂x_j and d/dx_j Φ̇ per step (/monitors sensitivity_constraint_*): with projection
    at round-off of their scale max_j ‖J_Φ ∇q_j‖; without, they drift like the state."""
    sets = ["integrator.t_end=1", "output.sensitivity_history=true", "output.history=[q,qd,qdd]"]
    plain = dynsens.run_case(dynsens.load_case(LONG, [*sets, "model.projection.enabled=false"]))
    proj = dynsens.run_case(dynsens.load_case(LONG, [*sets, f"model.projection.mode={mode}"]))
    scale = proj.monitors["sensitivity_constraint_scale"].max()
    assert scale > 0.1
    assert proj.monitors["sensitivity_constraint_position"].max() <= 1e-12 * scale
    assert proj.monitors["sensitivity_constraint_velocity"].max() <= 1e-12 * scale
    assert plain.monitors["sensitivity_constraint_position"].max() > 1e-6 * scale


@pytest.mark.parametrize("name, mode, t_end", [("four_bar", "state", 0.3), ("four_bar", "output", 0.3),
                                                ("slider_crank", "state", 0.1)])
def test_closed_loop_mechanism_with_projection_against_complex_step(name, mode, t_end):
    """A closed loop of rigid bodies (Euler parameters: the normalisations are projected too)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        case = dynsens.load_case(CASES / f"{name}.yaml", [f"integrator.t_end={t_end}", "sensitivity.partials=complex",
                                                         f"model.projection={{mode: {mode}}}"])
        direct = dynsens.run_case(_with_method(case, "direct"))
        adjoint = dynsens.run_case(_with_method(case, "adjoint"))
        cs = complex_step_gradients(case)
    assert direct.monitors["constraint_position"].max() <= 1e-12
    assert direct.monitors["constraint_velocity"].max() <= 1e-11
    checked = 0
    for r, rv in direct.responses.items():
        if rv.gradient is None or np.linalg.norm(cs[r]) == 0:
            continue
        assert rel_err(rv.gradient, cs[r]) < 1e-10, (r, rel_err(rv.gradient, cs[r]))
        assert rel_err(adjoint.responses[r].gradient, rv.gradient) < 1e-12, r
        checked += 1
    assert checked >= 3


def test_forward_partials_with_projection_close_to_complex_step():
    """The projection's design partials follow the run's partials method: forward differences
    give the gradient to their own accuracy."""
    case = dynsens.load_case(CASES / "four_bar.yaml", ["integrator.t_end=0.15", "sensitivity.partials=forward",
                                                      "model.projection={mode: state}"])
    res = dynsens.run_case(case)
    cs = complex_step_gradients(case)
    for r, rv in res.responses.items():
        assert rel_err(rv.gradient, cs[r]) < 1e-6, r


def test_adjoint_checkpoints_recompute_projected_steps_bit_identically():
    case = dynsens.load_case(CASES / "four_bar.yaml", ["integrator.t_end=0.15", "model.projection={mode: state}"])
    kept = dynsens.run_case(_with_method(case, "adjoint"))
    tight = dynsens.run_case(_with_method(case, "adjoint", memory_budget=1e5))
    assert kept.counters["recomputed_steps"] == 0 < tight.counters["recomputed_steps"]
    for r, rv in kept.responses.items():
        assert np.array_equal(tight.responses[r].gradient, rv.gradient), r


@pytest.mark.parametrize("setting, message", [
    ("model.projection={tol: -1}", r"model\.projection\.tol: expected a number in \(0, 1e-3\)"),
    ("model.projection={mode: always}", r"model\.projection\.mode: expected state or output, found 'always'"),
    ("model.projection={max_iterations: 1}", r"model\.projection\.max_iterations: expected an integer >= 2"),
    ("model.projection={enabled: yes please}", r"model\.projection\.enabled: expected true or false"),
    ("model.projection={tolerance: 1e-12}", r"model\.projection.*tolerance"),
    ("model.projection=true", r"model\.projection: expected a mapping"),
])
def test_projection_settings_are_checked(setting, message):
    with pytest.raises(CaseError, match=message):
        dynsens.load_case(CASES / "point_pendulum.yaml", [setting])


def test_projection_that_cannot_converge_stops_with_a_message():
    """One iteration of headroom is not enough for a step's drift at a tight tolerance: a
    ModelError naming the setting, never a run marked completed."""
    from dynsens.errors import ModelError
    case = dynsens.load_case(CASES / "point_pendulum.yaml", ["model.projection={max_iterations: 2, tol: 1.0e-16}",
                                                             "integrator.dt=0.05"])
    with pytest.raises(ModelError, match=r"projection onto the position constraints did not converge at t = .*"
                                         r"model\.projection\.tol"):
        dynsens.run_case(case, sensitivities=False)
