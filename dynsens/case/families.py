"""Families of design variables: one variable per element of a selection, in one case entry.

.. code-block:: yaml

    design:
      families:
        - name: A                       # members are named A[<element name>]
          elements: "diag*"             # all | [names] | a glob pattern of element names
          type: bar                     # element type selected (default bar)
          value: 400.0                  # shared start, bounds and scale
          lower: 50.0
          upper: 2000.0
          assign:                       # element keys set per member; 'A' stands for A[<element>]
            area: A
            inertia: "A**2*10/(8*pi)"
          members:                      # optional per-member start/bounds/scale
            diag7: {value: 600.0}

Expansion happens on the raw mapping before the model is built: each selected element's
``assign`` keys receive the expression with the family name replaced by the member's name, and
the members join the design variables after the case's own ``variables`` (in element order).
"""
from __future__ import annotations

import fnmatch
import re
from typing import Any, Callable

from ..case_keys import allowed
from ..errors import ProblemCollector
from ..models._keys import check_keys, did_you_mean

_FAMILY_KEYS = allowed("design.family")
_MEMBER_KEYS = allowed("design.family.member")
_IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_MEMBER_NAME = re.compile(r"^(?:[A-Za-z_][A-Za-z0-9_]*|[0-9]+)$")

DesignReader = Callable[[Any, ProblemCollector], "tuple[list, tuple[str, ...]]"]


def member_name(family: str, element: str) -> str:
    """The design-variable name of ``element``'s member of ``family``: ``A[diag7]``."""
    return f"{family}[{element}]"


def design_with_families(raw: dict, pc: ProblemCollector, read_design: DesignReader
                         ) -> tuple[list, tuple[str, ...]]:
    """Expand ``raw['design']['families']`` in place (member variables appended to the design
    variables, element keys assigned) and read the design with ``read_design``."""
    design = raw.get("design")
    if not isinstance(design, dict) or "families" not in design:
        return read_design(raw.get("design", {"variables": []}), pc)
    families = design.pop("families")
    if not isinstance(families, list):
        pc.add("design.families", f"expected a list of families, found {families!r}")
        families = []
    if not isinstance(design.get("variables", []) or [], list):
        return read_design(design, pc)   # the reader reports it
    own = [v.get("name") for v in design.get("variables", []) or [] if isinstance(v, dict)]
    members: list[dict] = []
    taken = set(own)
    for i, fam in enumerate(families):
        members += _expand(fam, f"design.families[{i}]", raw.get("model"), taken, pc)
    design["variables"] = list(design.get("variables", []) or []) + members
    return read_design(design, pc)


def _expand(fam: Any, path: str, model: Any, taken: set, pc: ProblemCollector) -> list[dict]:
    """The member variables of one family; assigns the selected elements' keys."""
    if not check_keys(fam, path, _FAMILY_KEYS, pc, required=("name", "value", "assign")):
        return []
    name = fam.get("name")
    if not isinstance(name, str) or not _IDENT.match(name):
        pc.add(f"{path}.name", f"expected an identifier (letters, digits, _), found {name!r}")
        return []
    if name in taken:
        pc.add(f"{path}.name", f"{name!r} is already a design variable or family")
    taken.add(name)
    assign = fam.get("assign")
    if not isinstance(assign, dict) or not assign:
        pc.add(f"{path}.assign", "expected a mapping element key -> expression of the family name")
        return []
    elements = model.get("elements", []) if isinstance(model, dict) else []
    elements = elements if isinstance(elements, list) else []
    kind = fam.get("type", "bar")
    pool = [(str(el.get("name", f"{el.get('type')}{k}")), el) for k, el in enumerate(elements)
            if isinstance(el, dict) and el.get("type") == kind]
    chosen = _select(fam.get("elements", "all"), pool, kind, f"{path}.elements", pc)
    overrides = fam.get("members", {}) or {}
    if not isinstance(overrides, dict):
        pc.add(f"{path}.members", "expected a mapping element name -> {value, lower, upper, scale}")
        overrides = {}
    chosen_names = [n for n, _ in chosen]
    for el_name, entry in overrides.items():
        if el_name not in chosen_names:
            pc.add(f"{path}.members.{el_name}", f"not a member of family {name!r}"
                                                f"{did_you_mean(el_name, chosen_names)}")
        else:
            check_keys(entry, f"{path}.members.{el_name}", _MEMBER_KEYS, pc)
    symbol = re.compile(rf"(?<![\w\]]){re.escape(name)}(?![\w\[])")
    out = []
    for el_name, el in chosen:
        if not _MEMBER_NAME.match(el_name):
            pc.add(f"{path}.elements", f"element name {el_name!r} cannot name a family member "
                                       "(use letters, digits and _)")
            continue
        member = member_name(name, el_name)
        if member in taken:
            pc.add(f"{path}.elements", f"{member!r} is already a design variable")
        taken.add(member)
        for key, expr in assign.items():
            text = str(expr) if isinstance(expr, (str, int, float)) and not isinstance(expr, bool) else None
            if text is None:
                pc.add(f"{path}.assign.{key}", f"expected an expression, found {expr!r}")
                continue
            el[key] = symbol.sub(member, text)
        var = {"name": member, **{k: fam[k] for k in ("value", "lower", "upper", "scale") if k in fam}}
        entry = overrides.get(el_name)
        where = path
        if isinstance(entry, dict):
            var.update({k: v for k, v in entry.items() if k in _MEMBER_KEYS})
            where = f"{path}.members.{el_name}"
        out.append(_checked(var, where, pc))
    return out


def _checked(var: dict, path: str, pc: ProblemCollector) -> dict:
    """The member variable, its start inside its bounds (reported here, under the family's
    path, rather than at an index of the expanded variable list)."""
    value, lo, up = var.get("value"), var.get("lower", float("-inf")), var.get("upper", float("inf"))
    if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (value, lo, up)):
        if lo >= up:
            pc.add(path, f"{var['name']}: lower >= upper ({lo} >= {up}): did you swap the bounds?")
            return {"name": var["name"], "value": 0.0}
        if not lo <= value <= up:
            pc.add(f"{path}.value", f"{var['name']}: {value} is outside the bounds [{lo}, {up}]")
            return {**var, "value": lo if value < lo else up}
    return var


def _select(spec: Any, pool: list[tuple[str, dict]], kind: str, path: str,
            pc: ProblemCollector) -> list[tuple[str, dict]]:
    """Elements named by ``spec``: ``all``, a list of names, or a glob pattern of names."""
    names = [n for n, _ in pool]
    if spec == "all":
        chosen = pool
    elif isinstance(spec, str):
        chosen = [(n, el) for n, el in pool if fnmatch.fnmatchcase(n, spec)]
    elif isinstance(spec, list):
        unknown = [s for s in spec if s not in names]
        for s in unknown:
            pc.add(path, f"no {kind} element named {s!r}{did_you_mean(s, names)}")
        wanted = set(spec)
        chosen = [(n, el) for n, el in pool if n in wanted]
    else:
        pc.add(path, f"expected all, a list of element names or a pattern such as 'diag*', found {spec!r}")
        return []
    if not chosen and not (isinstance(spec, list) and not spec):
        pc.add(path, f"selects no {kind} element (the case has {len(pool)})")
    return chosen
