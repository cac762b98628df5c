"""Case entries of the aggregate responses (``ks``, ``max``, ``min``, ``stress_ratio``,
``buckling_ratio``, ``displacement_limit``): validated here, built as :class:`dynsens.responses.sizing.Aggregate`.

Every key these responses accept changes the result; any other key is an error.
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from ..case_keys import AGGREGATE_TYPES, allowed
from ..errors import ProblemCollector
from ..expressions.restricted import ExpressionError, compile_expression
from ..models._keys import check_keys
from ..models.parameters import finite_float, number_text
from ..models.base import Output
from ..responses.base import Response
from ..responses.sizing import Aggregate, GroupTerm, MagnitudeAggregate, Term
from .quantities import component_index, missing_component

__all__ = ["AGGREGATE_TYPES", "aggregate_maker"]

OutputId = Callable[[Any, str], "int | None"]


def aggregate_maker(name: str, kind: str, r: dict, path: str, output_id: OutputId,
                    outputs: list[Output], pc: ProblemCollector,
                    beams: tuple[str, ...] = ()) -> Callable[[], Response] | None:
    """Validate response entry ``r`` (at YAML ``path``) of type ``kind`` in AGGREGATE_TYPES;
    a factory of fresh :class:`Aggregate` accumulators, or None (problems reported).
    ``beams``: the model's beam names (their buckling ratio scales with the response's K²)."""
    maker = _MAKERS[kind]
    if maker is _ratio_maker:
        return _ratio_maker(name, kind, r, path, output_id, outputs, pc, beams)
    return maker(name, kind, r, path, output_id, outputs, pc)


def _extremum_maker(name: str, kind: str, r: dict, path: str, output_id: OutputId,
                    outputs: list[Output], pc: ProblemCollector) -> Callable[[], Response] | None:
    """``ks`` (smooth maximum or minimum), ``max``, ``min``: the extremum of quantities over their
    components and the run, optionally of their absolute values and divided by a ``limit``."""
    check_keys(r, path, allowed(f"response.{kind}"), pc, required=("rho",) if kind == "ks" else ())
    n0 = len(pc.problems)
    qs = _quantities(r, kind, path, pc)
    if qs is None:
        return None
    # (a single 'quantity' is reported as quantities[0], as the loader always has)
    oids = [output_id(q, f"{path}.quantities[{k}]") for k, q in enumerate(qs)]
    # (a missing rho is reported by check_keys above)
    rho = positive(r["rho"], f"{path}.rho", pc) if kind == "ks" and "rho" in r else None
    sense, absolute = _sense(r, kind, path, pc)
    limit = positive(r["limit"], f"{path}.limit", pc) if "limit" in r else 1.0
    ids = [o for o in oids if o is not None]
    if len(ids) != len(oids) or limit is None or (kind == "ks" and rho is None) or len(pc.problems) > n0:
        return None
    comps = _components(r.get("components"), [outputs[o] for o in ids], "quantities" in r,
                        f"{path}.components", pc)
    if comps is None:
        return None
    signs = [1.0, -1.0] if absolute else [1.0]
    terms = tuple(Term(o, c, np.array([[s / limit] * len(c) for s in signs])) for o, c in zip(ids, comps))
    how = "ks" if kind == "ks" else "max"
    u = _unit(r.get("unit"), "limit" in r, outputs[ids[0]])
    return lambda: Aggregate(name, terms, how, u, sense=sense, rho=rho)


def _unit(unit: Any, divided: bool, first: Output) -> str:
    """The response's unit: as given, else '-' for quantities divided by a limit, else the first quantity's."""
    return str(unit) if unit is not None else ("-" if divided else first.unit)


def _sense(r: dict, kind: str, path: str, pc: ProblemCollector) -> tuple[int, bool]:
    """(sense: 1 for a maximum, -1 for a minimum (``min``, ``side: lower``), whether of |quantity|)."""
    side = r.get("side", "upper")
    if side not in ("upper", "lower"):
        pc.add(f"{path}.side", f"expected upper (smooth maximum) or lower (smooth minimum), found {side!r}")
    absolute = r.get("absolute", False)
    if not isinstance(absolute, bool):
        pc.add(f"{path}.absolute", f"expected true or false, found {absolute!r}")
    return (-1 if kind == "min" or side == "lower" else 1), absolute


def _quantities(r: dict, kind: str, path: str, pc: ProblemCollector) -> list | None:
    """The entry's quantity specs: ``quantity`` (one) or ``quantities`` (a non-empty list)."""
    qs = r["quantities"] if "quantities" in r else [r["quantity"]] if "quantity" in r else None
    if "quantity" in r and "quantities" in r:
        pc.add(path, "give 'quantity' or 'quantities', not both")
    if not isinstance(qs, list) or not qs:
        pc.add(path, f"a {kind} response needs 'quantity' or a non-empty list 'quantities'")
        return None
    return qs


