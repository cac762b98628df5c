"""The discrete adjoint equals the direct gradient to round-off (same discrete procedure, same
records, same partials) and the complex-step derivative of the whole run.

Tolerances: adjoint vs direct ≤ 1e-10 relative with complex partials (both exact to round-off;
observed ≤ 1e-12), ≤ 1e-7 with forward partials (the output partials are then taken by complex
step in the adjoint and by forward differences in the direct mode: their error, ~1e-8), except the
weir's fixed-time stroke, 8.4e-6 (test_weir_with_its_forward_partials);
against complex step of the whole run ≤ 1e-9 (the tolerance the direct mode is held to).
The weir's stroke is the one exception to 1e-10: its gradient (~1e-2 mm per unit) is the sum of
terms ~1e5 times larger (∂stroke/∂q ≈ 600 mm per unit of Euler parameter times ∇q), so any order
of summation carries ~1e5 ε; the direct mode itself is 2e-11 from the complex step of the whole
run there and the adjoint 2e-10 (measured; every other weir response agrees to 5e-14).
"""
from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import pytest

import dynsens
from conftest import CASES
from dynsens.errors import CaseError
from dynsens.responses.base import Response, ResponseValue
from helpers import complex_step_gradients, rel_err
from scripts_path import hard_step_case  # (puts scripts/ on the path)
from bench_peers import chain_case

# event-free variants of the cases with events (short runs for every scheme; the events have
# tests of their own below)
NO_EVENTS = {
    "hydraulic_lever": ["events=[]", "integrator.t_end=0.15", "responses=["
                        "{name: pivot_ks, type: ks, quantity: {joint: pivot, kind: reaction_force_norm}, rho: 0.01},"
                        "{name: p1_end, type: value, quantity: {element: cyl, kind: pressure_1}},"
                        "{name: stroke_int, type: integral, quantity: {element: cyl, kind: stroke}},"
                        "{name: angle_mid, type: value, quantity: {body: lever, kind: angle_z}, time: 0.0712}]"],
    "tyrolean_weir": ["events=[]", "integrator.t_end=0.4", "optimization=null", "responses=["
                      "{name: ks_force, type: ks, rho: 200.0, quantities: [{joint: Z, kind: reaction_force_norm},"
                      " {joint: A, kind: reaction_force_norm}, {joint: P, kind: reaction_force_norm}]},"
                      "{name: stroke, type: value, quantity: {element: cylinder, kind: stroke}},"
                      "{name: theta_0, type: value, quantity: {body: rack, kind: angle_z}, time: 0.0},"
                      "{name: f, type: expression, expression: 'ks_force + 0.01*stroke/theta_0'}]"],
    "pendulum_3d": ["events=[]", "integrator.t_end=0.3", "responses=["
                    "{name: pivot_force, type: ks, quantity: {joint: pivot, kind: reaction_force_norm}, rho: 50.0},"
                    "{name: x_end, type: value, quantity: {body: bob, kind: position}, component: bob.x}]"],
}
SHORT = {"duffing_chain": ["integrator.t_end=0.3"], "four_bar": ["integrator.t_end=0.3"],
         "slider_crank": ["integrator.t_end=0.3"], "sdof_step": ["integrator.t_end=0.5"],
         "truss_impact": [], "truss_lightweight": [], "pendulum_projection": ["integrator.t_end=1"],
         "n_four_bar": ["integrator.t_end=0.8"], "ten_bar_truss": [], **NO_EVENTS}
SCHEMES = {"newmark": [], "hht": ["integrator.scheme=hht", "integrator.alpha=0.1"],
           "generalized_alpha": ["integrator.scheme=generalized_alpha", "integrator.rho_inf=0.6"]}


def _with_method(case, method, **plan):
    c = copy.copy(case)
    c.plan = replace(case.plan, method=method, **plan)
    return c


def _both(name, extra=()):
    case = dynsens.load_case(CASES / f"{name}.yaml", [*SHORT[name], *extra])
    return (dynsens.run_case(_with_method(case, "direct")), dynsens.run_case(_with_method(case, "adjoint")),
            case)


def _compare(direct, adjoint, tol):
    assert adjoint.method == "adjoint" and direct.method == "direct"
    checked = 0
    for name, rv in direct.responses.items():
        ra = adjoint.responses[name]
        assert ra.value == pytest.approx(rv.value, rel=1e-12, abs=1e-300), name
        if rv.gradient is None:
            assert ra.gradient is None, name
            continue
        if np.linalg.norm(rv.gradient) == 0.0:
            assert np.all(ra.gradient == 0.0), name
            continue
        assert rel_err(ra.gradient, rv.gradient) <= tol, (name, rel_err(ra.gradient, rv.gradient))
        checked += 1
    assert checked


