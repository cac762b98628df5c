"""Bad input is reported as ONE CaseError listing every problem with its YAML path.

Contract (issue): unknown keys (with did-you-mean), wrong types, out-of-range values,
swapped bounds, expressions naming unknown symbols, responses naming missing DOFs or
elements, missing files: one error listing every problem with its YAML path.  NaN or
Inf in the state stops the run with a message that says where it first appeared.
"""
from __future__ import annotations

import copy
import re
import warnings

import numpy as np
import pytest
import yaml

import dynsens
from dynsens import CaseError, load_case
from dynsens.case.load import load_case_dict, load_case_text
from dynsens.errors import DynsensError, NonFiniteError
from dynsens.simulation import run_case

# A small two-DOF case with distinctive names (so that a name found in a message cannot
# be there by accident): base -- spring_a -- ground, tip -- spring_b -- base.
BASE: dict = {
    "name": "two_dof",
    "design": {"variables": [
        {"name": "mass_b", "value": 2.0, "lower": 0.5, "upper": 10.0},
        {"name": "stiff", "value": 50.0, "lower": 10.0, "upper": 200.0},
    ]},
    "model": {
        "type": "structural",
        "dofs": ["base", "tip"],
        "elements": [
            {"type": "mass", "name": "body_a", "dof": "base", "mass": 1.0},
            {"type": "mass", "name": "body_b", "dof": "tip", "mass": "mass_b"},
            {"type": "spring", "name": "spring_a", "dofs": ["base", "ground"], "k": 80.0},
            {"type": "spring", "name": "spring_b", "dofs": ["tip", "base"], "k": "stiff"},
            {"type": "damper", "name": "damper_b", "dofs": ["tip", "base"], "c": 0.5},
        ],
        "loads": [{"dof": "tip", "value": 10.0, "function": {"type": "ramp", "t0": 0.0, "t1": 0.1}}],
    },
    "integrator": {"scheme": "newmark", "beta": 0.25, "gamma": 0.5, "dt": 1.0e-3, "t_end": 0.2},
    "sensitivity": {"enabled": True, "partials": "forward"},
    "responses": [
        {"name": "tip_end", "type": "value", "quantity": {"dof": "tip", "kind": "displacement"}},
        {"name": "force_ks", "type": "ks", "quantity": {"element": "spring_b", "kind": "force"},
         "rho": 50.0},
        {"name": "combo", "type": "expression", "expression": "tip_end + 0.1*stiff"},
    ],
}


def make(mutate=None) -> dict:
    """A deep copy of BASE, changed in place by ``mutate(raw)``."""
    raw = copy.deepcopy(BASE)
    if mutate is not None:
        mutate(raw)
    return raw


def as_text(raw: dict) -> str:
    return yaml.safe_dump(raw, sort_keys=False)


