"""Build a :class:`~dynsens.models.structural.StructuralModel` from a case's ``model`` mapping
(``model.type: structural``): nodes and supports, DOFs, elements, loads, initial conditions,
damping."""
from __future__ import annotations

from typing import Any

from ..case_keys import STRUCTURAL_ELEMENT_TYPES, allowed
from ..errors import ProblemCollector
from ._keys import check_keys, did_you_mean
from .parameters import ParameterTable
from .beams import BeamSet, parse_beam
from .beams3d import Beam3DSet, parse_beam_3d
from .dampers import NonlinearDampers
from .follower import FollowerLoads
from .registry import register
from .structural import AXES, GROUND, StructuralModel, _Group
from .timefunctions import build_time_function

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
    dof_names: list[str] = []
    fixed: set[str] = set()
    scalar = spec.get("dofs", [])
    if not isinstance(scalar, list) or not all(isinstance(d, str) for d in scalar):
        problems.add(f"{path}.dofs", f"expected a list of DOF names, found {scalar!r}")
        scalar = []
    dof_names += scalar
    node_coords: dict[str, list[int]] = {}
    rotating = _beam_nodes(spec.get("elements"))   # nodes that carry rotations (beams)
    rotations = ["rz"] if dim == 2 else ["rx", "ry", "rz"]
    nodes = spec.get("nodes", {}) or {}
    if not isinstance(nodes, dict):
        problems.add(f"{path}.nodes", "expected a mapping node name -> {coords, fixed}")
        nodes = {}
    for name, nd in nodes.items():
        npath = f"{path}.nodes.{name}"
        if not check_keys(nd, npath, allowed("structural.node"), problems, required=("coords",)):
            continue
        node_coords[name] = table.add_many(nd.get("coords", [0] * dim), f"{npath}.coords", problems, length=dim)
        fx = nd.get("fixed", [])
        axes = list(AXES[:dim]) + (rotations if name in rotating else [])
        if fx is True or fx == "all":
            fx = axes
        if not isinstance(fx, list) or any(a not in axes for a in fx):
            problems.add(f"{npath}.fixed", f"expected a list of axes from {axes} or 'all', found {fx!r}")
            fx = []
        for a in axes:
            (fixed.add if a in fx else dof_names.append)(f"{name}.{a}")
    if len(set(dof_names)) != len(dof_names):
        problems.add(f"{path}.dofs", "DOF names must be unique")
    n = len(dof_names)
    index = {d: i for i, d in enumerate(dof_names)}

    def dof(name: Any, p: str) -> int:
        if not isinstance(name, str):
            problems.add(p, f"expected a DOF name, found {name!r}")
            return n
        if name == GROUND or name in fixed:
            return n
        if name not in index:
            problems.add(p, f"unknown dof {name!r}{did_you_mean(name, list(index) + [GROUND])}")
            return n
        return index[name]

    def node_dofs(name: Any, p: str) -> list[int]:
        if not isinstance(name, str) or name not in node_coords:
            problems.add(p, f"unknown node {name!r}{did_you_mean(name, node_coords)}")
            return [n] * dim
        return [dof(f"{name}.{a}", p) for a in AXES[:dim]]

    def beam_dofs(name: Any, p: str) -> list[int]:
        """(x, y, θz) of a plane beam node; (x, y, z, θx, θy, θz) in 3D."""
        return node_dofs(name, p) + ([dof(f"{name}.{a}", p) for a in rotations] if name in node_coords
                                     else [n] * len(rotations))

    mass_terms: list[tuple[int, int]] = []
    springs, dampers, bars = _Group(), _Group(), _Group()
    beams = BeamSet()
    frames = Beam3DSet()
    nl_dampers = NonlinearDampers()
    bar_nodes: list[tuple[str, str]] = []
    names_seen: set[str] = set()
    spring_nonlinear = False
    zero_index = -1
    elements = spec.get("elements", [])
    if not isinstance(elements, list):
        problems.add(f"{path}.elements", "expected a list")
        elements = []
    kinds = STRUCTURAL_ELEMENT_TYPES
    # which YAML entries act on each DOF: run-time errors name them (Model.describe_equation)
    sources: list[tuple[str, list[int]]] = []

    def touched(entry: dict) -> list[int]:
        """DOFs an element or load names (silently: its own checks report bad names)."""
        names: list[str] = []
        for key in ("dof", "dofs", "node", "nodes"):
            v = entry.get(key)
            for item in (v if isinstance(v, list) else [v]):
                if isinstance(item, str):
                    names += [f"{item}.{a}" for a in (*AXES[:dim], "rx", "ry", "rz")] if key.startswith("node") \
                        else [item]      # (rotations a node does not carry are not in the index)
        return [index[d] for d in names if d in index]

    for k, el in enumerate(elements):
        ep = f"{path}.elements[{k}]"
        if not isinstance(el, dict):
            problems.add(ep, f"expected a mapping, found {el!r}")
            continue
        kind = el.get("type")
        name = str(el.get("name", f"{kind}{k}"))
        sources.append((f"{ep} ({kind} '{name}')", touched(el)))
        if name in names_seen:
            problems.add(f"{ep}.name", f"duplicate element name {name!r}")
        names_seen.add(name)
        if kind == "mass":
            check_keys(el, ep, allowed("structural.mass"), problems, required=("mass",))
            pi = table.add(el.get("mass"), f"{ep}.mass", problems, positive=True)
            targets = [dof(el["dof"], f"{ep}.dof")] if "dof" in el else \
                node_dofs(el.get("node"), f"{ep}.node") if "node" in el else []
            if not targets:
                problems.add(ep, "a mass needs 'dof' or 'node'")
            mass_terms += [(d, pi) for d in targets]
        elif kind in ("spring", "damper"):
            keys = allowed(f"structural.{kind}")
            check_keys(el, ep, keys, problems, required=("dofs", "k" if kind == "spring" else "c"))
            pair = el.get("dofs", [])
            if not isinstance(pair, list) or len(pair) not in (1, 2):
                problems.add(f"{ep}.dofs", f"expected [dof] or [dof_a, dof_b|ground], found {pair!r}")
                continue
            n_known = len(problems.problems)
            ids = [dof(d, f"{ep}.dofs") for d in pair] + ([n] if len(pair) == 1 else [])
            if ids[0] == ids[1] and len(problems.problems) == n_known:
                problems.add(f"{ep}.dofs", f"expected a {kind} between two different DOFs (or a DOF and ground), "
                                           f"found {pair!r}: " + ("it would act on ground (or fixed DOFs) only"
                                                                  if ids[0] == n else "both ends are one DOF"))
                continue
            if kind == "spring":
                higher = {}
                for key in ("k2", "k3"):
                    if key in el:
                        spring_nonlinear = True
                        higher[key] = table.add(el[key], f"{ep}.{key}", problems)
                    else:
                        if zero_index < 0:
                            zero_index = table.add(0.0, "", problems)
                        higher[key] = zero_index
                springs.add(name, ids, k1=table.add(el.get("k"), f"{ep}.k", problems), **higher)
            elif "exponent" in el or "regularization" in el:
                if "exponent" not in el or "regularization" not in el:
                    problems.add(ep, "a nonlinear damper needs 'exponent' (α) and 'regularization' (velocity ε > 0)")
                    continue
                nl_dampers.names.append(name)
                nl_dampers.dofs.append(ids)
                nl_dampers.c.append(table.add(el.get("c"), f"{ep}.c", problems, nonnegative=True))
                nl_dampers.alpha.append(table.add(el["exponent"], f"{ep}.exponent", problems, positive=True))
                nl_dampers.eps.append(table.add(el["regularization"], f"{ep}.regularization", problems, positive=True))
            else:
                dampers.add(name, ids, c=table.add(el.get("c"), f"{ep}.c", problems, nonnegative=True))
        elif kind == "bar":
            check_keys(el, ep, allowed("structural.bar"), problems, required=("nodes", "area", "E"))
            pair = el.get("nodes", [])
            if not isinstance(pair, list) or len(pair) != 2:
                problems.add(f"{ep}.nodes", f"expected [node_a, node_b], found {pair!r}")
                continue
            ids = node_dofs(pair[0], f"{ep}.nodes") + node_dofs(pair[1], f"{ep}.nodes")
            bars.add(name, ids, A=table.add(el.get("area"), f"{ep}.area", problems, positive=True),
                     E=table.add(el.get("E"), f"{ep}.E", problems, positive=True),
                     rho=table.add(el.get("density", 0.0), f"{ep}.density", problems, nonnegative=True),
                     I=table.add(el["inertia"], f"{ep}.inertia", problems, positive=True) if "inertia" in el else -1,
                     K=table.add(el.get("effective_length_factor", 1.0), f"{ep}.effective_length_factor",
                                 problems, positive=True))
            bar_nodes.append((pair[0], pair[1]))
        elif kind == "beam" and dim == 3:
            parse_beam_3d(el, ep, name, frames, table, beam_dofs, node_coords, problems,
                          {k: nd.get("coords") for k, nd in nodes.items() if isinstance(nd, dict)})
        elif kind == "beam":
            for key in ("G", "orientation", "kinematics"):
                if key in el:
                    problems.add(f"{ep}.{key}", f"'{key}' belongs to 3D beams (dim: 3); a plane beam has none")
            parse_beam(el, ep, name, beams, table, beam_dofs, node_coords, problems)
        else:
            problems.add(f"{ep}.type", f"unknown element type {kind!r}{did_you_mean(kind, kinds)} "
                                       f"(known: {', '.join(kinds)})")
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
        sources.append((f"{lp} (load)", touched(ld)))
        if ld.get("follower", False) is not False:
            _follower(ld, lp, rotating, beam_dofs, table, followers, problems)
            continue
        if "dof" in ld:
            target = dof(ld["dof"], f"{lp}.dof")
        elif "node" in ld:
            direction = ld.get("direction")
            directions = list(AXES[:dim]) + (rotations if ld["node"] in rotating else [])
            if direction not in directions:
                problems.add(f"{lp}.direction", f"expected one of {directions}, found {direction!r}")
                continue
            target = node_dofs(ld["node"], f"{lp}.node")[AXES.index(direction)] if direction in AXES else \
                beam_dofs(ld["node"], f"{lp}.node")[directions.index(direction)]
        else:
            problems.add(lp, "a load needs 'dof' or 'node' + 'direction'")
            continue
        amp = table.add(ld.get("value"), f"{lp}.value", problems)
        fn = build_time_function(ld.get("function"), f"{lp}.function", table, problems)
        if fn is not None:
            loads.append((target, amp, fn))
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
                di = dof(d, ip)
                init_lists[j].append((di, table.add(v, ip, problems)))
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
    la = spec.get("linear_algebra", "auto")
    if la not in ("auto", "dense", "sparse"):
        problems.add(f"{path}.linear_algebra", f"expected auto, dense or sparse, found {la!r}")
    if n == 0:
        problems.add(path, "the model has no free degrees of freedom")
    massed = {d for d, _ in mass_terms} | {d for row in bars.dofs + beams.dofs + frames.dofs for d in row}
    for i, d in enumerate(dof_names):
        if i not in massed:
            problems.add(f"{path}.elements", f"dof {d!r} has no mass (add a mass or a bar density)")
    try:
        model = StructuralModel(dof_names=dof_names, table=table, mass_terms=mass_terms, springs=springs,
                                dampers=dampers, bars=bars, dim=dim, node_coords=node_coords,
                                bar_nodes=bar_nodes, loads=loads, initial=init_lists, rayleigh=rayleigh,
                                rayleigh_corotated=corotated is True,
                                sparse=None if la == "auto" else la == "sparse",
                                spring_nonlinear=spring_nonlinear, beams=beams, nl_dampers=nl_dampers,
                                followers=followers, frames=frames)
    except (ValueError, IndexError, TypeError, KeyError):
        if len(problems.problems) > n_before:
            return None  # the problems already listed explain why it cannot be assembled
        raise
    model.equation_sources = sources
    # with problems listed, the model is still returned so that the responses can be checked
    # against its DOFs and elements; the loader raises before anything runs
    return model


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
