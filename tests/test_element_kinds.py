"""The structural element kinds' registry and protocol (dynsens/models/structural/elements/kind.py): every
registered type has its key section in the case's key table and in the model's ``elements``
list; a type the model's dimension has no kind for is one problem at its key; whether the
compiled step serves a model is what its kinds declare."""
from __future__ import annotations

import pytest

import dynsens
from dynsens.case.load import load_case_dict
from dynsens.case_keys import SECTIONS
from dynsens.models.structural.elements import KINDS, ElementKind, load_kinds, register_kind
from dynsens.models.structural.step import serves


def chain(extra: list | None = None, dim: int = 2) -> dict:
    """Two masses on cubic springs (a spring network), plus ``extra`` elements."""
    nodes = {"a": {"coords": [0.0] * dim, "fixed": "all"}, "b": {"coords": [1.0] + [0.0] * (dim - 1)}}
    elements = [{"type": "mass", "dof": "u1", "mass": 1.0}, {"type": "mass", "dof": "u2", "mass": 1.0},
                {"type": "mass", "node": "b", "mass": 1.0},
                {"type": "spring", "dofs": ["u1", "ground"], "k": 10.0, "k3": 5.0},
                {"type": "spring", "dofs": ["u1", "u2"], "k": 10.0},
                {"type": "spring", "dofs": ["b.x", "ground"], "k": 10.0}] + (extra or [])
    if dim == 2:
        elements.append({"type": "spring", "dofs": ["b.y", "ground"], "k": 10.0})
    else:
        elements += [{"type": "spring", "dofs": [f"b.{a}", "ground"], "k": 10.0} for a in "yz"]
    return {"name": "chain", "design": {"variables": []},
            "model": {"type": "structural", "dim": dim, "dofs": ["u1", "u2"], "nodes": nodes, "elements": elements},
            "integrator": {"dt": 1e-2, "t_end": 1e-2}, "sensitivity": {"enabled": False}}


def test_every_registered_type_has_its_key_section_listed_in_the_model_elements() -> None:
    kinds = load_kinds()
    assert {"mass", "spring", "damper", "bar", "beam", "cable"} <= set(kinds)
    elements = next(k for k in SECTIONS["model.structural"].keys if k.name == "elements")
    for classes in kinds.values():
        for cls in classes:
            assert cls.section in SECTIONS and cls.section in elements.item, cls.type
            assert SECTIONS[cls.section].type_value == cls.type


def test_a_type_without_a_kind_for_the_model_dimension_is_one_problem_at_its_key(monkeypatch) -> None:
    class PlaneOnly(ElementKind):
        type, dims, order, section = "plane_only", (2,), 99, "structural.mass"
        compiled = False

        def __init__(self) -> None:
            self.names: list[str] = []

        def read(self, entry, path, name, ctx) -> None:
            self.names.append(name)

    monkeypatch.setitem(KINDS, "plane_only", [PlaneOnly])
    load_case_dict(chain([{"type": "plane_only"}]))
    expected = r"\(1 problem\):\n  - model\.elements\[6\]\.type: a plane_only element serves models of dim 2, not 3"
    with pytest.raises(dynsens.CaseError, match=expected):
        load_case_dict(chain([{"type": "plane_only"}], dim=3))


def test_every_kind_declares_whether_it_runs_compiled() -> None:
    """Compiled or Python only is declared by each kind in its own class body: a registered kind
    without the declaration is refused, and every shipped kind has one."""
    for classes in load_kinds().values():
        for cls in classes:
            assert isinstance(cls.__dict__.get("compiled"), bool), cls.__name__

    class Undeclared(ElementKind):
        type, order, section = "undeclared", 99, "structural.mass"

    with pytest.raises(TypeError, match="Undeclared.*must declare `compiled = True`"):
        register_kind(Undeclared)
    assert "undeclared" not in KINDS


def test_the_compiled_step_serves_what_the_kinds_declare() -> None:
    assert serves(load_case_dict(chain()).model)
    nonlinear_damper = {"type": "damper", "dofs": ["u2", "ground"], "c": 1.0, "exponent": 0.5,
                        "regularization": 1e-3}
    assert not serves(load_case_dict(chain([nonlinear_damper])).model)
    cable = {"type": "cable", "nodes": ["a", "b"], "area": 1.0, "E": 1.0}
    assert not serves(load_case_dict(chain([cable])).model)       # (a cable declares no compiled step)