# every scheme is one Newmark class (integrators/newmark.py) whose code branches only on
# α_m = α_f = 0 (Newmark) or not: HHT (α_m = 0, α_f = α) takes the same paths as generalized-α
# (α_m, α_f ≠ 0, which also exercises the α_m terms HHT zeroes), so HHT is not repeated on every
# case; its adjoint stays checked through events (test_event_time_responses_with_the_dissipative_schemes)
@pytest.mark.parametrize("scheme", ["newmark", "generalized_alpha"])
@pytest.mark.parametrize("name", list(SHORT))
def test_adjoint_equals_direct_with_complex_partials(name, scheme):
    direct, adjoint, _ = _both(name, ["sensitivity.partials=complex", *SCHEMES[scheme]])
    _compare(direct, adjoint, 1e-9 if name == "tyrolean_weir" else 1e-10)
    assert adjoint.counters["backward_solves"] == adjoint.counters["steps"] + 1
    assert adjoint.counters["sensitivity_residual_evaluations"] == 0


@pytest.mark.parametrize("name", ["duffing_chain", "truss_impact", "slider_crank", "four_bar"])
def test_adjoint_equals_direct_with_forward_partials(name):
    """(Not the hydraulic lever's stroke integral: there the forward partials themselves are
    1.5e-4 from the complex step of the whole run, in both modes.)"""
    direct, adjoint, _ = _both(name, ["sensitivity.partials=forward"])
    _compare(direct, adjoint, 1e-7)


def test_adjoint_equals_direct_with_central_partials_and_converged_matrix():
    direct, adjoint, _ = _both("four_bar", ["sensitivity.partials=central", "sensitivity.matrix=converged"])
    _compare(direct, adjoint, 1e-9)


@pytest.mark.parametrize("name, extra", [
    ("sdof_step", ["integrator.t_end=0.2"]),
    ("slider_crank", ["integrator.t_end=0.1"]),                            # assembly, constraints
    ("hydraulic_lever", ["integrator.t_end=0.08"]),                        # hydraulic states
    ("duffing_chain", ["integrator.t_end=0.1", "integrator.scheme=generalized_alpha"]),
])
def test_adjoint_matches_complex_step_of_the_whole_run(name, extra):
    case = dynsens.load_case(CASES / f"{name}.yaml", [*SHORT[name], *extra, "sensitivity.partials=complex"])
    adjoint = dynsens.run_case(_with_method(case, "adjoint"))
    ref = complex_step_gradients(case)
    for r, rv in adjoint.responses.items():
        if rv.gradient is not None and np.linalg.norm(ref[r]) > 0:
            assert rel_err(rv.gradient, ref[r]) < 1e-9, r


def test_adjoint_through_step_cuts():
    """Sub-steps of cut steps are records of their own: the sweep goes through them."""
    case = hard_step_case(8)
    direct = dynsens.run_case(_with_method(case, "direct"))
    adjoint = dynsens.run_case(_with_method(case, "adjoint"))
    assert adjoint.counters["step_cuts"] > 0
    assert adjoint.counters["backward_solves"] > adjoint.counters["steps"] + 1
    _compare(direct, adjoint, 1e-10)
    assert rel_err(adjoint.responses["q_ks"].gradient, complex_step_gradients(case)["q_ks"]) < 1e-9


@pytest.mark.parametrize("name, budget", [("duffing_chain", 3e5), ("four_bar", 2e5)])
def test_checkpointing_recomputes_segments_bit_identically(name, budget):
    case = dynsens.load_case(CASES / f"{name}.yaml", SHORT[name])
    kept = dynsens.run_case(_with_method(case, "adjoint"))
    tight = dynsens.run_case(_with_method(case, "adjoint", memory_budget=budget))
    assert kept.counters["recomputed_steps"] == 0
    assert tight.counters["recomputed_steps"] > 0
    for r, rv in kept.responses.items():
        if rv.gradient is not None:
            assert np.array_equal(tight.responses[r].gradient, rv.gradient), r


def test_checkpointing_through_step_cuts_is_bit_identical():
    case = hard_step_case(8)
    kept = dynsens.run_case(_with_method(case, "adjoint"))
    tight = dynsens.run_case(_with_method(case, "adjoint", memory_budget=1.0))
    assert tight.counters["recomputed_steps"] > 0 and kept.counters["step_cuts"] > 0
    assert np.array_equal(tight.responses["q_ks"].gradient, kept.responses["q_ks"].gradient)


