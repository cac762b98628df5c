"""Per-member design variables: a family declares one variable per selected element.

Contract (issue 14): members are named ``A[element]`` in the design, the HDF5 design group and
the summaries; bounds, start and scale are shared (a member may override them); ``--set``
reaches the family (``design.families[0].value``) or one member
(``design.families[0].members.NAME.value``) and ``-x`` the family (``A=…``) or one member
(``A[diag1]=…``); the gradient of every member equals complex step of the whole run, and a
group's gradient is the sum of its members'; bad families are reported with their YAML path.
"""
from __future__ import annotations

import copy
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import dynsens
from dynsens import CaseError
from dynsens.case.load import load_case, load_case_dict
import dynsens.cli.simulate  # noqa: F401  (registers the command)
from dynsens.cli.main import cli
from dynsens.optimize.runner import OptimizationError, resolve_x0
from helpers import complex_step_gradients

TRUSS = Path(__file__).resolve().parents[1] / "cases" / "truss_lightweight.yaml"
GROUPS = {"A_chord_bottom": "bottom", "A_chord_top": "top", "A_web": ("diag", "vert")}


def per_member(**family) -> dict:
    """truss_lightweight with one area per bar (family A) instead of three groups."""
    raw = yaml.safe_load(TRUSS.read_text())
    fam = {"name": "A", "elements": "all", "value": 300.0, "lower": 50.0, "upper": 2000.0,
           "assign": {"area": "A", "inertia": "A**2*10/(8*pi)"}}
    fam.update(family)
    raw["design"] = {"families": [fam]}
    for el in raw["model"]["elements"]:
        if el["type"] == "bar":
            el["area"], el["inertia"] = 1.0, 1.0          # replaced for the family's members
    return raw


def bar_names(raw: dict) -> list[str]:
    return [el["name"] for el in raw["model"]["elements"] if el["type"] == "bar"]


def test_members_are_named_bounded_and_assigned() -> None:
    raw = per_member(members={"diag1": {"value": 500.0, "upper": 900.0}})
    case = load_case_dict(raw)
    names = bar_names(raw)
    assert case.design_names == tuple(f"A[{n}]" for n in names) and len(names) == 16
    j = case.design_names.index("A[diag1]")
    assert case.x0[j] == 500.0 and case.upper[j] == 900.0
    others = np.delete(np.arange(16), j)
    assert np.all(case.x0[others] == 300.0) and np.all(case.lower == 50.0) and np.all(case.upper[others] == 2000.0)
    # each bar's area is its own member: the mass is Σ ρ A_e L_e + the tip mass
    params = case.model.parameters(case.x0)
    np.testing.assert_allclose(params["A"], case.x0)
    np.testing.assert_allclose(params["P_euler"], np.pi ** 2 * 210000.0 * case.x0 ** 2 * 10 / (8 * np.pi)
                               / params["L0"] ** 2)
    # a pattern and a list select subsets; the case's own variables come first
    raw = per_member(elements="diag*")
    raw["design"]["variables"] = [{"name": "A_rest", "value": 300.0, "lower": 50.0, "upper": 2000.0}]
    for el in raw["model"]["elements"]:
        if el["type"] == "bar" and not el["name"].startswith("diag"):
            el["area"], el["inertia"] = "A_rest", "A_rest**2*10/(8*pi)"
    case = load_case_dict(raw)
    assert case.design_names == ("A_rest", "A[diag1]", "A[diag2]", "A[diag3]", "A[diag4]")
    case = load_case_dict(per_member(elements=["vert2", "top1"]))
    assert case.design_names == ("A[top1]", "A[vert2]")          # element order


