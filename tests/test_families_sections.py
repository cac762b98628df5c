"""Design families over beam sections (issue 38): a family's ``assign`` sets any numeric entry of
the selected elements, also a section's dimensions and properties (``section.D``, ``section.h``,
``section.Iy``) of 2D and 3D beams.

Contract: each member keeps its own name and bounds; the gradients of a frame sized through
section families equal complex step of the whole run (direct and adjoint); the expanded family is
the case written out by hand, bit for bit; a member touches one beam, so the coloured design
partials cost the colour count, not the member count; an entry a member's section does not take
is one problem at the family's ``assign`` key (path, expected, found).
"""
from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import pytest

import dynsens
from dynsens import CaseError
from dynsens.case.load import load_case_dict
from dynsens.derivatives.partials import DesignPartials
from helpers import complex_step_gradients
from test_beams import cantilever, portal_frame
from test_beams3d import space_frame

TOL = 1e-8          # direct and adjoint against complex step of the whole run (as test_beams)


def family(name: str, elements: list[str], assign: dict, value: float, lower: float, upper: float,
           **extra) -> dict:
    return {"name": name, "type": "beam", "elements": elements, "value": value, "lower": lower,
            "upper": upper, "assign": assign, **extra}


def portal_by_families() -> dict:
    """The portal frame with tube D and t per column and the girders' h per member (families),
    instead of one shared D, t and h."""
    raw = portal_frame()
    raw["design"]["variables"] = [v for v in raw["design"]["variables"] if v["name"] in ("H", "E_col")]
    raw["design"]["families"] = [
        family("D", ["col_a", "col_b"], {"section.D": "D"}, 80.0, 30.0, 200.0,
               members={"col_b": {"value": 90.0}}),
        family("t", ["col_a", "col_b"], {"section.t": "t"}, 5.0, 1.0, 20.0),
        family("h", ["girder_1", "girder_2"], {"section.h": "h"}, 120.0, 50.0, 300.0,
               members={"girder_2": {"value": 110.0, "upper": 250.0}}),
    ]
    return raw


def portal_by_hand() -> dict:
    """The same variables written out: the family's expansion, by hand."""
    raw = portal_frame()
    own = [v for v in raw["design"]["variables"] if v["name"] in ("H", "E_col")]
    raw["design"]["variables"] = own + [
        {"name": "D[col_a]", "value": 80.0, "lower": 30.0, "upper": 200.0},
        {"name": "D[col_b]", "value": 90.0, "lower": 30.0, "upper": 200.0},
        {"name": "t[col_a]", "value": 5.0, "lower": 1.0, "upper": 20.0},
        {"name": "t[col_b]", "value": 5.0, "lower": 1.0, "upper": 20.0},
        {"name": "h[girder_1]", "value": 120.0, "lower": 50.0, "upper": 300.0},
        {"name": "h[girder_2]", "value": 110.0, "lower": 50.0, "upper": 250.0},
    ]
    for el in raw["model"]["elements"]:
        sec = el.get("section", {})
        for key in ("D", "t", "h"):
            if sec.get(key) == key:
                sec[key] = f"{key}[{el['name']}]"
    return raw


def space_frame_by_families() -> dict:
    """The 3D L-frame with the column's tube D and t and each arm's h as members."""
    raw = space_frame()
    raw["design"]["variables"] = [v for v in raw["design"]["variables"] if v["name"] in ("H", "G_arm")]
    raw["design"]["families"] = [
        family("tube", ["col"], {"section.D": "tube", "section.t": "tube/16"}, 80.0, 30.0, 200.0),
        family("h", ["arm_1", "arm_2"], {"section.h": "h"}, 100.0, 50.0, 300.0,
               members={"arm_2": {"value": 90.0}}),
    ]
    return raw


def assert_gradients_match_complex_step(case, res) -> None:
    cs = complex_step_gradients(case)
    for name, rv in res.responses.items():
        np.testing.assert_allclose(np.real(rv.gradient), cs[name], rtol=TOL,
                                   atol=1e-10 * np.abs(cs[name]).max(), err_msg=name)


@pytest.mark.parametrize("build", [portal_by_families, space_frame_by_families], ids=["plane", "space"])
def test_section_families_gradients_equal_complex_step_direct_and_adjoint(build) -> None:
    case = load_case_dict(build())
    members = [n for n in case.design_names if "[" in n]
    assert len(members) == (6 if build is portal_by_families else 3)
    res = dynsens.run_case(case)
    assert res.status == "completed"
    # each member sizes its own beam: a nonzero mass gradient, and different members differ
    g_mass = np.real(res.responses["mass"].gradient)
    assert all(g_mass[case.design_names.index(m)] > 0 for m in members)
    assert_gradients_match_complex_step(case, res)
    adj = dynsens.run_case(replace(case, plan=replace(case.plan, method="adjoint")))
    assert adj.method == "adjoint"
    for name, rv in res.responses.items():
        np.testing.assert_allclose(np.real(adj.responses[name].gradient), np.real(rv.gradient), rtol=TOL,
                                   atol=1e-10 * np.abs(rv.gradient).max(), err_msg=name)


