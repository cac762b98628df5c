"""Families that size beam sections: ``assign: {section.D: D}`` gives every selected beam its own
section dimension (issue 38).

Contract: a family may assign any numeric entry of its element type, a beam's section
dimensions and section properties included (``section.KEY``, 2D and 3D); each member keeps its
name and bounds; the expanded case equals the case written out by hand, bit for bit; the
gradients of a plane and a space frame sized that way equal complex step of the whole run,
direct and adjoint; the design partials stay coloured (a member touches one element); a key the
element's section does not have is refused at the family's assign path.
"""
from __future__ import annotations

import copy

import numpy as np
import pytest

import dynsens
from dynsens.case.load import load_case_dict
from dynsens.errors import CaseError
from dynsens.sensitivity import colour_columns
from helpers import complex_step_gradients
from test_beams import portal_frame
from test_beams3d import space_frame


def plane_families() -> dict:
    """The portal frame with one tube diameter and wall per column and one height per girder."""
    raw = portal_frame()
    raw["design"]["variables"] = [v for v in raw["design"]["variables"] if v["name"] in ("H", "E_col")]
    raw["design"]["families"] = [
        {"name": "D", "type": "beam", "elements": "col_*", "value": 80.0, "lower": 30.0, "upper": 200.0,
         "assign": {"section.D": "D"}, "members": {"col_b": {"value": 90.0}}},
        {"name": "t", "type": "beam", "elements": "col_*", "value": 5.0, "lower": 1.0, "upper": 20.0,
         "assign": {"section.t": "t"}},
        {"name": "h", "type": "beam", "elements": "girder_*", "value": 120.0, "lower": 50.0, "upper": 300.0,
         "assign": {"section.h": "h"}},
    ]
    return raw


def by_hand() -> dict:
    """The same frame with every member variable written out."""
    raw = portal_frame()
    raw["design"]["variables"] = [v for v in raw["design"]["variables"] if v["name"] in ("H", "E_col")] + [
        {"name": "D[col_a]", "value": 80.0, "lower": 30.0, "upper": 200.0},
        {"name": "D[col_b]", "value": 90.0, "lower": 30.0, "upper": 200.0},
        {"name": "t[col_a]", "value": 5.0, "lower": 1.0, "upper": 20.0},
        {"name": "t[col_b]", "value": 5.0, "lower": 1.0, "upper": 20.0},
        {"name": "h[girder_1]", "value": 120.0, "lower": 50.0, "upper": 300.0},
        {"name": "h[girder_2]", "value": 120.0, "lower": 50.0, "upper": 300.0},
    ]
    els = {e["name"]: e for e in raw["model"]["elements"]}
    for col in ("col_a", "col_b"):
        els[col]["section"] = {**els[col]["section"], "D": f"D[{col}]", "t": f"t[{col}]"}
    for g in ("girder_1", "girder_2"):
        els[g]["section"] = {**els[g]["section"], "h": f"h[{g}]"}
    return raw


def test_plane_frame_sized_per_member_equals_the_case_written_by_hand() -> None:
    fam, hand = load_case_dict(plane_families()), load_case_dict(by_hand())
    assert fam.design_names == ("H", "E_col", "D[col_a]", "D[col_b]", "t[col_a]", "t[col_b]",
                                "h[girder_1]", "h[girder_2]")
    assert sorted(fam.design_names) == sorted(hand.design_names)
    order = [hand.design_names.index(n) for n in fam.design_names]
    np.testing.assert_array_equal(fam.x0, hand.x0[order])
    np.testing.assert_array_equal(fam.lower, hand.lower[order])
    a, b = dynsens.run_case(fam), dynsens.run_case(hand)
    for name, rv in a.responses.items():
        assert rv.value == b.responses[name].value, name
        np.testing.assert_array_equal(rv.gradient, b.responses[name].gradient[order], err_msg=name)