@pytest.mark.parametrize("location", ["interpolate", "step"])
@pytest.mark.parametrize("name", ["hydraulic_lever", "pendulum_3d"])
def test_event_time_responses_in_both_location_modes(name, location):
    """Event times, values at the event (total and fixed-time), KS and integrals up to it."""
    case = dynsens.load_case(CASES / f"{name}.yaml", ["sensitivity.partials=complex",
                                                       f"integrator.event_location={location}"])
    direct = dynsens.run_case(_with_method(case, "direct"))
    adjoint = dynsens.run_case(_with_method(case, "adjoint"))
    assert adjoint.status == "terminated"
    _compare(direct, adjoint, 1e-10)


def test_event_instant_weights_against_complex_step():
    """Integral up to an event (the end of its last interval moves) and the end time, against the
    complex step of the whole run (interpolate mode: the exact derivative of the procedure)."""
    case = dynsens.load_case(CASES / "hydraulic_lever.yaml", [
        "sensitivity.partials=complex", "responses=["
        "{name: t_end, type: end_time},"
        "{name: stroke_int, type: integral, quantity: {element: cyl, kind: stroke}},"
        "{name: p1_fixed, type: value, quantity: {element: cyl, kind: pressure_1}, event: lifted,"
        " derivative: fixed_time}]"])
    adjoint = dynsens.run_case(_with_method(case, "adjoint"))
    ref = complex_step_gradients(case)
    for r in ("t_end", "stroke_int"):
        assert rel_err(adjoint.responses[r].gradient, ref[r]) < 1e-8, r
    direct = dynsens.run_case(_with_method(case, "direct"))
    _compare(direct, adjoint, 1e-10)


@pytest.mark.slow
def test_weir_with_both_methods():
    """The whole weir (both events, the cleaning-time constraint g3, fixed-time stroke)."""
    case = dynsens.load_case(CASES / "tyrolean_weir.yaml", ["sensitivity.partials=complex"])
    direct = dynsens.run_case(_with_method(case, "direct"))
    adjoint = dynsens.run_case(_with_method(case, "adjoint"))
    assert adjoint.status == "terminated"
    _compare(direct, adjoint, 1e-10)


@pytest.mark.slow
def test_weir_with_its_forward_partials():
    """The weir as shipped (forward partials): every gradient within 1e-7, except the fixed-time
    stroke (and g2_fixed_time, made from it), whose direct and adjoint values differ by the forward
    partials' own error, 8.4e-6 measured: the adjoint takes the output partials by complex step, the
    direct mode by forward differences, and this gradient is ~1e5 times smaller than the terms it
    sums (docs/weir.md).  The README's claim is this test's."""
    case = dynsens.load_case(CASES / "tyrolean_weir.yaml")
    assert case.plan.partials == "forward"
    direct = dynsens.run_case(_with_method(case, "direct"))
    adjoint = dynsens.run_case(_with_method(case, "adjoint"))
    fixed_time = {"stroke_fixed_time", "g2_fixed_time"}
    errors = {n: rel_err(adjoint.responses[n].gradient, r.gradient) for n, r in direct.responses.items()
              if r.gradient is not None and np.linalg.norm(r.gradient) > 0}
    assert set(errors) >= fixed_time | {"f", "g1", "g3", "stroke"}
    assert all(e <= 1e-7 for n, e in errors.items() if n not in fixed_time), errors
    assert all(e <= 2e-5 for n, e in errors.items() if n in fixed_time), errors


def test_auto_falls_back_to_direct_for_a_response_it_cannot_seed():
    class Peak(Response):
        def __init__(self):
            self.name, self.output_ids = "peak", (0,)

        def finish(self, ctx):
            return ResponseValue(0.0, None)

    case = dynsens.load_case(CASES / "duffing_chain.yaml", [
        "integrator.t_end=0.01", "sensitivity.method=auto",
        "responses=[{name: tip_end, type: value, quantity: {dof: u20, kind: displacement}}]"])
    base = case.new_response_set

    def with_peak(record: bool = True):
        rs = base(record=record)
        rs.responses.append(Peak())
        return rs
    case.new_response_set = with_peak
    res = dynsens.run_case(case)
    assert res.method == "direct" and "response 'peak': response type Peak has no adjoint seeds" \
        in res.method_reason
    with pytest.raises(CaseError, match="sensitivity.method: adjoint does not cover this case yet"):
        dynsens.run_case(_with_method(case, "adjoint"))


