"""``output.quantities``: the quantities a case records over time (validated here).

Each entry names a quantity in the case language (the same ``quantity:`` mappings responses
and events use) and how to show it::

    output:
      quantities:
        - {name: cylinder_force, quantity: {element: cylinder, kind: force}, unit: N,
           label: cylinder force}
        - {name: reaction_Z, quantity: {joint: Z, kind: reaction_force}, unit: N,
           component: [fx, fy]}                 # a subset of the components (default: all)
        - {name: stroke, quantity: {element: cylinder, kind: stroke}, unit: mm, sensitivity: true}
"""
from __future__ import annotations

import re
from typing import Any, Callable, Sequence

from ..errors import ProblemCollector
from ..case_keys import allowed
from ..models._keys import check_keys
from ..models.base import Output
from ..timeloop.records import RESERVED, QuantitySpec

QUANTITY_KEYS = allowed("output.quantity")
_IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def component_index(labels: Sequence[str], c: Any) -> int | None:
    """Index of component ``c`` among ``labels``: an index, a label in full ("Z.fx") or, where
    it names one component, its last part ("fx") or its first ("u10" of "u10.displacement");
    None when it names none.  Every key that picks a
    component (output.quantities, responses) reads it so."""
    if isinstance(c, int) and not isinstance(c, bool) and 0 <= c < len(labels):
        return c
    if c in labels:
        return list(labels).index(c)
    if not isinstance(c, str):
        return None
    for short in ([lb.rsplit(".", 1)[-1] for lb in labels], [lb.split(".", 1)[0] for lb in labels]):
        if short.count(c) == 1:
            return short.index(c)
    return None


def missing_component(labels: Sequence[str], c: Any) -> str:
    """Why :func:`component_index` found no component ``c`` among ``labels``: a short label that
    names several components is ambiguous, not missing."""
    if isinstance(c, str):
        for short in ([lb.rsplit(".", 1)[-1] for lb in labels], [lb.split(".", 1)[0] for lb in labels]):
            matches = [lb for lb, s in zip(labels, short) if s == c]
            if len(matches) > 1:
                shown = ", ".join(matches[:4]) + (", ..." if len(matches) > 4 else "")
                return f"component {c!r} is ambiguous: it names {len(matches)} components ({shown}); give a full label"
    return f"component {c!r} not found (components: {list(labels)})"


def _components(out: Output, comp: Any, path: str, pc: ProblemCollector) -> tuple[int, ...] | None:
    """Indices of the requested components (all when ``comp`` is None)."""
    if comp is None:
        return tuple(range(len(out.labels)))
    wanted = comp if isinstance(comp, list) else [comp]
    idx = []
    for c in wanted:
        i = component_index(out.labels, c)
        if i is None:
            pc.add(path, missing_component(out.labels, c))
            return None
        idx.append(i)
    return tuple(idx)


def parse_quantities(spec: Any, output_id: Callable[[Any, str], int | None], outputs: list[Output],
                     pc: ProblemCollector) -> tuple[QuantitySpec, ...]:
    """The validated ``output.quantities`` list (problems go to ``pc`` with their YAML path)."""
    if spec is None:
        return ()
    if not isinstance(spec, list):
        pc.add("output.quantities", f"expected a list of quantities, found {type(spec).__name__}")
        return ()
    out: list[QuantitySpec] = []
    names: list[str] = []
    for i, q in enumerate(spec):
        p = f"output.quantities[{i}]"
        if not check_keys(q, p, QUANTITY_KEYS, pc, required=("name", "quantity")):
            continue
        name = q.get("name")
        if not isinstance(name, str) or not _IDENT.match(name):
            pc.add(f"{p}.name", f"expected an identifier (letters, digits, _), found {name!r}")
            continue
        if name in names:
            pc.add(f"{p}.name", f"duplicate quantity {name!r}")
        elif name in RESERVED or name.endswith("_component"):
            pc.add(f"{p}.name", f"{name!r} is reserved for the result file (reserved: "
                                f"{', '.join(RESERVED)} and names ending in _component)")
        names.append(name)
        sens = q.get("sensitivity", False)
        if not isinstance(sens, bool):
            pc.add(f"{p}.sensitivity", f"expected true or false, found {sens!r}")
        for key in ("unit", "label"):
            if key in q and not isinstance(q[key], str):
                pc.add(f"{p}.{key}", f"expected text, found {q[key]!r}")
        oid = output_id(q.get("quantity"), f"{p}.quantity")
        if oid is None:
            continue
        comps = _components(outputs[oid], q.get("component"), f"{p}.component", pc)
        if comps is None:
            continue
        labels = tuple(outputs[oid].labels[c] for c in comps)
        out.append(QuantitySpec(name, oid, comps, labels, str(q.get("unit", outputs[oid].unit)),
                                str(q.get("label", name.replace("_", " "))), sens is True))
    return tuple(out)