@pytest.mark.parametrize("method", ["direct", "adjoint"])
def test_plane_frame_section_family_gradients_equal_complex_step(method: str) -> None:
    raw = plane_families()
    raw["sensitivity"] = {"partials": "complex", "method": method}
    case = load_case_dict(raw)
    res = dynsens.run_case(case)
    assert res.status == "completed"
    cs = complex_step_gradients(case)
    # the columns' diameters and walls differ in effect member by member
    assert abs(cs["drift_max"][2] - cs["drift_max"][3]) > 1e-3 * abs(cs["drift_max"][2])
    for name, rv in res.responses.items():
        np.testing.assert_allclose(np.real(rv.gradient), cs[name], rtol=1e-8,
                                   atol=1e-10 * np.abs(cs[name]).max(), err_msg=f"{method}: {name}")


def test_space_frame_box_height_family_gradients_equal_complex_step() -> None:
    raw = space_frame()
    raw["design"]["variables"] = [v for v in raw["design"]["variables"] if v["name"] != "h"]
    raw["design"]["families"] = [{"name": "h", "type": "beam", "elements": ["arm_1", "arm_2"], "value": 100.0,
                                  "lower": 50.0, "upper": 300.0, "assign": {"section.h": "h"}}]
    case = load_case_dict(raw)
    assert case.design_names[-2:] == ("h[arm_1]", "h[arm_2]")
    res = dynsens.run_case(case)
    cs = complex_step_gradients(case)
    for name, rv in res.responses.items():
        np.testing.assert_allclose(np.real(rv.gradient), cs[name], rtol=1e-8,
                                   atol=1e-10 * np.abs(cs[name]).max(), err_msg=name)
    adj = dynsens.run_case(load_case_dict({**raw, "sensitivity": {"partials": "complex", "method": "adjoint"}}))
    for name, rv in adj.responses.items():
        np.testing.assert_allclose(np.real(rv.gradient), np.real(res.responses[name].gradient), rtol=1e-9,
                                   atol=1e-12 * np.abs(cs[name]).max(), err_msg=name)


def chain_of_beams(n: int) -> dict:
    """A cantilever of n tube beams, one diameter per beam."""
    nodes = {f"n{i}": {"coords": [100.0 * i, 0.0]} for i in range(n + 1)}
    nodes["n0"]["fixed"] = "all"
    return {
        "name": "chain",
        "design": {"families": [{"name": "D", "type": "beam", "value": 40.0, "lower": 10.0, "upper": 100.0,
                                 "assign": {"section.D": "D"}}]},
        "model": {"type": "structural", "dim": 2, "nodes": nodes,
                  "elements": [{"type": "beam", "name": f"e{i}", "nodes": [f"n{i}", f"n{i + 1}"], "E": 2.1e5,
                                "density": 7.85e-9, "section": {"shape": "tube", "D": 1.0, "t": 3.0}}
                               for i in range(n)],
                  "loads": [{"node": f"n{n}", "direction": "y", "value": -100.0, "function": "constant"}]},
        "integrator": {"dt": 1e-3, "t_end": 0.005},
        "responses": [{"name": "tip", "type": "value", "quantity": {"dof": f"n{n}.y"}}],
    }


def test_member_partials_stay_coloured() -> None:
    case = load_case_dict(chain_of_beams(30))
    colours = colour_columns(case.model.design_pattern(), len(case.design_names))
    assert len(case.design_names) == 30
    assert colours is not None and len(colours) <= 4          # a member touches its own beam only


@pytest.mark.parametrize("assign, needle", [
    ({"section.Dx": "D"}, "unknown key"),
    ({"nodes.D": "D"}, "not a numeric entry"),
    ({"section.D": [1, 2]}, "expected an expression"),
])
def test_bad_section_assignments_are_refused_at_the_assign_path(assign: dict, needle: str) -> None:
    raw = chain_of_beams(3)
    raw["design"]["families"][0]["assign"] = assign
    with pytest.raises(CaseError) as exc:
        load_case_dict(raw)
    text = str(exc.value)
    assert "design.families[0].assign." in text and needle in text


def test_an_element_without_the_section_mapping_is_reported() -> None:
    raw = chain_of_beams(3)
    raw["model"]["elements"][1] = copy.deepcopy(raw["model"]["elements"][1])
    raw["model"]["elements"][1]["section"] = "tube"
    with pytest.raises(CaseError, match=r"model.elements\[1\].section"):
        load_case_dict(raw)
