"""The vocabulary of the key table: :class:`Key`, :class:`Section` and the names of the case
language's variants (response, element, force, joint and time-function types)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

# what a key takes (the schema and the reference render these):
#   number   a number                      expr     a number or an expression of the design
#   string   text                          name     an identifier-like name
#   bool     true / false                  integer  an integer
#   enum     one of ``values``             vector   a list of numbers or expressions
#   list     a list of ``item`` (a section, or a kind above)
#   map      a mapping name -> ``item``     section  the mapping ``item``
#   any      anything the loader interprets (see the meaning)
KINDS = ("number", "expr", "string", "name", "bool", "integer", "enum", "vector", "list", "map", "section", "any")
NO_DEFAULT = object()


@dataclass(frozen=True)
class Key:
    """One key of a section."""

    name: str
    kind: str
    doc: str
    required: bool = False
    default: Any = NO_DEFAULT
    values: tuple[Any, ...] = ()      # enum values
    item: str | tuple[str, ...] | None = None   # section(s) or kind of list items / map values / section
    length: int | None = None         # vectors of a fixed length


@dataclass(frozen=True)
class Section:
    """One mapping of the case language."""

    title: str
    doc: str
    keys: tuple[Key, ...]
    type_value: str | None = None     # for a variant: the value of its ``type`` key
    open_ended: bool = False          # names chosen by the user (bodies, nodes, markers) map to items
    extra: dict[str, Any] = field(default_factory=dict)


def _k(name: str, kind: str, doc: str, **kw: Any) -> Key:
    return Key(name, kind, doc, **kw)


def _req(name: str, kind: str, doc: str, **kw: Any) -> Key:
    return Key(name, kind, doc, required=True, **kw)


TIME_FUNCTION_TYPES = ("constant", "step", "ramp", "smoothstep", "harmonic", "pulse", "table")
AGGREGATE_TYPES = ("ks", "max", "min", "stress_ratio", "buckling_ratio", "displacement_limit")
RESPONSE_TYPES = ("value", *AGGREGATE_TYPES, "interaction_ratio", "integral", "event_time", "end_time", "mass",
                  "frequency", "buckling_factor", "expression")
STRUCTURAL_ELEMENT_TYPES = ("mass", "spring", "damper", "bar", "beam")
BEAM_SECTION_SHAPES = ("tube", "rectangle", "box", "properties")
JOINT_TYPES = ("revolute", "prismatic", "spherical", "cylindrical", "fixed", "planar_pin")