def test_member_gradients_equal_complex_step_and_sum_to_the_group_gradient() -> None:
    raw = per_member(value=400.0)
    raw["integrator"]["t_end"] = 0.006                   # the pulse's peak: a short run suffices
    raw["sensitivity"] = {"partials": "complex"}
    case = load_case_dict(raw)
    res = dynsens.run_case(case)
    cs = complex_step_gradients(case)
    for name, rv in res.responses.items():
        np.testing.assert_allclose(np.real(rv.gradient), cs[name], rtol=1e-8,
                                   atol=1e-10 * np.abs(cs[name]).max(), err_msg=name)
    # the grouped case at the same areas: d/dA_group = Σ over its members of d/dA[member]
    grouped = yaml.safe_load(TRUSS.read_text())
    grouped["integrator"]["t_end"] = 0.006
    grouped["sensitivity"] = {"partials": "complex"}
    for v in grouped["design"]["variables"]:
        v["value"] = 400.0
    gcase = load_case_dict(grouped)
    gres = dynsens.run_case(gcase)
    members = case.design_names
    for j, (group, prefix) in enumerate(GROUPS.items()):
        cols = [k for k, m in enumerate(members) if m[2:].startswith(prefix)]
        for name in ("mass", "stress_ks", "buckling_ks", "tip_ks"):
            assert float(np.real(gres.responses[name].value)) == pytest.approx(
                float(np.real(res.responses[name].value)), rel=1e-12)
            assert np.real(gres.responses[name].gradient[j]) == pytest.approx(
                np.real(res.responses[name].gradient[cols]).sum(), rel=1e-9, abs=1e-14), (name, group)


def test_set_and_x_address_the_family_or_one_member(tmp_path: Path) -> None:
    path = tmp_path / "members.yaml"
    path.write_text(yaml.safe_dump(per_member(), sort_keys=False))
    case = load_case(path, ["design.families[0].value=350", "design.families[0].members.top2.value=700"])
    x = dict(zip(case.design_names, case.x0))
    assert x["A[top2]"] == 700.0 and all(v == 350.0 for k, v in x.items() if k != "A[top2]")
    case = load_case(path)
    x0 = resolve_x0(case, {"A": 250.0, "A[diag3]": 800.0})          # family first, then one member
    assert x0[case.design_names.index("A[diag3]")] == 800.0 and np.sum(x0 == 250.0) == 15
    with pytest.raises(OptimizationError, match="outside the bounds of design variable 'A\\[bottom1\\]'"):
        resolve_x0(case, {"A": 3000.0})
    with pytest.raises(OptimizationError, match="unknown design variable 'B'"):
        resolve_x0(case, {"B": 1.0})
    # the HDF5 design group and the summary carry the member names
    out = tmp_path / "run.h5"
    r = CliRunner().invoke(cli, ["simulate", str(path), "-o", str(out), "--no-sensitivities",
                                 "--set", "design.families[0].members.vert4.value=600"])
    assert r.exit_code == 0, r.output
    assert "gradient d/d[A[bottom1], A[top1], A[diag1]" in r.output
    with h5py.File(out) as f:
        names = list(f["design/names"].asstr()[()])
        values = f["design/values"][()]
    assert names[-1] == "A[vert4]" and values[-1] == 600.0 and len(names) == 16


