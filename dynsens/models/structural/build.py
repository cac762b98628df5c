"""Build a :class:`~dynsens.models.structural.model.StructuralModel` from a case's ``model`` mapping
(``model.type: structural``): nodes and supports, DOFs, elements (each read by the set of its
kind, :mod:`.elements`), loads, initial conditions, damping."""
from __future__ import annotations

from typing import Any

from ...case_keys import allowed
from ...errors import ProblemCollector
from .._keys import check_keys, did_you_mean
from .elements import ElementKind, ReadContext, element_types, kind_class, load_kinds
from .follower import FollowerLoads
from ..parameters import ParameterTable
from ..registry import register
from .model import AXES, GROUND, StructuralModel
from ..timefunctions import build_time_function

# ---------------------------------------------------------------------- builder
_MODEL_KEYS = allowed("model.structural")


@register("structural")
def build_structural(spec: dict, path: str, table: ParameterTable,
                     problems: ProblemCollector) -> StructuralModel | None:
    """Build a :class:`StructuralModel` from the case's ``model`` mapping."""
    n_before = len(problems.problems)
    check_keys(spec, path, _MODEL_KEYS, problems)
    dim = spec.get("dim", 2)
    if dim not in (2, 3):
        problems.add(f"{path}.dim", f"must be 2 or 3, found {dim!r}")
        dim = 2
    dofs = _Dofs(spec, path, dim, table, problems)
    ctx = ReadContext(dim, table, problems, dofs.node_coords, dofs.dof, dofs.node_dofs, dofs.beam_dofs,
                      dofs.given_coords)
    sets = _read_elements(spec, path, ctx, dofs)
    loads, followers = _read_loads(spec, path, ctx, dofs)
    init_lists = _read_initial(spec, path, ctx)
    rayleigh, corotated = _read_damping(spec, path, table, problems)
    la = spec.get("linear_algebra", "auto")
    if la not in ("auto", "dense", "sparse"):
        problems.add(f"{path}.linear_algebra", f"expected auto, dense or sparse, found {la!r}")
    if dofs.n == 0:
        problems.add(path, "the model has no free degrees of freedom")
    massed = {d for k in sets for d in k.dofs()}
    for i, d in enumerate(dofs.names):
        if i not in massed:
            problems.add(f"{path}.elements", f"dof {d!r} has no mass (add a mass or a bar density)")
    try:
        model = StructuralModel(dof_names=dofs.names, table=table, sets=sets, dim=dim,
                                node_coords=dofs.node_coords, loads=loads, initial=init_lists, rayleigh=rayleigh,
                                rayleigh_corotated=corotated is True,
                                sparse=None if la == "auto" else la == "sparse", followers=followers)
    except (ValueError, IndexError, TypeError, KeyError):
        if len(problems.problems) > n_before:
            return None  # the problems already listed explain why it cannot be assembled
        raise
    model.equation_sources = dofs.sources
    # with problems listed, the model is still returned so that the responses can be checked
    # against its DOFs and elements; the loader raises before anything runs
    return model


