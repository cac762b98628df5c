"""Run-time faults named in the case's words (README "Reliability"):

* a non-finite sensitivity stops the run at the step where it appears (direct and adjoint),
  naming the step, the time and the design variable or response, whether or not sensitivity
  histories are stored;
* run-time NaN/Inf messages name the YAML entries acting on the equation (elements and loads
  of a structural model, joints and forces of a multibody model);
* a run that grows without bound while staying finite is stopped by the runaway monitor,
  naming the scheme's stability limit when that is the cause.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from test_reliability import make, simulate_refused

from dynsens.case.load import load_case, load_case_text
from dynsens.errors import NonFiniteError
from dynsens.simulation import run_case
from dynsens.timeloop.runaway import RUNAWAY_FACTOR

CASES = Path(__file__).resolve().parents[1] / "cases"


@pytest.fixture(autouse=True)
def _quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        yield


def _case(mutate=None, name: str = "rt.yaml"):
    return load_case_text(yaml.safe_dump(make(mutate)), name)


def _nan_design_derivative_after(case, t_bad: float) -> None:
    """The model's residual at perturbed designs turns NaN from t_bad on: a design derivative
    that stops being finite mid-run (the primal residual is untouched)."""
    model = case.model
    inner = model.residual_batch_steps

    def batch(ts, states, params_list):
        F = np.array(inner(ts, states, params_list), dtype=float)
        F[np.asarray(ts) >= t_bad] = np.nan
        return F
    model.residual_batch_steps = batch        # instance attribute: this case only


def _no_event(r: dict) -> None:
    del r["events"]


# ---------------------------------------------------------------- 2. non-finite sensitivities


@pytest.mark.parametrize("stored, t_bad, where", [
    (False, 0.1 - 1e-9, "step 20 (t = 0.1 s)"),       # dt = 5 ms: mid-run, inside a trail block
    (True, 0.1 - 1e-9, "step 20 (t = 0.1 s)"),
    (False, -1.0, "step 0 (t = 0 s)"),                  # at the initial solve
])
def test_direct_mode_names_the_first_non_finite_sensitivity_step(stored, t_bad, where):
    case = _case(lambda r: (_no_event(r), r.__setitem__("output", {"sensitivity_history": stored})))
    _nan_design_derivative_after(case, t_bad)
    with pytest.raises(NonFiniteError) as info:
        run_case(case)
    msg = str(info.value)
    assert where in msg and "with respect to 'm'" in msg, msg
    assert "DOF 'u'" in msg and "failed, not completed" in msg, msg
    if t_bad > 0:
        assert "design derivative of the residual is not finite at this step" in msg, msg


def test_direct_mode_passes_finite_sensitivities_of_every_shipped_structural_case():
    # the block check reads one sum per block: a real run is untouched (same gradient)
    case = _case(_no_event)
    g = run_case(case).responses["q_end"].gradient
    assert np.all(np.isfinite(g)) and np.any(g != 0)


def test_adjoint_names_the_step_and_the_response():
    case = _case(lambda r: (_no_event(r), r["responses"].pop(),
                            r["sensitivity"].__setitem__("method", "adjoint")))
    assert run_case(case).method == "adjoint"
    _nan_design_derivative_after(case, 0.1 - 1e-9)
    with pytest.raises(NonFiniteError) as info:
        run_case(case)
    msg = str(info.value)
    assert "adjoint of response 'q_end' went non-finite at step 20 (t = 0.1 s)" in msg, msg
    assert "design derivative of the residual" in msg and "failed, not completed" in msg, msg


def test_adjoint_multipliers_non_finite_at_a_step(monkeypatch):
    from dynsens.derivatives import output_seeds
    case = _case(lambda r: (_no_event(r), r["responses"].pop(),
                            r["sensitivity"].__setitem__("method", "adjoint")))
    inner = output_seeds.OutputSeeds.seeds_block

    def seeds(self, ts, states, weights, r):
        out = inner(self, ts, states, weights, r)
        return [(np.full_like(y, np.nan), x) for y, x in out]
    monkeypatch.setattr(output_seeds.OutputSeeds, "seeds_block", seeds)
    with pytest.raises(NonFiniteError) as info:
        run_case(case)
    msg = str(info.value)
    # q_end reads the last instant only: the sweep's first step is the last one (40)
    assert "adjoint of response 'q_end' went non-finite at step 40 (t = 0.2 s)" in msg, msg


# ---------------------------------------------------------------- 3. messages name the YAML entry


def test_nan_in_the_residual_names_the_element_and_its_key_path():
    # the residual turns NaN at t >= 0.1 s (as an element law outside its range would): the
    # run stops naming the DOF and the YAML entries acting there, not an equation index
    raw = make(_no_event)
    raw["model"]["dofs"] = ["u", "w"]
    raw["model"]["elements"] += [{"type": "mass", "name": "mw", "dof": "w", "mass": 1.0},
                                 {"type": "spring", "name": "k_w", "dofs": ["w", "ground"], "k": 3.0}]
    case = load_case_text(yaml.safe_dump(raw), "nan.yaml")
    model = case.model
    inner = model.residual

    def residual(t, s, params):
        R = np.array(inner(t, s, params))
        if t >= 0.1 - 1e-9:
            R[1] = np.nan
        return R
    model.residual = residual
    with pytest.raises(NonFiniteError) as info:
        run_case(case, sensitivities=False)
    msg = str(info.value)
    assert "t = 0.1 s (step 20)" in msg, msg
    assert "DOF 'w' (acted on by model.elements[3] (mass 'mw'), model.elements[4] (spring 'k_w'))" in msg, msg
    assert "spring 'spring'" not in msg, msg


def test_structural_equations_name_only_the_entries_acting_there():
    raw = make(_no_event)
    raw["model"]["dofs"] = ["u", "w"]
    raw["model"]["elements"] += [{"type": "mass", "name": "mw", "dof": "w", "mass": 1.0},
                                 {"type": "spring", "name": "k_uw", "dofs": ["u", "w"], "k": 3.0}]
    model = load_case_text(yaml.safe_dump(raw), "two.yaml").model
    w = model.describe_equation(1)
    assert w == "DOF 'w' (acted on by model.elements[3] (mass 'mw'), model.elements[4] (spring 'k_uw'))", w
    assert "spring 'spring'" in model.describe_equation(0)


def test_multibody_equations_name_joints_bodies_and_forces():
    model = load_case(CASES / "hydraulic_lever.yaml").model
    n_q = model.traits.n_q
    body = model.describe_equation(3)
    assert "body 'lever' (model.bodies.lever)" in body and "model.forces[0] (point_force 'load')" in body, body
    joint = model.describe_equation(n_q)
    assert joint.startswith("constraint ") and "model.joints[0] (revolute " in joint, joint


def test_nan_in_a_constraint_equation_names_the_joint_entry():
    case = load_case(CASES / "point_pendulum.yaml")
    model = case.model
    n_q = model.traits.n_q
    row = next(k for k, o in enumerate(model.eq_owner) if o.startswith("rod."))   # the YAML joint 'rod'
    inner = model.residual

    def residual(t, s, params):
        R = np.array(inner(t, s, params))
        if t >= 0.01 - 1e-12:
            R[n_q + row] = np.nan
        return R
    model.residual = residual
    # the NaN is injected into the Python residual: the step iterates in Python (the compiled
    # step's message is the same, tests/test_compiled_step.py)
    model.compiled_step = lambda newton, refactor: None
    with pytest.raises(NonFiniteError) as info:
        run_case(case, sensitivities=False)
    msg = str(info.value)
    assert "(step 10)" in msg and "'rod')" in msg, msg
    assert f"constraint {model.eq_owner[row]} of model.joints[0] (" in msg, msg
    lock = model.describe_equation(n_q)      # the point mass's orientation lock: its body entry
    assert "body 'bob' (model.bodies.bob)" in lock, lock


# ---------------------------------------------------------------- 1. the runaway monitor


def _runaway_message(case, x=None) -> str:
    with pytest.raises(NonFiniteError) as info:
        run_case(case, x)
    return str(info.value)


def test_runaway_growth_is_stopped_long_before_overflow_and_names_the_limit():
    # central differences past their limit (0.4 s at x0): growth ×~3 per step, overflow would
    # come after ~600 steps; the monitor stops it at RUNAWAY_FACTOR times the early scale
    # (a dt past the limit at x0 is refused when the case is loaded; the optimizer asks for a
    # design past it: k = 200 gives a limit of 0.2 s)
    case = _case(lambda r: (_no_event(r), r["integrator"].update(beta=0.0, dt=0.35, t_end=500.0)))
    msg = _runaway_message(case, np.array([2.0, 0.0, 200.0]))
    assert "grows without bound" in msg and "DOF 'u'" in msg and "model.elements[1] (spring 'spring')" in msg, msg
    assert "stability limit" in msg and "= 0.2 s" in msg and "found 0.35 s" in msg, msg
    step = int(msg.split("(step ")[1].split(")")[0])
    assert step < 50, msg               # growth ×~16 per step: overflow to Inf only after ~250 steps


def test_runaway_growth_of_a_physical_instability_is_stopped_without_blaming_the_scheme():
    # a negative spring: exp growth, unconditionally stable scheme: no stability-limit claim
    case = _case(lambda r: (_no_event(r), r["model"]["elements"][1].__setitem__("k", "-k"),
                            r["integrator"].update(t_end=10.0)))
    msg = _runaway_message(case)
    assert "grows without bound" in msg and "stability limit" not in msg, msg
    assert f"{RUNAWAY_FACTOR:.0e}" in msg, msg


@pytest.mark.parametrize("function", [
    {"type": "ramp", "t1": 20.0},                               # q ~ t³ from rest
    {"type": "pulse", "t0": 15.0, "duration": 0.05},            # at rest, then a short kick
    {"type": "smoothstep", "t0": 10.0, "t1": 10.5},             # at rest, then ~ (t - t0)^4
], ids=["ramp", "late_pulse", "late_smoothstep"])
@pytest.mark.parametrize("model_scale", [True, False], ids=["with_model_scale", "window_alone"])
def test_growth_from_rest_is_not_a_runaway(function, model_scale, monkeypatch):
    # undamped, stiff against the load: responses grow from exact zeros (or from ~1e-31 where
    # the load switches on between grid points) by powers of t, orders of magnitude within a
    # few steps, which is not growth without bound; also without the model's own scale
    if not model_scale:
        from dynsens.models.structural.model import StructuralModel
        monkeypatch.setattr(StructuralModel, "displacement_scale", lambda self, params, lin: 0.0)
    def mutate(r):
        _no_event(r)
        r["model"]["loads"][0]["function"] = function
        r["model"]["elements"].pop(2)
        r["integrator"].update(t_end=30.0, dt=5e-3)
        r["responses"].pop()
    case = _case(mutate)
    res = run_case(case, sensitivities=False)
    q = res.history["q"][:, 0]
    assert res.status == "completed" and np.max(np.abs(q)) > 1e6 * np.min(np.abs(q[q != 0])), res.message


@pytest.mark.parametrize("name", sorted(p.stem for p in CASES.glob("*.yaml")))
def test_runaway_monitor_never_trips_on_a_shipped_case_start(name):
    # the first 0.05 s of each shipped case (the whole suite runs the rest of them in full)
    from dataclasses import replace

    from dynsens.case.load_cases import LoadCaseSet, load_any_case
    loaded = load_any_case(CASES / f"{name}.yaml")
    for case in loaded.cases.values() if isinstance(loaded, LoadCaseSet) else [loaded]:   # every load case
        plan = case.plan
        case.plan = replace(plan, t_end=min(plan.t_end, plan.t0 + 40 * plan.dt))
        res = run_case(case, sensitivities=False)
        assert res.status in ("completed", "terminated")


def test_a_conditionally_stable_scheme_without_a_computed_limit_is_named_for_growth_only():
    # a mechanism (constraints): no plain stability limit; a runaway still names the scheme
    from dynsens.timeloop.runchecks import unstable_scheme_note
    raw = yaml.safe_load((CASES / "point_pendulum.yaml").read_text())
    raw["integrator"]["beta"] = 0.0
    case = load_case_text(yaml.safe_dump(raw), "pp.yaml")
    x = np.real(case.x0)
    note = unstable_scheme_note(case.model, case.scheme, case.plan, x, growth=True)
    assert note is not None and "beta = 0 < gamma/2 = 0.25 is only conditionally stable" in note, note
    assert unstable_scheme_note(case.model, case.scheme, case.plan, x, growth=False) is None
    stable = load_case(CASES / "point_pendulum.yaml")
    assert unstable_scheme_note(stable.model, stable.scheme, stable.plan, x, growth=True) is None


def test_simulate_of_a_runaway_exits_2_and_writes_nothing(tmp_path):
    raw = make(lambda r: (_no_event(r), r["model"]["elements"][1].__setitem__("k", "-k"),
                          r["integrator"].update(t_end=10.0)))
    simulate_refused(CliRunner(), tmp_path, raw, "grows without bound", "DOF 'u'",
                     "model.elements[1] (spring 'spring')")