def _ratio_maker(name: str, kind: str, r: dict, path: str, output_id: OutputId,
                 outputs: list[Output], pc: ProblemCollector,
                 beams: tuple[str, ...] = ()) -> Callable[[], Response] | None:
    """``stress_ratio``: σ/σ_t (tension) and −σ/σ_c (compression), or |σ|/σ_lim (``limit``);
    ``buckling_ratio``: −N/P_E (a beam's P_E with the response's effective-length factor K);
    both aggregated over the elements and the run."""
    limits = ("tension_limit", "compression_limit", "limit") if kind == "stress_ratio" else ()
    check_keys(r, path, allowed(f"response.{kind}"), pc)
    n0 = len(pc.problems)
    how, rho = how_and_rho(r, path, pc)
    elements = r.get("elements", "all")
    side_rows: list[float] = [1.0]
    quantity_kind = "buckling"
    K = positive(r.get("effective_length_factor", 1.0), f"{path}.effective_length_factor", pc) \
        if kind == "buckling_ratio" else 1.0
    if kind == "stress_ratio":
        quantity_kind = "stress"
        read = {k: positive(r[k], f"{path}.{k}", pc) for k in limits if k in r}
        given = {k: v for k, v in read.items() if v is not None}   # a bad limit is reported above
        if "limit" in given and len(given) > 1:
            pc.add(f"{path}.limit", "give 'limit' (|σ|) or tension_limit/compression_limit, not both")
        elif not read:
            pc.add(path, "give tension_limit and/or compression_limit, or limit (|σ| <= limit)")
        if "limit" in given:
            given = {"tension_limit": given["limit"], "compression_limit": given["limit"]}
        side_rows = []
        if given.get("tension_limit"):
            side_rows.append(1.0 / given["tension_limit"])
        if given.get("compression_limit"):
            side_rows.append(-1.0 / given["compression_limit"])
    if len(pc.problems) > n0:
        return None
    n1 = len(pc.problems)
    picked = _shared_output(elements, quantity_kind, f"{path}.elements", output_id, outputs, pc)
    for p in pc.problems[n1:]:
        if p.path == f"{path}.elements.kind":   # the kind is the response type's, not a key of the case
            p.path, p.message = f"{path}.type", f"{kind} of response {name!r} reads '{quantity_kind}': {p.message}"
        elif p.path == f"{path}.elements.element":      # the quantity's key is the response's 'elements'
            p.path = f"{path}.elements"
    if picked is None or K is None:
        return None
    oid, comps = picked
    # a beam's −N/P_E is given at K = 1 (P_E ∝ 1/K²); a bar's carries its element's K already
    is_beam = np.array([outputs[oid].labels[c].split(".", 1)[0] in beams for c in comps], dtype=bool)
    scale = np.where(is_beam, K * K, 1.0)
    if "effective_length_factor" in r and not is_beam.any():
        pc.add(f"{path}.effective_length_factor", "applies to beams (a bar takes its own from its element's "
                                                  "effective_length_factor); the response names no beam")
        return None
    term = Term(oid, comps, np.array([c * scale for c in side_rows]))
    u = str(r.get("unit", "-"))
    return lambda: Aggregate(name, (term,), str(how), u, rho=rho)


def how_and_rho(r: dict, path: str, pc: ProblemCollector) -> tuple[str, float | None]:
    """``aggregate`` (ks or max) and ``rho`` (required with ks, refused with max)."""
    how = r.get("aggregate", "ks")
    if how not in ("ks", "max"):
        pc.add(f"{path}.aggregate", f"expected ks or max, found {how!r}")
    rho = None
    if how == "ks":
        rho = positive(r["rho"], f"{path}.rho", pc) if "rho" in r else None
        if "rho" not in r:
            pc.add(f"{path}.rho", "missing required key (aggregate: ks)")
    elif "rho" in r:
        pc.add(f"{path}.rho", "rho applies to 'aggregate: ks' only (the sampled maximum has none)")
    return str(how), rho