@pytest.mark.parametrize("change, path, needle", [
    ({"elements": ["diag1", "diagg2"]}, "design.families[0].elements", "did you mean 'diag2'"),
    ({"elements": "chord*"}, "design.families[0].elements", "selects no bar element"),
    ({"members": {"diag9": {"value": 1.0}}}, "design.families[0].members.diag9", "not a member"),
    ({"members": {"diag1": {"value": 1.0}}}, "design.families[0].members.diag1.value", "A[diag1]: 1.0 is outside"),
    ({"members": {"diag1": {"valu": 1.0}}}, "design.families[0].members.diag1.valu", "unknown key"),
    # a problem of an assigned entry is the family's: once, at its assign key, naming the members
    ({"assign": {"area": "A*B"}}, "design.families[0].assign.area",
     "A[bottom1] (model.elements[0].area): expression 'A[bottom1]*B' names unknown symbol 'B'"),
    ({"assign": {"area": "-A"}}, "design.families[0].assign.area", "also fails for 15 more members"),
    ({"value": -5.0, "lower": -10.0}, "design.families[0].assign.area", "expected > 0, found -5"),
    ({"assign": {"areaa": "A"}}, "design.families[0].assign.areaa",
     "unknown key of a bar element; did you mean 'area'"),
    ({"assign": {"nodes": "A"}}, "design.families[0].assign.nodes", "not a numeric entry of a bar element"),
    ({"assign": {"name": "A"}}, "design.families[0].assign.name", "not a numeric entry"),
    ({"assign": {"area": True}}, "design.families[0].assign.area", "expected an expression of the family name"),
    ({"value": "x"}, "design.families[0].value", "expected a number or a constant expression"),
    ({"scale": -1.0}, "design.families[0].scale", "expected a positive finite number"),
    ({"members": {"diag1": {"upper": float("nan")}}}, "design.families[0].members.diag1.upper", "finite number"),
    ({"lower": -1e308, "upper": 1e308}, "design.families[0]", "expected bounds whose difference is a "
     "finite number, found lower -1e+308 and upper 1e+308"),
    ({"name": "A b"}, "design.families[0].name", "identifier"),
    ({"colour": 1}, "design.families[0].colour", "unknown key"),
])
def test_bad_families_are_reported_with_their_path(change, path, needle) -> None:
    with pytest.raises(CaseError) as err:
        load_case_dict(per_member(**change))
    msgs = [p.message for p in err.value.problems if p.path == path]
    assert any(needle in m for m in msgs), [str(p) for p in err.value.problems]


def test_bad_family_entries_are_one_problem_each() -> None:
    """Before, a family's bad entry came back once per member (16 times here), at expanded paths."""
    with pytest.raises(CaseError) as err:
        load_case_dict(per_member(value="x", assign={"area": "-A", "nodes": "A"}))
    assert sorted(p.path for p in err.value.problems) == ["design.families[0].assign.nodes",
                                                          "design.families[0].value"]
    with pytest.raises(CaseError) as err:
        load_case_dict(per_member(assign={"area": "-A", "inertia": "A"}))
    assert [p.path for p in err.value.problems] == ["design.families[0].assign.area"]
    # the family's own bounds, swapped or overflowing, are one problem too (was one per member)
    for bounds, needle in (({"lower": 10.0, "upper": 1.0}, "did you swap the bounds?"),
                           ({"lower": -1e308, "upper": 1e308}, "upper - lower overflows")):
        with pytest.raises(CaseError) as err:
            load_case_dict(per_member(value=5.0, **bounds))
        assert [p.path for p in err.value.problems] == ["design.families[0]"], str(err.value)
        assert needle in err.value.problems[0].message and "A[" not in err.value.problems[0].message
    # a member's own bounds keep the member's name
    with pytest.raises(CaseError) as err:
        load_case_dict(per_member(members={"diag1": {"lower": 10.0, "upper": 1.0, "value": 5.0}}))
    assert [p.message.split(":")[0] for p in err.value.problems] == ["A[diag1]"], str(err.value)


def test_a_placeholder_the_family_replaces_is_still_a_number() -> None:
    raw = per_member()
    raw["model"]["elements"][0]["area"] = [1.0, 2.0]     # replaced by A[bottom1], but not a value
    with pytest.raises(CaseError) as err:
        load_case_dict(raw, "truss.yaml")
    assert [str(p) for p in err.value.problems] == [
        "model.elements[0].area: expected a number or an expression (a placeholder that "
        "design.families[0].assign replaces), found [1.0, 2.0]"]
    assert "truss.yaml" in str(err.value)


def test_family_member_of_an_unnameable_element_is_rejected() -> None:
    raw = per_member()
    raw["model"]["elements"][0]["name"] = "bottom-1"
    with pytest.raises(CaseError, match="'bottom-1' cannot name a family member"):
        load_case_dict(copy.deepcopy(raw))