class _Dofs:
    """The model's DOFs: scalar ones, and those of its nodes (translations; rotations at beam
    nodes), minus the fixed ones; name lookups that report unknown names."""

    def __init__(self, spec: dict, path: str, dim: int, table: ParameterTable, problems: ProblemCollector):
        self.dim, self.problems = dim, problems
        self.names: list[str] = []
        self.fixed: set[str] = set()
        scalar = spec.get("dofs", [])
        if not isinstance(scalar, list) or not all(isinstance(d, str) for d in scalar):
            problems.add(f"{path}.dofs", f"expected a list of DOF names, found {scalar!r}")
            scalar = []
        self.names += scalar
        self.node_coords: dict[str, list[int]] = {}
        self.rotating = _beam_nodes(spec.get("elements"))   # nodes that carry rotations (beams)
        self.rotations = ["rz"] if dim == 2 else ["rx", "ry", "rz"]
        nodes = spec.get("nodes", {}) or {}
        if not isinstance(nodes, dict):
            problems.add(f"{path}.nodes", "expected a mapping node name -> {coords, fixed}")
            nodes = {}
        self.given_coords = {k: nd.get("coords") for k, nd in nodes.items() if isinstance(nd, dict)}
        for name, nd in nodes.items():
            self._node(name, nd, f"{path}.nodes.{name}", table)
        if len(set(self.names)) != len(self.names):
            problems.add(f"{path}.dofs", "DOF names must be unique")
        self.n = len(self.names)
        self.index = {d: i for i, d in enumerate(self.names)}
        # which YAML entries act on each DOF: run-time errors name them (Model.describe_equation)
        self.sources: list[tuple[str, list[int]]] = []

    def _node(self, name: str, nd: Any, npath: str, table: ParameterTable) -> None:
        problems, dim = self.problems, self.dim
        if not check_keys(nd, npath, allowed("structural.node"), problems, required=("coords",)):
            return
        self.node_coords[name] = table.add_many(nd.get("coords", [0] * dim), f"{npath}.coords", problems,
                                                length=dim)
        fx = nd.get("fixed", [])
        axes = list(AXES[:dim]) + (self.rotations if name in self.rotating else [])
        if fx is True or fx == "all":
            fx = axes
        if not isinstance(fx, list) or any(a not in axes for a in fx):
            problems.add(f"{npath}.fixed", f"expected a list of axes from {axes} or 'all', found {fx!r}")
            fx = []
        for a in axes:
            (self.fixed.add if a in fx else self.names.append)(f"{name}.{a}")

    def dof(self, name: Any, p: str) -> int:
        n = self.n
        if not isinstance(name, str):
            self.problems.add(p, f"expected a DOF name, found {name!r}")
            return n
        if name == GROUND or name in self.fixed:
            return n
        if name not in self.index:
            self.problems.add(p, f"unknown dof {name!r}{did_you_mean(name, list(self.index) + [GROUND])}")
            return n
        return self.index[name]

    def node_dofs(self, name: Any, p: str) -> list[int]:
        if not isinstance(name, str) or name not in self.node_coords:
            self.problems.add(p, f"unknown node {name!r}{did_you_mean(name, self.node_coords)}")
            return [self.n] * self.dim
        return [self.dof(f"{name}.{a}", p) for a in AXES[:self.dim]]

    def beam_dofs(self, name: Any, p: str) -> list[int]:
        """(x, y, θz) of a plane beam node; (x, y, z, θx, θy, θz) in 3D."""
        return self.node_dofs(name, p) + ([self.dof(f"{name}.{a}", p) for a in self.rotations]
                                          if name in self.node_coords else [self.n] * len(self.rotations))

    def touched(self, entry: dict) -> list[int]:
        """DOFs an element or load names (silently: its own checks report bad names)."""
        names: list[str] = []
        for key in ("dof", "dofs", "node", "nodes"):
            v = entry.get(key)
            for item in (v if isinstance(v, list) else [v]):
                if isinstance(item, str):
                    names += [f"{item}.{a}" for a in (*AXES[:self.dim], "rx", "ry", "rz")] \
                        if key.startswith("node") else [item]  # (rotations a node lacks are not in the index)
        return [self.index[d] for d in names if d in self.index]


def _read_elements(spec: dict, path: str, ctx: ReadContext, dofs: _Dofs) -> list[ElementKind]:
    """Every ``elements[i]`` entry read into the set of its kind (one set per registered kind)."""
    problems = ctx.problems
    sets = {cls: cls() for classes in load_kinds().values() for cls in classes if ctx.dim in cls.dims}
    names_seen: set[str] = set()
    elements = spec.get("elements", [])
    if not isinstance(elements, list):
        problems.add(f"{path}.elements", "expected a list")
        elements = []
    for k, el in enumerate(elements):
        ep = f"{path}.elements[{k}]"
        if not isinstance(el, dict):
            problems.add(ep, f"expected a mapping, found {el!r}")
            continue
        kind = el.get("type")
        name = str(el.get("name", f"{kind}{k}"))
        dofs.sources.append((f"{ep} ({kind} '{name}')", dofs.touched(el)))
        if name in names_seen:
            problems.add(f"{ep}.name", f"duplicate element name {name!r}")
        names_seen.add(name)
        cls = kind_class(kind, ctx.dim)
        if cls is None and kind in element_types():
            dims = sorted({d for c in load_kinds()[kind] for d in c.dims})
            problems.add(f"{ep}.type", f"a {kind} element serves models of dim {' or '.join(map(str, dims))}, "
                                       f"not {ctx.dim}")
            continue
        if cls is None:
            kinds = element_types()
            problems.add(f"{ep}.type", f"unknown element type {kind!r}{did_you_mean(kind, kinds)} "
                                       f"(known: {', '.join(kinds)})")
            continue
        sets[cls].read(el, ep, name, ctx)
    return list(sets.values())


def _read_loads(spec: dict, path: str, ctx: ReadContext, dofs: _Dofs
                ) -> tuple[list[tuple[int, int, Any]], FollowerLoads]:
    """The loads: value · function(t) on a DOF or a node direction, or following a node."""
    problems, table, dim = ctx.problems, ctx.table, ctx.dim
    loads = []
    followers = FollowerLoads()
    load_specs = spec.get("loads", []) or []
    if not isinstance(load_specs, list):
        problems.add(f"{path}.loads", f"expected a list of loads, found {load_specs!r}")
        load_specs = []
    for k, ld in enumerate(load_specs):
        lp = f"{path}.loads[{k}]"
        if not check_keys(ld, lp, allowed("structural.load"), problems, required=("value",)):
            continue
        if ld.get("follower", False) is not False and dim == 3:
            problems.add(f"{lp}.follower", "follower loads act in plane models (dim: 2) only, so far")
            continue
        dofs.sources.append((f"{lp} (load)", dofs.touched(ld)))
        if ld.get("follower", False) is not False:
            _follower(ld, lp, dofs.rotating, dofs.beam_dofs, table, followers, problems)
            continue
        target = _load_target(ld, lp, dofs)
        if target is None:
            continue
        amp = table.add(ld.get("value"), f"{lp}.value", problems)
        fn = build_time_function(ld.get("function"), f"{lp}.function", table, problems)
        if fn is not None:
            loads.append((target, amp, fn))
    return loads, followers