def case_error(mutate=None, overrides=()) -> CaseError:
    """Load the mutated case from YAML text; it must fail with a CaseError."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(CaseError) as info:
            load_case_text(as_text(make(mutate)), "bad.yaml", list(overrides))
    return info.value


def problem_for(err: CaseError, path: str) -> list[str]:
    """Messages of the problems reported at exactly ``path``."""
    return [p.message for p in err.problems if p.path == path]


def assert_problem(err: CaseError, path: str, *fragments: str) -> str:
    """The error names ``path`` and one problem at ``path`` contains every fragment."""
    text = str(err)
    assert path in text, f"YAML path {path!r} missing from:\n{text}"
    msgs = problem_for(err, path)
    assert msgs, f"no problem reported at {path!r}; problems: {[str(p) for p in err.problems]}"
    for m in msgs:
        if all(f.lower() in m.lower() for f in fragments):
            return m
    pytest.fail(f"no problem at {path!r} contains {fragments}; got {msgs}")


# ---------------------------------------------------------------------------- sanity
def test_base_case_is_valid_and_runs():
    case = load_case_text(as_text(make()), "ok.yaml")
    assert case.design_names == ("mass_b", "stiff")
    assert case.response_names == ("tip_end", "force_ks", "combo")
    res = run_case(case)
    assert res.status == "completed"
    assert np.isfinite(res.responses["tip_end"].value)


def test_case_error_is_a_value_error_and_a_dynsens_error():
    err = case_error(lambda r: r["integrator"].update(dt=-1.0))
    assert isinstance(err, ValueError) and isinstance(err, DynsensError)
    assert err.source == "bad.yaml"
    assert str(err).startswith("invalid case bad.yaml (1 problem):")


# ---------------------------------------------------------------------------- unknown keys
@pytest.mark.parametrize("mutate, path, suggestion", [
    (lambda r: r.__setitem__("integratr", r.pop("integrator")), "integratr", "integrator"),
    (lambda r: r["integrator"].__setitem__("tend", 1.0), "integrator.tend", "t_end"),
    (lambda r: r["design"]["variables"][1].__setitem__("uper", 3.0), "design.variables[1].uper", "upper"),
    (lambda r: r["model"]["elements"][3].__setitem__("k4", 1.0), "model.elements[3].k4", "k"),
    (lambda r: r["model"]["elements"][4].__setitem__("dof", "tip"), "model.elements[4].dof", "dofs"),
    (lambda r: r["model"]["loads"][0]["function"].__setitem__("t_1", 1.0),
     "model.loads[0].function.t_1", "t1"),
    (lambda r: r["responses"][1].__setitem__("rhoo", 5.0), "responses[1].rhoo", "rho"),
    (lambda r: r["sensitivity"].__setitem__("enable", False), "sensitivity.enable", "enabled"),
    (lambda r: r.__setitem__("output", {"histroy": ["q"]}), "output.histroy", "history"),
], ids=["top", "integrator", "design", "spring", "damper", "timefunction", "response", "sensitivity",
        "output"])
def test_unknown_key_names_path_and_did_you_mean(mutate, path, suggestion):
    err = case_error(mutate)
    assert_problem(err, path, "unknown key", f"did you mean '{suggestion}'")


@pytest.mark.parametrize("mutate, path, suggestion", [
    (lambda r: r["model"]["elements"][2].__setitem__("type", "sprin"), "model.elements[2].type", "spring"),
    (lambda r: r["model"].__setitem__("type", "structral"), "model.type", "structural"),
    (lambda r: r["responses"][1].__setitem__("type", "kss"), "responses[1].type", "ks"),
    (lambda r: r["model"]["loads"][0]["function"].__setitem__("type", "rmp"),
     "model.loads[0].function.type", "ramp"),
    (lambda r: r["sensitivity"].__setitem__("partials", "forwrd"), "sensitivity.partials", "forward"),
    (lambda r: r["responses"][0]["quantity"].__setitem__("kind", "displacment"),
     "responses[0].quantity.kind", "displacement"),
], ids=["element_type", "model_type", "response_type", "function_type", "partials", "kind"])
def test_unknown_names_have_did_you_mean(mutate, path, suggestion):
    err = case_error(mutate)
    assert_problem(err, path, f"did you mean '{suggestion}'")


def test_unknown_integration_scheme_is_reported_at_its_own_path():
    # The problem is the value of integrator.scheme; the error must point there.
    err = case_error(lambda r: r["integrator"].__setitem__("scheme", "newmrk"))
    assert "newmrk" in str(err)
    assert "integrator.scheme" in str(err), str(err)


# ---------------------------------------------------------------------------- wrong types
@pytest.mark.parametrize("mutate, path, fragment", [
    (lambda r: r["integrator"].__setitem__("dt", "fast"), "integrator.dt", "fast"),
    (lambda r: r["model"].__setitem__("dofs", "base"), "model.dofs", "list"),
    (lambda r: r["model"]["elements"][0].__setitem__("mass", True), "model.elements[0].mass", "True"),
    (lambda r: r["model"]["elements"][2].__setitem__("k", [80.0]), "model.elements[2].k", "[80.0]"),
    (lambda r: r["sensitivity"].__setitem__("enabled", "yes please"), "sensitivity.enabled", "yes please"),
    (lambda r: r["integrator"].__setitem__("solver", {"max_iterations": 2.5}),
     "integrator.solver.max_iterations", "2.5"),
    (lambda r: r["responses"][1].__setitem__("rho", "lots"), "responses[1].rho", "lots"),
    (lambda r: r["model"].__setitem__("elements", {"type": "mass"}), "model.elements", "list"),
    (lambda r: r.__setitem__("responses", {"name": "x"}), "responses", "list"),
    (lambda r: r["responses"][0].__setitem__("unit", {"a": 1}), "responses[0].unit", "{'a': 1}"),
    (lambda r: r["responses"][1].__setitem__("unit", -1), "responses[1].unit", "-1"),
    (lambda r: r["integrator"].__setitem__("solver", {"max_iterations": True}),
     "integrator.solver.max_iterations", "True"),
], ids=["dt_str", "dofs_str", "mass_bool", "k_list", "enabled_str", "max_iter_float", "rho_str",
        "elements_map", "responses_map", "unit_map", "unit_number", "max_iter_bool"])
def test_wrong_type_names_path(mutate, path, fragment):
    err = case_error(mutate)
    assert_problem(err, path, "expected", fragment)


@pytest.mark.parametrize("value, shown", [([1e-3], "[0.001]"), ({"a": 1}, "{'a': 1}"), (True, "True")],
                         ids=["list", "mapping", "bool"])
def test_wrong_type_message_says_what_was_found(value, shown):
    # "expected a number, found nothing" is wrong when something (a list, a mapping, a
    # boolean) *was* found: the message must show the offending value.
    err = case_error(lambda r: r["integrator"].__setitem__("dt", value))
    msg = assert_problem(err, "integrator.dt", "expected")
    assert "nothing" not in msg, msg
    assert shown in msg, msg


# ---------------------------------------------------------------------------- out of range
@pytest.mark.parametrize("mutate, path, fragment", [
    (lambda r: r["integrator"].__setitem__("dt", -1e-3), "integrator.dt", "positive"),
    (lambda r: r["integrator"].__setitem__("dt", float("inf")), "integrator.dt", "finite"),
    (lambda r: r["integrator"].__setitem__("t_end", -1.0), "integrator.t_end", "greater than t0"),
    (lambda r: r["model"]["elements"][0].__setitem__("mass", -1.0), "model.elements[0].mass", "> 0"),
    (lambda r: r["model"]["elements"][4].__setitem__("c", -0.5), "model.elements[4].c", ">= 0"),
    (lambda r: r["design"]["variables"][0].__setitem__("value", 20.0), "design.variables[0].value",
     "outside the bounds"),
    (lambda r: r["design"]["variables"][0].__setitem__("scale", 0.0), "design.variables[0].scale", "positive"),
    (lambda r: r["responses"][1].__setitem__("rho", -3.0), "responses[1].rho", "positive"),
    (lambda r: r["model"]["loads"][0]["function"].__setitem__("t1", -1.0), "model.loads[0].function.t1",
     "greater than t0"),
    # like rtol, atol is a tolerance: non-negative and finite
    (lambda r: r["integrator"].__setitem__("solver", {"atol": -1e-8}), "integrator.solver.atol",
     "expected a non-negative finite number, found -1e-08"),
    (lambda r: r["integrator"].__setitem__("solver", {"atol": float("nan")}), "integrator.solver.atol",
     "expected a non-negative finite number, found nan"),
    (lambda r: r.__setitem__("optimization", {"objective": "combo", "ftol": float("nan")}), "optimization.ftol",
     "expected a positive finite number, found nan"),
    (lambda r: r.__setitem__("optimization", {"objective": "combo", "constraints": [
        {"response": "tip_end", "upper": float("nan")}]}), "optimization.constraints[0].upper",
     "expected a finite number, found nan"),
], ids=["dt_neg", "dt_inf", "t_end", "mass", "damper", "design_value", "scale", "rho", "ramp_t1",
        "atol_neg", "atol_nan", "ftol_nan", "bound_nan"])
def test_out_of_range_value_names_path(mutate, path, fragment):
    err = case_error(mutate)
    assert_problem(err, path, fragment)


def test_gamma_below_half_names_the_entry():
    err = case_error(lambda r: r["integrator"].__setitem__("gamma", 0.3))
    assert "integrator.gamma" in str(err)
    assert "0.5" in str(err)


def test_response_time_before_start_is_out_of_range():
    # A value response at t = -1 s (before t0 = 0) can never be sampled: it is an
    # out-of-range value and must be reported at load time with its YAML path, not as a
    # "missing" response after the whole run ("the run ended before t = -1.0 s").
    err = case_error(lambda r: r["responses"][0].__setitem__("time", -1.0))
    assert_problem(err, "responses[0].time")


# ---------------------------------------------------------------------------- swapped bounds
def test_swapped_bounds_are_reported_with_hint():
    def swap(r):
        v = r["design"]["variables"][1]
        v["lower"], v["upper"] = v["upper"], v["lower"]
    err = case_error(swap)
    assert_problem(err, "design.variables[1]", "swap")


def test_bounds_whose_span_overflows_are_refused():
    # ±1e308 are finite, but upper - lower overflows to inf: the scaled design, the samples of
    # a study and the KKT measure came out inf or nan (a crash, or nan designs and exit 0)
    def huge(r):
        r["design"]["variables"][0].update(lower=-1e308, upper=1e308)
    err = case_error(huge)
    msg = assert_problem(err, "design.variables[0]", "bounds whose difference is a finite number")
    assert "-1e+308" in msg and "1e+308" in msg, msg
    assert len(err.problems) == 1, str(err)
    # a wide yet finite span stays valid
    for lo, up in ((-1e308, 10.0), (0.5, 1e308), (-1e307, 1e307)):
        raw = make(lambda r, lo=lo, up=up: r["design"]["variables"][0].update(lower=lo, upper=up))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            load_case_text(as_text(raw), "ok.yaml")


def _swap_stiff(r):
    v = r["design"]["variables"][1]
    v["lower"], v["upper"] = v["upper"], v["lower"]


@pytest.mark.parametrize("mutate", [
    _swap_stiff,
    lambda r: r["design"]["variables"][1].__setitem__("value", "lots"),
    lambda r: r["responses"][0]["quantity"].__setitem__("dof", "tipp"),
], ids=["swapped_bounds", "bad_design_value", "bad_response_used_in_expression"])
def test_one_mistake_gives_one_problem_not_spurious_unknown_symbols(mutate):
    # 'stiff' and 'tip_end' are defined in the case; rejecting an entry of theirs must not
    # turn every later use into "expression ... names unknown symbol 'stiff'".
    err = case_error(mutate)
    assert "unknown symbol" not in str(err), str(err)
    assert len(err.problems) == 1, str(err)


# ---------------------------------------------------------------------------- expressions
@pytest.mark.parametrize("mutate, path, suggestion", [
    (lambda r: r["model"]["elements"][1].__setitem__("mass", "mass_bb"), "model.elements[1].mass", "mass_b"),
    (lambda r: r["model"]["elements"][3].__setitem__("k", "2*stif"), "model.elements[3].k", "stiff"),
    (lambda r: r["model"]["loads"][0].__setitem__("value", "10*mass_c"), "model.loads[0].value", "mass_b"),
    (lambda r: r["model"]["loads"][0]["function"].__setitem__("t1", "0.1*stifff"),
     "model.loads[0].function.t1", "stiff"),
    (lambda r: r["responses"][2].__setitem__("expression", "tip_nd + 1"), "responses[2].expression", "tip_end"),
], ids=["mass", "spring", "load", "timefunction", "response_expression"])
def test_expression_with_unknown_symbol(mutate, path, suggestion):
    err = case_error(mutate)
    assert_problem(err, path, "unknown symbol", f"did you mean '{suggestion}'")


def test_expression_calling_forbidden_function_is_rejected():
    err = case_error(lambda r: r["model"]["elements"][0].__setitem__("mass", "__import__('os')"))
    assert_problem(err, "model.elements[0].mass", "not allowed")


# ---------------------------------------------------------------------------- missing DOFs / elements
@pytest.mark.parametrize("mutate, path, name, suggestion", [
    (lambda r: r["responses"][0]["quantity"].__setitem__("dof", "tipp"), "responses[0].quantity.dof",
     "tipp", "tip"),
    (lambda r: r["responses"][1]["quantity"].__setitem__("element", "spring_bb"),
     "responses[1].quantities[0].element", "spring_bb", "spring_b"),
    (lambda r: r["model"]["loads"][0].__setitem__("dof", "tp"), "model.loads[0].dof", "tp", "tip"),
    (lambda r: r["model"]["elements"][3].__setitem__("dofs", ["tip", "bse"]), "model.elements[3].dofs",
     "bse", "base"),
], ids=["response_dof", "response_element", "load_dof", "spring_dof"])
def test_missing_dof_or_element(mutate, path, name, suggestion):
    err = case_error(mutate)
    assert_problem(err, path, f"'{name}'", f"did you mean '{suggestion}'")


def test_response_naming_unrelated_dof_still_names_it():
    err = case_error(lambda r: r["responses"][0]["quantity"].__setitem__("dof", "nowhere"))
    assert_problem(err, "responses[0].quantity.dof", "'nowhere'")


def test_response_naming_unknown_event():
    def add(r):
        r["events"] = [{"name": "contact", "quantity": {"dof": "tip"}, "value": 0.05}]
        r["responses"].append({"name": "t_hit", "type": "event_time", "event": "contcat"})
    err = case_error(add)
    assert_problem(err, "responses[3].event", "'contcat'", "did you mean 'contact'")


# ---------------------------------------------------------------------------- files and YAML
def test_missing_file(tmp_path):
    missing = tmp_path / "nope" / "case.yaml"
    with pytest.raises(CaseError, match=r"file not found: .*case\.yaml") as info:
        load_case(missing)
    assert str(missing) in str(info.value)
    assert len(info.value.problems) == 1


def test_directory_instead_of_file(tmp_path):
    with pytest.raises(CaseError, match="cannot read"):
        load_case(tmp_path)


def test_invalid_yaml_reports_line(tmp_path):
    p = tmp_path / "broken.yaml"
    p.write_text("name: x\nintegrator: {dt: 1e-3, t_end: [1\n", encoding="utf-8")
    with pytest.raises(CaseError, match=r"not valid YAML at line \d+, column \d+") as info:
        load_case(p)
    assert str(p) in str(info.value)


def test_top_level_not_a_mapping():
    with pytest.raises(CaseError, match="expected a mapping at the top level, found list"):
        load_case_text("- a\n- b\n", "list.yaml")


def test_load_case_from_file_reports_file_name(tmp_path):
    p = tmp_path / "case.yaml"
    raw = make(lambda r: r["integrator"].__setitem__("tend", 1.0))
    p.write_text(as_text(raw), encoding="utf-8")
    with pytest.raises(CaseError, match=r"invalid case .*case\.yaml \(1 problem\)"):
        load_case(p)


# ---------------------------------------------------------------------------- all problems at once
def test_every_problem_is_reported_in_one_error():
    def many(r):
        r["integrator"]["tend"] = 1.0                                   # unknown key
        r["integrator"]["dt"] = "fast"                                  # wrong type
        r["model"]["elements"][0]["mass"] = -1.0                        # out of range
        v = r["design"]["variables"][0]
        v["lower"], v["upper"] = v["upper"], v["lower"]                 # swapped bounds
        r["model"]["elements"][3]["k"] = "2*stif"                       # unknown symbol
        r["responses"][0]["quantity"]["dof"] = "tipp"                   # missing DOF
        r["responses"][1]["quantity"]["element"] = "spring_bb"          # missing element
        r["sensitivity"]["partials"] = "forwrd"                         # unknown name
    err = case_error(many)
    expected = {
        "integrator.tend": "did you mean 't_end'",
        "integrator.dt": "fast",
        "model.elements[0].mass": "> 0",
        "design.variables[0]": "swap",
        "model.elements[3].k": "did you mean 'stiff'",
        "responses[0].quantity.dof": "did you mean 'tip'",
        "responses[1].quantities[0].element": "did you mean 'spring_b'",
        "sensitivity.partials": "did you mean 'forward'",
    }
    for path, fragment in expected.items():
        assert_problem(err, path, fragment)
    text = str(err)
    n = len(err.problems)
    assert n >= len(expected)
    assert text.startswith(f"invalid case bad.yaml ({n} problems):")
    assert text.count("\n  - ") == n
    assert "Traceback" not in text


@pytest.mark.parametrize("first", [
    lambda r: r["model"]["elements"][0].__setitem__("mass", -1.0),
    lambda r: r["design"]["variables"][0].__setitem__("value", 20.0),
    lambda r: r["integrator"].__setitem__("dt", -1.0),
], ids=["model_problem", "design_problem", "integrator_problem"])
def test_response_problems_are_reported_together_with_earlier_problems(first):
    # A problem in the model (or anywhere before the responses) must not hide the
    # problems of the responses: the user gets every problem in ONE error.
    def both(r):
        first(r)
        r["responses"][1]["quantity"]["element"] = "spring_bb"
    err = case_error(both)
    assert len(err.problems) == 2, str(err)
    assert_problem(err, "responses[1].quantities[0].element", "did you mean 'spring_b'")


def test_problems_are_not_reported_twice():
    # A missing required key is one problem, not "missing required key" plus
    # "expected a number, found nothing" at the same path.
    err = case_error(lambda r: r["integrator"].pop("dt"))
    assert_problem(err, "integrator.dt", "missing")
    paths = [p.path for p in err.problems]
    assert len(paths) == len(set(paths)), str(err)


def test_load_case_dict_collects_problems_too():
    raw = make(lambda r: (r["integrator"].__setitem__("dtt", 1.0), r["model"]["dofs"].append("free")))
    with pytest.raises(CaseError) as info:
        load_case_dict(raw, "dict-case")
    err = info.value
    assert_problem(err, "integrator.dtt", "did you mean 'dt'")
    assert_problem(err, "model.elements", "'free'", "no mass")


# ---------------------------------------------------------------------------- --set overrides
def test_override_changes_the_case():
    case = load_case_text(as_text(make()), "ok.yaml",
                          ["integrator.t_end=0.05", "design.variables[1].value=75", "integrator.dt=2.5e-3"])
    assert case.plan.t_end == pytest.approx(0.05)
    assert case.plan.dt == pytest.approx(2.5e-3)
    assert case.x0[1] == pytest.approx(75.0)
    # the stored case text reflects the overrides (it goes into the HDF5 'case' attribute)
    assert yaml.safe_load(case.text)["integrator"]["t_end"] == pytest.approx(0.05)


@pytest.mark.parametrize("override, path, fragment", [
    ("design.variables[9].value=1", "--set design.variables[9].value", "does not exist"),
    ("integrator.t_end", "--set integrator.t_end", "KEY=VALUE"),
    ("integrator.dt.x=1", "--set integrator.dt.x", "not inside a mapping"),
], ids=["bad_index", "no_equals", "into_scalar"])
def test_invalid_override(override, path, fragment):
    err = case_error(overrides=[override])
    assert_problem(err, path, fragment)


def test_override_with_unknown_key_gets_did_you_mean():
    err = case_error(overrides=["integrator.tend=1"])
    assert_problem(err, "integrator.tend", "did you mean 't_end'")


def test_override_with_invalid_value_is_validated():
    err = case_error(overrides=["integrator.dt=-1"])
    assert_problem(err, "integrator.dt", "positive")


def test_all_bad_overrides_in_one_error():
    err = case_error(overrides=["nonsense", "design.variables[5].value=1", "responses[7].rho=3"])
    assert len(err.problems) == 3, str(err)


# ---------------------------------------------------------------------------- NaN / Inf
def unstable(raw: dict) -> None:
    """The tip carries a strongly negative spring of its own: its motion grows like
    exp(1000 t) and overflows after about 0.3-0.5 s.  The base stays well behaved."""
    el = raw["model"]["elements"]
    el[3]["dofs"] = ["tip", "ground"]
    el[3]["k"] = "-1e6*stiff/50"
    el[4]["dofs"] = ["tip", "ground"]
    raw["integrator"]["t_end"] = 1.0


def _nonfinite(raw: dict) -> NonFiniteError:
    case = load_case_text(as_text(raw), "nan.yaml")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(NonFiniteError) as info:
            run_case(case)
    return info.value


def _time_in(msg: str) -> float:
    m = re.search(r"t = ([-+0-9.eE]+) s", msg)
    assert m, f"no time in {msg!r}"
    return float(m.group(1))


def test_blow_up_stops_with_time_and_step():
    err = _nonfinite(make(unstable))
    msg = str(err)
    assert isinstance(err, DynsensError) and isinstance(err, FloatingPointError)
    assert "NaN" in msg
    t = _time_in(msg)
    # the runaway monitor stops the growth (×1e6 beyond its early scale) at ~0.03 s, long
    # before it would overflow (~0.97 s)
    assert 0.0 < t <= 1.0
    assert re.search(r"step \d+", msg), msg


def test_blow_up_message_names_the_dof_where_it_first_appeared():
    # "says where it first appeared": the state of 'tip' overflows first; the message
    # must name that DOF (only the time and step is not enough).
    msg = str(_nonfinite(make(unstable)))
    assert "tip" in msg, msg
    assert "base" not in msg, msg


def test_nan_parameter_names_where_it_first_appeared():
    # mass_b = 2 makes sqrt(mass_b - 5) NaN: refused when the case is loaded (the start
    # design is checked before any step), naming the entry, the expression and the value
    with pytest.raises(CaseError) as info:
        load_case_text(as_text(make(lambda r: r["model"]["elements"][1].__setitem__("mass", "sqrt(mass_b - 5)"))),
                       "nan.yaml")
    msg = str(info.value)
    assert "model.elements[1].mass" in msg and "sqrt(mass_b - 5)" in msg and "mass_b = 2" in msg, msg
    assert "start design" in msg, msg


def test_version_is_exposed():
    assert isinstance(dynsens.__version__, str) and dynsens.__version__


@pytest.mark.parametrize("case, body, value", [("cart_pole", "pole", -1e300), ("pendulum_3d", "bob", 1e200)])
def test_overflowing_body_position_is_a_clear_error_not_a_failed_svd(case, body, value):
    """A position of −1e300 made the redundancy analysis' SVD fail to converge (a traceback), then
    a ModelError without the case file; 1e200 still failed in the SVD (a traceback)."""
    from conftest import CASES
    raw = yaml.safe_load((CASES / f"{case}.yaml").read_text())
    raw["model"]["bodies"][body]["position"][0] = value
    with pytest.raises(CaseError) as info, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        load_case_dict(raw, source="bad.yaml")
    assert "bad.yaml" in str(info.value)
    assert_problem(info.value, "model.bodies", "not finite", f"body '{body}' at position [{value:.3g}",
                   "magnitude below 1e+150")


def _four_bar(**crank) -> dict:
    from conftest import CASES
    raw = yaml.safe_load((CASES / "four_bar.yaml").read_text())
    raw["model"]["bodies"]["crank"].update(crank)
    return raw


@pytest.mark.parametrize("crank, path, fragment", [
    ({"mass": "1/0"}, "model.bodies.crank.mass", "expression '1/0' cannot be evaluated: division by zero"),
    ({"mass": "a/0"}, "model.bodies.crank.mass", "at a = 0.15: division by zero"),
    ({"markers": {"O": ["-0.5*a", 0, 0], "A": ["1/0", 0, 0]}}, "model.bodies.crank.markers.A[0]", "division by zero"),
    ({"position": ["log(a - 1)", 0, 0]}, "model.bodies.crank.position[0]", "outside a function's domain"),
    ({"mass": "m_crank"}, "model.bodies.crank.mass", "unknown symbol 'm_crank'"),
], ids=["mass_const", "mass_design", "marker", "position", "unknown_symbol"])
def test_mechanism_expression_errors_name_file_and_path(crank, path, fragment):
    """An expression without a value at the start design stopped the mechanism's redundancy
    analysis with a bare ExpressionError (no file, no path); a structural case said both."""
    with pytest.raises(CaseError) as info:
        load_case_dict(_four_bar(**crank), source="mech.yaml")
    assert "mech.yaml" in str(info.value)
    assert_problem(info.value, path, fragment)


@pytest.mark.parametrize("key, value, path", [
    ("stabilization", {"alpha": float("nan")}, "model.stabilization.alpha"),
    ("constraint_scale", float("inf"), "model.constraint_scale"),
    ("drift_limit", float("nan"), "model.drift_limit"),
    ("initial", {"hold": ["crank.angle_z"], "tolerance": float("nan")}, "model.initial.tolerance"),
])
def test_mechanism_settings_are_finite(key, value, path):
    """nan passed the `< 0` / `<= 0` range tests of these settings (every comparison is false)."""
    raw = _four_bar()
    raw["model"][key] = value
    with pytest.raises(CaseError) as info:
        load_case_dict(raw, source="mech.yaml")
    assert_problem(info.value, path, "expected a finite number")


def test_output_folder_that_cannot_be_made_is_a_clear_error(tmp_path, monkeypatch):
    """A folder the path checks cannot foresee (creating it fails) is an OutputPathError naming
    the path, with no temporary file left behind."""
    from pathlib import Path
    from dynsens.io.paths import OutputPathError, atomic_path

    def refuse(self, *a, **k):
        raise FileNotFoundError(2, "No such file or directory")
    monkeypatch.setattr(Path, "mkdir", refuse)
    with pytest.raises(OutputPathError) as info:
        with atomic_path(tmp_path / "sub" / "x.h5"):
            pass
    assert "sub" in str(info.value) and "No such file" in str(info.value)
    assert not list(tmp_path.iterdir())