def _displacement_maker(name: str, kind: str, r: dict, path: str, output_id: OutputId, outputs: list[Output],
                        pc: ProblemCollector) -> Callable[[], Response] | None:
    """``displacement_limit`` (``kind``): |u|/limit of each node's translation vector (``nodes``) or
    of each DOF (``dofs``, both signs), aggregated over them and the run."""
    check_keys(r, path, allowed("response.displacement_limit"), pc, required=("limit",))
    n0 = len(pc.problems)
    how, rho = how_and_rho(r, path, pc)
    limit = positive(r["limit"], f"{path}.limit", pc) if "limit" in r else None
    if ("nodes" in r) == ("dofs" in r):
        pc.add(path, "give 'nodes' (length of each node's translation) or 'dofs' (|u| of each DOF), one of them")
    if len(pc.problems) > n0 or limit is None:
        return None
    terms: list[GroupTerm] = []
    if "dofs" in r:
        oid = output_id({"dof": r["dofs"], "kind": "displacement"}, f"{path}.dofs")
        if oid is not None:
            terms.append(GroupTerm(oid, np.arange(len(outputs[oid].labels))[:, None], 1.0 / limit))
    else:
        nodes = r["nodes"] if isinstance(r["nodes"], list) else [r["nodes"]]
        for k, node in enumerate(nodes):
            oid = output_id({"node": node, "kind": "displacement"}, f"{path}.nodes[{k}]")
            if oid is not None:
                terms.append(GroupTerm(oid, np.arange(len(outputs[oid].labels))[None, :], 1.0 / limit))
    if len(pc.problems) > n0 or not terms:
        return None
    u = str(r.get("unit", "-"))
    return lambda: MagnitudeAggregate(name, tuple(terms), how, u, rho=rho)


def _shared_output(elements: Any, kind: str, path: str, output_id: OutputId, outputs: list[Output],
                   pc: ProblemCollector) -> tuple[int, np.ndarray] | None:
    """The output of ``kind`` over all elements and the components of ``elements``: every ratio
    response of a case then reads one output (evaluated once per block) instead of one each.
    Falls back to the elements' own output, which reports any problem with them."""
    n0 = len(pc.problems)
    oid = output_id({"element": "all", "kind": kind}, path)
    if oid is not None and elements != "all" and isinstance(elements, (list, str)):
        wanted = elements if isinstance(elements, list) else [elements]
        labels = outputs[oid].labels
        owner = [lab.split(".", 1)[0] for lab in labels]
        if all(isinstance(w, str) for w in wanted) and set(wanted) <= set(owner):
            chosen = set(wanted)
            return oid, np.array([i for i, o in enumerate(owner) if o in chosen], dtype=int)
        oid = None
    if oid is not None and elements == "all":
        return oid, np.arange(len(outputs[oid].labels))
    del pc.problems[n0:]          # the elements' own output says what is wrong, if anything
    oid = output_id({"element": elements, "kind": kind}, path)
    return None if oid is None else (oid, np.arange(len(outputs[oid].labels)))


def positive(value: Any, path: str, pc: ProblemCollector) -> float | None:
    """A positive finite number (or a constant expression) at ``path``."""
    found = value
    if isinstance(value, str):
        try:
            value = compile_expression(value, set()).evaluate({})
        except ExpressionError:
            value = None
    v = None if isinstance(value, bool) or not isinstance(value, (int, float)) else finite_float(value)
    if v is None or v <= 0:
        pc.add(path, f"expected a positive number or a constant expression, found {number_text(found)}")
        return None
    return v


def _components(spec: Any, outs: list[Output], several: bool, path: str,
                pc: ProblemCollector) -> list[np.ndarray] | None:
    """Component indices per output: all of them without ``spec``; with one quantity a list
    of names or indices; with ``quantities`` one such list (or null: all) per quantity."""
    if spec is None:
        return [np.arange(len(o.labels)) for o in outs]
    per_output = spec if several else [spec]
    if not isinstance(per_output, list) or len(per_output) != len(outs):
        pc.add(path, f"expected one list of components per quantity ({len(outs)}), found {spec!r}")
        return None
    out = []
    for j, (sel, o) in enumerate(zip(per_output, outs)):
        p = f"{path}[{j}]" if several else path
        if sel is None:
            out.append(np.arange(len(o.labels)))
            continue
        sel = sel if isinstance(sel, list) else [sel]
        idx: list[int] = []
        given: dict[int, Any] = {}
        dup = False
        for c in sel:
            i = component_index(o.labels, c)
            if i is None:
                pc.add(p, missing_component(o.labels, c))
            elif i in given:
                # counted twice, a KS would be ln(2)/rho higher and a mean weighted
                pc.add(p, f"expected each component once, found {o.labels[i]!r} twice"
                          + (f" (as {given[i]!r} and {c!r})" if given[i] != c else ""))
                dup = True
            else:
                given[i] = c
                idx.append(i)
        if dup or len(idx) != len(sel):
            return None
        if not idx:
            pc.add(p, "expected at least one component")
            return None
        out.append(np.array(idx, dtype=int))
    return out


# one maker per aggregate type (AGGREGATE_TYPES), all called alike
_MAKERS: dict[str, Callable[[str, str, dict, str, OutputId, list[Output], ProblemCollector],
                            Callable[[], Response] | None]] = {
    "ks": _extremum_maker, "max": _extremum_maker, "min": _extremum_maker,
    "stress_ratio": _ratio_maker, "buckling_ratio": _ratio_maker, "displacement_limit": _displacement_maker}
assert set(_MAKERS) == set(AGGREGATE_TYPES)