def test_section_family_members_are_named_bounded_and_assigned() -> None:
    case = load_case_dict(portal_by_families())
    assert case.design_names == ("H", "E_col", "D[col_a]", "D[col_b]", "t[col_a]", "t[col_b]",
                                 "h[girder_1]", "h[girder_2]")
    np.testing.assert_array_equal(case.x0[2:], [80.0, 90.0, 5.0, 5.0, 120.0, 110.0])
    np.testing.assert_array_equal(case.upper[2:], [200.0, 200.0, 20.0, 20.0, 300.0, 250.0])


@pytest.mark.parametrize("method", ["direct", "adjoint"])
def test_family_equals_the_variables_written_by_hand_bit_for_bit(method) -> None:
    fam, hand = (load_case_dict(b()) for b in (portal_by_families, portal_by_hand))
    assert fam.design_names == hand.design_names
    np.testing.assert_array_equal(fam.x0, hand.x0)
    np.testing.assert_array_equal(fam.lower, hand.lower)
    np.testing.assert_array_equal(fam.upper, hand.upper)
    a, b = (dynsens.run_case(replace(c, plan=replace(c.plan, method=method))) for c in (fam, hand))
    assert a.responses.keys() == b.responses.keys()
    for name in a.responses:
        assert np.array_equal(a.responses[name].value, b.responses[name].value), name
        assert np.array_equal(a.responses[name].gradient, b.responses[name].gradient), name


def frame_of_members(n: int = 8) -> dict:
    """A plane cantilever frame of n beams, each with its own box height h and tube-free box wall
    (family h) under a tip pulse: n local members."""
    raw = cantilever(n, section={"shape": "box", "b": 40.0, "h": 1.0, "t": 3.0},
                     loads=[{"node": f"n{n}", "direction": "y", "value": 2.0e3,
                             "function": {"type": "pulse", "t0": 0.0, "duration": 0.004}}])
    raw["design"] = {"families": [family("h", "all", {"section.h": "h"}, 80.0, 20.0, 200.0)]}
    raw["integrator"] = {"dt": 1e-3, "t_end": 0.006}
    raw["sensitivity"] = {"partials": "complex"}
    raw["responses"] = [{"name": "tip", "type": "value", "quantity": {"dof": f"n{n}.y"}},
                        {"name": "mass", "type": "mass"}]
    return raw


def test_section_family_partials_cost_the_colour_count_not_the_member_count() -> None:
    n = 8
    case = load_case_dict(frame_of_members(n))
    assert case.x0.size == n
    pattern = case.model.design_pattern()
    assert all(len(rows) <= 6 for rows in pattern)           # a member reaches its own beam's two nodes
    colours = DesignPartials(case.model, case.x0, "complex").colours
    assert colours is not None and len(colours) == 2         # neighbours share a node: alternate colours
    res = dynsens.run_case(case)
    steps = res.counters["steps"] + 1
    assert res.counters["sensitivity_residual_evaluations"] == len(colours) * steps
    assert_gradients_match_complex_step(case, res)


def _set(raw: dict, fam: int, **kw) -> dict:
    raw = copy.deepcopy(raw)
    raw["design"]["families"][fam].update(kw)
    return raw


@pytest.mark.parametrize("change, path, needles", [
    # the tube columns have no h: expected the tube's dimensions, found h, for both members
    (lambda r: _set(r, 2, elements=["col_a", "col_b"]), "design.families[2].assign.section.h",
     ("h[col_a]", "tube section of a 2D beam (D, t)", "found h", "h[col_b]")),
    # 2D beams have no Iy (a 3D property): unknown to the section of a beam
    (lambda r: _set(r, 2, assign={"section.Iy": "h"}), "design.families[2].assign.section.Iy",
     ("box section of a 2D beam (b, h, t)", "found Iy")),
    (lambda r: _set(r, 2, assign={"section.shape": "h"}), "design.families[2].assign.section.shape",
     ("not a numeric entry", "section.h")),
    (lambda r: _set(r, 2, assign={"section.X": "h"}), "design.families[2].assign.section.X",
     ("not a numeric entry", "section.b")),
    (lambda r: _set(r, 2, assign={"section.h": ["h"]}), "design.families[2].assign.section.h",
     ("expected an expression of the family name",)),
])
def test_bad_section_entry_is_one_problem_at_the_assign_key(change, path, needles) -> None:
    with pytest.raises(CaseError) as err:
        load_case_dict(change(portal_by_families()))
    problems = [p for p in err.value.problems if p.path == path]
    assert len(problems) == 1, [(p.path, p.message) for p in err.value.problems]
    for needle in needles:
        assert needle in problems[0].message, problems[0].message


def test_section_placeholder_must_be_numeric_and_section_a_mapping() -> None:
    raw = portal_by_families()
    raw["model"]["elements"][2]["section"]["h"] = [1.0]
    with pytest.raises(CaseError) as err:
        load_case_dict(raw)
    assert any(p.path == "model.elements[2].section.h" and "placeholder" in p.message for p in err.value.problems)
    raw = space_frame_by_families()
    raw["model"]["elements"][1]["section"] = "box"
    with pytest.raises(CaseError) as err:
        load_case_dict(raw)
    hits = [p for p in err.value.problems if p.path == "design.families[1].assign.section.h"]
    assert len(hits) == 1 and "h[arm_1]" in hits[0].message and "found 'box'" in hits[0].message