def test_a_response_type_without_adjoint_hooks_is_refused():
    class Peak(Response):
        def __init__(self):
            self.name, self.output_ids = "peak", (0,)

        def finish(self, ctx):
            return ResponseValue(0.0, None)

    case = dynsens.load_case(CASES / "sdof_step.yaml", ["integrator.t_end=0.05"])
    rs = case.new_response_set()
    rs.responses.append(Peak())
    assert rs.adjoint_unsupported() == ["response 'peak': response type Peak has no adjoint seeds"]


def test_auto_picks_by_the_count_of_functions_and_design_variables():
    case = dynsens.load_case(CASES / "duffing_chain.yaml", ["integrator.t_end=0.05", "sensitivity.method=auto"])
    res = dynsens.run_case(case)
    assert res.method == "direct" and "4 functions against 4 design variables" in res.method_reason
    one = dynsens.load_case(CASES / "duffing_chain.yaml", [
        "integrator.t_end=0.05", "sensitivity.method=auto",
        "responses=[{name: tip_end, type: value, quantity: {dof: u20, kind: displacement}}]"])
    res = dynsens.run_case(one)
    assert res.method == "direct" and "1 functions against 4 design variables (m < 4(r + 1))" in res.method_reason
    per_element = dynsens.load_case_dict(chain_case(10, 0.05, True), overrides=[
        "sensitivity.method=auto",
        "responses=[{name: tip_end, type: value, quantity: {dof: u10, kind: displacement}}]"])
    res = dynsens.run_case(per_element)
    assert res.method == "adjoint" and "1 functions against 10 design variables (m >= 4(r + 1))" in res.method_reason


def test_case_keys_are_validated():
    with pytest.raises(CaseError, match=r"sensitivity.memory_budget: expected a positive size"):
        dynsens.load_case(CASES / "sdof_step.yaml", ["sensitivity.memory_budget=-3"])
    with pytest.raises(CaseError, match=r"sensitivity.method: expected one of direct, adjoint, auto"):
        dynsens.load_case(CASES / "sdof_step.yaml", ["sensitivity.method=backward"])
    assert dynsens.load_case(CASES / "sdof_step.yaml", ["sensitivity.memory_budget=1.5 GiB"]).plan.memory_budget \
        == 1.5 * 2**30


def test_optimize_a_per_element_chain_with_the_adjoint(tmp_path):
    """``dynsens optimize`` on the chain with one stiffness per element (m = 8 > 4(r + 1) for
    r = 1: ``auto`` picks the adjoint): tip KS minimized under a total-stiffness budget."""
    import yaml
    from click.testing import CliRunner

    import dynsens.cli.optimize  # noqa: F401  (registers the command)
    from dynsens.cli.main import cli
    n = 8
    d = chain_case(n, 0.3, True)
    d["sensitivity"] = {"method": "auto", "partials": "complex"}
    d["responses"] = [
        {"name": "tip_ks", "type": "ks", "quantity": {"dof": f"u{n}", "kind": "displacement"}, "rho": 200.0},
        {"name": "stiffness", "type": "expression", "expression": " + ".join(f"k_{i + 1}" for i in range(n))}]
    k0 = d["design"]["variables"][0]["value"]
    d["optimization"] = {"objective": "tip_ks", "constraints": [{"response": "stiffness", "upper": n * k0}],
                         "maxiter": 30}
    path = tmp_path / "chain.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    assert dynsens.run_case(dynsens.load_case(path)).method == "adjoint"
    out = CliRunner().invoke(cli, ["optimize", str(path), "-o", str(tmp_path / "opt.h5")])
    assert out.exit_code == 0, out.output
    assert "converged" in out.output and "feasible" in out.output


def test_check_gradients_uses_the_adjoint(tmp_path):
    """``dynsens check-gradients`` with ``--set sensitivity.method=adjoint``: the adjoint gradient
    against complex step of the whole run."""
    import dynsens.cli.check_gradients  # noqa: F401  (registers the command)
    from click.testing import CliRunner

    from dynsens.cli.main import cli
    out = CliRunner().invoke(cli, ["check-gradients", str(CASES / "slider_crank.yaml"), "--scheme", "complex",
                                   "--steps", "1e-20", "--rtol", "1e-9", "--workers", "1",
                                   "--set", "integrator.t_end=0.1", "--set", "sensitivity.partials=complex",
                                   "--set", "sensitivity.method=adjoint"])
    assert out.exit_code == 0, out.output