def _load_target(ld: dict, lp: str, dofs: _Dofs) -> int | None:
    """The DOF a load acts on (``dof``, or ``node`` + ``direction``), or None with a problem listed."""
    if "dof" in ld:
        return dofs.dof(ld["dof"], f"{lp}.dof")
    if "node" not in ld:
        dofs.problems.add(lp, "a load needs 'dof' or 'node' + 'direction'")
        return None
    direction = ld.get("direction")
    directions = list(AXES[:dofs.dim]) + (dofs.rotations if ld["node"] in dofs.rotating else [])
    if direction not in directions:
        dofs.problems.add(f"{lp}.direction", f"expected one of {directions}, found {direction!r}")
        return None
    return dofs.node_dofs(ld["node"], f"{lp}.node")[AXES.index(direction)] if direction in AXES else \
        dofs.beam_dofs(ld["node"], f"{lp}.node")[directions.index(direction)]


def _read_initial(spec: dict, path: str, ctx: ReadContext
                  ) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """Initial displacements and velocities: (DOF, parameter index) pairs."""
    problems = ctx.problems
    init = spec.get("initial", {}) or {}
    init_lists: tuple[list[tuple[int, int]], list[tuple[int, int]]] = ([], [])
    if check_keys(init, f"{path}.initial", allowed("structural.initial"), problems):
        for j, key in enumerate(("displacement", "velocity")):
            entries = init.get(key, {}) or {}
            if not isinstance(entries, dict):
                problems.add(f"{path}.initial.{key}", "expected a mapping dof -> value")
                continue
            for d, v in entries.items():
                ip = f"{path}.initial.{key}.{d}"
                di = ctx.dof(d, ip)
                init_lists[j].append((di, ctx.table.add(v, ip, problems)))
    return init_lists


def _read_damping(spec: dict, path: str, table: ParameterTable, problems: ProblemCollector
                  ) -> tuple[tuple[int, int] | None, Any]:
    """Rayleigh damping: (α, β parameter indices) or None, and whether β K is co-rotated."""
    rayleigh, corotated = None, True
    damping = spec.get("damping")
    if damping is not None and check_keys(damping, f"{path}.damping", allowed("structural.damping"), problems):
        ry = damping.get("rayleigh")
        if check_keys(ry, f"{path}.damping.rayleigh", allowed("structural.rayleigh"), problems):
            rayleigh = (table.add(ry.get("alpha", 0.0), f"{path}.damping.rayleigh.alpha", problems, nonnegative=True),
                        table.add(ry.get("beta", 0.0), f"{path}.damping.rayleigh.beta", problems, nonnegative=True))
            corotated = ry.get("corotated", True)
            if not isinstance(corotated, bool):
                problems.add(f"{path}.damping.rayleigh.corotated", f"expected true or false, found {corotated!r}")
    return rayleigh, corotated


def _beam_nodes(elements: Any) -> set[str]:
    """Names of the nodes that beams connect (they carry a rotation DOF)."""
    if not isinstance(elements, list):
        return set()
    return {str(nd) for el in elements if isinstance(el, dict) and el.get("type") == "beam"
            and isinstance(el.get("nodes"), list) for nd in el["nodes"]}


def _follower(ld: dict, lp: str, rotating: set[str], beam_dofs: Any, table: ParameterTable,
              followers: FollowerLoads, problems: ProblemCollector) -> None:
    """A ``follower: true`` load: along the local x or y axis of a node that rotates (a beam node)."""
    if ld.get("follower") is not True:
        problems.add(f"{lp}.follower", f"expected true or false, found {ld.get('follower')!r}")
        return
    node, direction = ld.get("node"), ld.get("direction")
    if node not in rotating:
        problems.add(f"{lp}.node", f"a follower load needs a node with a rotation (a beam node), found {node!r}")
        return
    if direction not in ("x", "y"):
        problems.add(f"{lp}.direction", f"a follower force acts along the node's local x or y, found {direction!r}")
        return
    fn = build_time_function(ld.get("function"), f"{lp}.function", table, problems)
    if fn is None:
        return
    followers.dofs.append(tuple(beam_dofs(node, f"{lp}.node")))
    followers.local.append((1.0, 0.0) if direction == "x" else (0.0, 1.0))
    followers.amp.append(table.add(ld.get("value"), f"{lp}.value", problems))
    followers.fn.append(fn)
