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
``assign`` may set only the numeric entries (expressions) of the selected element type, a beam's
section dimensions and properties as dotted keys (``section.D``, ``section.h``, ``section.Iy``;
those of the member's shape, 2D or 3D), over a
placeholder that must itself be a number or an expression; a problem the model or the start
design finds in an assigned entry is reported once, at the family's ``assign`` key, naming the
members concerned (:func:`fold_assigned_problems`).
"""
from __future__ import annotations

import fnmatch
import re
from typing import Any, Callable

from ..case_keys import SECTIONS, allowed
from ..errors import Problem, ProblemCollector
from ..expressions.restricted import RESERVED_NAMES
from ..models._keys import check_keys, did_you_mean
from ..models.structural.beams import SHAPES
from ..models.structural.beams3d import SHAPES3
from .checks import bounds_problem, reserved_message
from .responses_spec import read_number

_FAMILY_KEYS = allowed("design.family")
_MEMBER_KEYS = allowed("design.family.member")
_IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_MEMBER_NAME = re.compile(r"^(?:[A-Za-z_][A-Za-z0-9_]*|[0-9]+)$")

DesignReader = Callable[[Any, ProblemCollector], "tuple[list, tuple[str, ...]]"]
#: element key path (model.elements[3].area) -> (the family's assign path, the member set there)
Assigned = dict[str, tuple[str, str]]
_NUMBERS = ("value", "lower", "upper", "scale")


def member_name(family: str, element: str) -> str:
    """The design-variable name of ``element``'s member of ``family``: ``A[diag7]``."""
    return f"{family}[{element}]"


def member_parts(name: str) -> tuple[str, str] | None:
    """(family, element) of a member's design-variable name (``A[diag7]`` -> ("A", "diag7")),
    the inverse of :func:`member_name`; None for a variable of no family."""
    if not name.endswith("]") or "[" not in name:
        return None
    family, element = name[:-1].split("[", 1)
    return family, element


def design_with_families(raw: dict, pc: ProblemCollector, read_design: DesignReader
                         ) -> tuple[list, tuple[str, ...], Assigned]:
    """Expand ``raw['design']['families']`` in place (member variables appended to the design
    variables, element keys assigned) and read the design with ``read_design``; also returns
    where each family assigned an element key (for :func:`fold_assigned_problems`)."""
    design = raw.get("design")
    assigned: Assigned = {}
    if not isinstance(design, dict) or "families" not in design:
        return (*read_design(raw.get("design", {"variables": []}), pc), assigned)
    families = design.pop("families")
    if not isinstance(families, list):
        pc.add("design.families", f"expected a list of families, found {families!r}")
        families = []
    if not isinstance(design.get("variables", []) or [], list):
        return (*read_design(design, pc), assigned)   # the reader reports it
    own = [v.get("name") for v in design.get("variables", []) or [] if isinstance(v, dict)]
    members: list[dict] = []
    taken = set(own)
    for i, fam in enumerate(families):
        members += _expand(fam, f"design.families[{i}]", raw.get("model"), taken, assigned, pc)
    design["variables"] = list(design.get("variables", []) or []) + members
    return (*read_design(design, pc), assigned)


def fold_assigned_problems(pc: ProblemCollector, assigned: Assigned, start: int = 0) -> None:
    """Problems at element keys a family assigned (from problem ``start`` on: those found in the
    expanded model) become one problem per ``assign`` key, at that path: the first member's
    message, then the other members where the entry also fails (the user wrote the entry once,
    in the family, not at the expanded element)."""
    out: list[Problem] = pc.problems[:start]
    groups: dict[str, tuple[Problem, list[str]]] = {}
    for p in pc.problems[start:]:
        hit = assigned.get(p.path)
        if hit is None:
            out.append(p)
        elif hit[0] in groups:
            groups[hit[0]][1].append(hit[1])
        else:
            groups[hit[0]] = (Problem(hit[0], f"{hit[1]} ({p.path}): {p.message}"), [])
            out.append(groups[hit[0]][0])
    for first, more in groups.values():
        if more:
            first.message += (f"; this entry also fails for {len(more)} more member{'s' if len(more) > 1 else ''}"
                              f" ({', '.join(more[:5])}{', ...' if len(more) > 5 else ''})")
    pc.problems = out


def _numeric_keys(kind: Any) -> list[str] | None:
    """The keys ``assign`` may set on an element of type ``kind``: its numeric entries
    (``area``) and those of its sub-sections as dotted paths (``section.D``, ``section.Iy``);
    None for an unknown type (reported by the model)."""
    section = SECTIONS.get(f"structural.{kind}")
    if section is None:
        return None
    out = []
    for k in section.keys:
        if k.kind == "expr":
            out.append(k.name)
        elif k.kind == "section" and isinstance(k.item, str) and k.item in SECTIONS:
            out += [f"{k.name}.{sub.name}" for sub in SECTIONS[k.item].keys if sub.kind == "expr"]
    return out


def _assignable(assign: Any, kind: Any, path: str, pc: ProblemCollector) -> dict[str, str]:
    """The ``assign`` entries as text, each checked once: a numeric entry (expression) of element
    type ``kind`` (not its name, nodes or type), or of its section (``section.D``), set to a
    number or an expression."""
    if not isinstance(assign, dict) or not assign:
        pc.add(path, "expected a mapping element key -> expression of the family name")
        return {}
    numeric = _numeric_keys(kind)
    out = {}
    for key, expr in assign.items():
        if numeric is not None and key not in numeric:
            head = str(key).split(".")[0]
            what = "not a numeric entry" if head in allowed(f"structural.{kind}") else "unknown key"
            pc.add(f"{path}.{key}", f"{what} of a {kind} element{did_you_mean(str(key), numeric)} "
                                    f"(assign sets one of: {', '.join(numeric)})")
        elif isinstance(expr, bool) or not isinstance(expr, (str, int, float)):
            pc.add(f"{path}.{key}", f"expected an expression of the family name, found {expr!r}")
        else:
            out[str(key)] = str(expr)
    return out


def _section_dimensions(kind: str, dim: Any, sec: dict) -> tuple[str, tuple[str, ...]] | None:
    """The shape of a beam's section and the dimensions it takes (2D or 3D); None when the shape
    is unknown (the model reports it)."""
    if kind != "beam":
        return None
    shapes = SHAPES3 if dim == 3 else SHAPES
    shape = sec.get("shape", "properties")
    return (shape, shapes[shape]) if isinstance(shape, str) and shape in shapes else None


def _target(el: dict, key: str, kind: str, dim: Any, ep: str) -> tuple[dict, str] | str:
    """The mapping and key that ``assign``'s ``key`` sets on element ``el`` (the element itself,
    or its section for ``section.D``), or why it cannot be set there (expected, found)."""
    if "." not in key:
        return el, key
    head, sub = key.split(".", 1)
    sec = el.get(head)
    if not isinstance(sec, dict):
        return (f"expected {ep}.{head} to be a mapping with a shape whose dimension {sub} the family "
                f"sizes, found {sec!r}")
    dims = _section_dimensions(kind, dim, sec)
    if dims is not None and sub not in dims[1]:
        plane = "3D" if dim == 3 else "2D"
        return (f"expected a dimension of the {dims[0]} section of a {plane} {kind} ({', '.join(dims[1])}) "
                f"at {ep}.{head}, found {sub}")
    return sec, sub


def _numbers(spec: dict, keys: tuple[str, ...], path: str, pc: ProblemCollector) -> dict[str, float] | None:
    """The numbers among ``keys`` of ``spec`` read once (not again for every member); None on a problem."""
    n0 = len(pc.problems)
    out = {k: read_number(spec[k], f"{path}.{k}", pc, positive=k == "scale") for k in keys if k in spec}
    return None if len(pc.problems) > n0 else out  # type: ignore[return-value]


def _expand(fam: Any, path: str, model: Any, taken: set, assigned: Assigned,
            pc: ProblemCollector) -> list[dict]:
    """The member variables of one family; assigns the selected elements' keys."""
    if not check_keys(fam, path, _FAMILY_KEYS, pc, required=("name", "value", "assign")):
        return []
    name = _family_name(fam.get("name"), path, taken, pc)
    if name is None:
        return []
    kind = fam.get("type", "bar")
    assign = _assignable(fam.get("assign"), kind, f"{path}.assign", pc)
    shared = _numbers(fam, _NUMBERS, path, pc)
    if not assign or shared is None:
        return []
    elements = model.get("elements", []) if isinstance(model, dict) else []
    elements = elements if isinstance(elements, list) else []
    index = {id(el): k for k, el in enumerate(elements)}
    pool = [(str(el.get("name", f"{el.get('type')}{k}")), el) for k, el in enumerate(elements)
            if isinstance(el, dict) and el.get("type") == kind]
    chosen = _select(fam.get("elements", "all"), pool, kind, f"{path}.elements", pc)
    overrides = _member_overrides(fam.get("members", {}) or {}, name, [n for n, _ in chosen], path, pc)
    symbol = re.compile(rf"(?<![\w\]]){re.escape(name)}(?![\w\[])")
    dim = model.get("dim", 2) if isinstance(model, dict) else 2
    misfits: dict[str, list[tuple[str, str]]] = {}     # assign key -> (member, why) it cannot be set
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
        ep = f"model.elements[{index[id(el)]}]"
        for key, text in assign.items():
            target = _target(el, key, kind, dim, ep)
            if isinstance(target, str):
                misfits.setdefault(key, []).append((member, target))
            else:
                _assign_key(target, symbol.sub(member, text), f"{ep}.{key}", path, pc)
                assigned[f"{ep}.{key}"] = (f"{path}.assign.{key}", member)
        out.append(_member_variable(member, shared, overrides.get(el_name), f"{path}.members.{el_name}", path, pc))
    _report_misfits(misfits, path, pc)
    return out


def _family_name(name: Any, path: str, taken: set, pc: ProblemCollector) -> str | None:
    """The family's name, now taken; None when it cannot be one (reported)."""
    if not isinstance(name, str) or not _IDENT.match(name):
        pc.add(f"{path}.name", f"expected an identifier (letters, digits, _), found {name!r}")
        return None
    if name in RESERVED_NAMES:      # its expressions would read the constant or function
        pc.add(f"{path}.name", reserved_message(name))
        return None
    if name in taken:
        pc.add(f"{path}.name", f"{name!r} is already a design variable or family")
    taken.add(name)
    return name


def _member_overrides(overrides: Any, name: str, chosen_names: list[str], path: str,
                      pc: ProblemCollector) -> dict:
    """``members``: element name -> its own value, bounds or scale; each must name a member."""
    if not isinstance(overrides, dict):
        pc.add(f"{path}.members", "expected a mapping element name -> {value, lower, upper, scale}")
        return {}
    for el_name, entry in overrides.items():
        if el_name not in chosen_names:
            pc.add(f"{path}.members.{el_name}", f"not a member of family {name!r}"
                                                f"{did_you_mean(el_name, chosen_names)}")
        else:
            check_keys(entry, f"{path}.members.{el_name}", _MEMBER_KEYS, pc)
    return overrides


def _assign_key(target: tuple[dict, str], text: str, key_path: str, path: str, pc: ProblemCollector) -> None:
    """Writes the member's expression ``text`` into its element's key (``key_path``)."""
    where_set, sub = target
    old = where_set.get(sub)      # a placeholder (the tower's 'area: 1.0'): replaced, yet of the key's kind
    if sub in where_set and (isinstance(old, bool) or not isinstance(old, (str, int, float))):
        pc.add(key_path, f"expected a number or an expression (a placeholder that "
                         f"{path}.assign replaces), found {old!r}")
    where_set[sub] = text


def _member_variable(member: str, shared: dict, entry: Any, entry_path: str, path: str,
                     pc: ProblemCollector) -> dict:
    """The member's design variable: the family's numbers, with the member's own where given."""
    var = {"name": member, **shared}
    where = path
    if isinstance(entry, dict):
        where = entry_path
        var.update(_numbers(entry, _MEMBER_KEYS, where, pc) or {})   # a problem: reported, shared kept
    family_bounds = (shared.get("lower", float("-inf")), shared.get("upper", float("inf")))
    return _checked(var, where, family_bounds, pc)


def _report_misfits(misfits: dict[str, list[tuple[str, str]]], path: str, pc: ProblemCollector) -> None:
    """One problem per assign key that some members cannot take, not one per member."""
    for key, misses in misfits.items():
        more = [m for m, _ in misses[1:]]
        pc.add(f"{path}.assign.{key}", f"{misses[0][0]}: {misses[0][1]}"
               + (f"; also for {len(more)} more member{'s' if len(more) > 1 else ''} "
                  f"({', '.join(more[:5])}{', ...' if len(more) > 5 else ''})" if more else ""))


def _checked(var: dict, path: str, family_bounds: tuple[float, float], pc: ProblemCollector) -> dict:
    """The member variable, its start inside its bounds (reported here, under the family's
    path, rather than at an index of the expanded variable list); bounds that are the family's
    own (``family_bounds``) are reported without the member's name, once."""
    value, lo, up = var["value"], var.get("lower", float("-inf")), var.get("upper", float("inf"))
    why = bounds_problem(lo, up)
    if why:
        if (lo, up) != family_bounds:
            pc.add(path, f"{var['name']}: {why}")
        elif not any(p.path == path and p.message == why for p in pc.problems):
            pc.add(path, why)           # the family's own bounds: one problem for all its members
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