def test_adjoint_with_sensitivity_history_is_refused():
    """The adjoint computes no sensitivity states: asking for their history is one clear error
    (``auto`` runs the direct mode instead)."""
    with pytest.raises(CaseError, match=r"sensitivity.method: .*output.sensitivity_history"):
        dynsens.load_case(CASES / "sdof_step.yaml", ["sensitivity.method=adjoint", "output.sensitivity_history=true"])
    one = dynsens.load_case_dict(chain_case(10, 0.02, True), overrides=[
        "sensitivity.method=auto", "output.sensitivity_history=true",
        "responses=[{name: tip_end, type: value, quantity: {dof: u10, kind: displacement}}]"])
    res = dynsens.run_case(one)
    assert res.method == "direct" and res.sensitivity_history["q"].shape[-1] == 10


@pytest.mark.parametrize("scheme", ["hht", "generalized_alpha"])
def test_event_time_responses_with_the_dissipative_schemes(scheme):
    case = dynsens.load_case(CASES / "hydraulic_lever.yaml", ["sensitivity.partials=complex", *SCHEMES[scheme]])
    direct = dynsens.run_case(_with_method(case, "direct"))
    adjoint = dynsens.run_case(_with_method(case, "adjoint"))
    assert adjoint.status == "terminated"
    _compare(direct, adjoint, 1e-10)


# mechanisms with redundant joints (Bricard), drivers given as expressions (rheonomic), rotational
# spring-dampers (torsional pair), point masses with distance joints (point pendulum) and adaptive
# steps (cart pole): whole runs, their events included; the two longest (no events) over the first
# part of their runs.  The cart pole over 1.6 s: the slow start near upright (long steps), the fast
# crossing of the bottom at 0.73 s (short and rejected steps) and the slow turning point at
# 1.34-1.57 s, i.e. every step size the controller takes; adjoint against direct is an identity
# of the discrete procedure, step by step, so the second crossing (2.18 s) added no code path
# (912 accepted steps instead of 1606 to 2.5 s)
MECHANISMS = ["bricard", "rheonomic", "torsional_pair", "point_pendulum", "cart_pole", "mechanism_members"]
HORIZON = {"torsional_pair": ["integrator.t_end=0.5"], "cart_pole": ["integrator.t_end=1.6"]}


@pytest.mark.parametrize("name", MECHANISMS)
def test_adjoint_equals_direct_on_the_newer_mechanisms(name):
    case = dynsens.load_case(CASES / f"{name}.yaml", ["sensitivity.partials=complex", *HORIZON.get(name, [])])
    _compare(dynsens.run_case(_with_method(case, "direct")), dynsens.run_case(_with_method(case, "adjoint")),
             1e-10)


def test_every_shipped_case_has_an_adjoint_test():
    shipped = {p.stem for p in CASES.glob("*.yaml")}
    # ground_structure(_two_loads): tests/test_ground_structure.py checks its adjoint against central
    # differences (each load case of the two-load one);
    # tyrolean_weir_flexible: adjoint against direct in tests/test_weir_flexible.py;
    # truss_two_loads: tests/test_load_cases.py checks adjoint = direct in each of its load cases;
    # two_bar_shape, crank_circle: tests/test_shape_optimum.py, tests/test_crank_circle.py
    # (adjoint = direct = complex step); spin_up_beam: tests/test_spin_up_beam.py
    covered = set(SHORT) | set(MECHANISMS) | {"tower_sizing", "tower_sizing_mma", "ground_structure",
                                              "ground_structure_two_loads",
                                              "tyrolean_weir_flexible", "truss_two_loads", "two_bar_shape",
                                              "crank_circle", "spin_up_beam"}
    assert shipped <= covered, sorted(shipped - covered)


@pytest.mark.parametrize("name", ["tower_sizing", "tower_sizing_mma"])
def test_adjoint_equals_direct_on_the_tower_with_204_member_areas(name):
    # the sizing aggregates (KS of stress and buckling ratios per level, sampled maxima with the
    # gradient of their active sample; the MMA variant: one KS over all 204 members) over 204
    # per-member design variables
    case = dynsens.load_case(CASES / f"{name}.yaml", ["integrator.t_end=0.04", "sensitivity.partials=complex"])
    direct, adjoint = (dynsens.run_case(_with_method(case, mode)) for mode in ("direct", "adjoint"))
    assert case.x0.size == 204
    _compare(direct, adjoint, 1e-10)
