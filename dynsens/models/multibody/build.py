"""``@register("multibody")``: build a :class:`MultibodyModel` from a case's ``model`` mapping.

All problems are collected with their YAML paths (unknown keys with did-you-mean hints,
unknown bodies/markers/joints, missing entries); the builder returns None when any was
found, and the case loader raises them together.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import ModelError, ProblemCollector
from ...case_keys import allowed
from .._keys import check_keys, did_you_mean
from ..parameters import ParameterTable, finite_float, number_text
from ..registry import register
from .bodies import GROUND, Const, Diff, Direction, Point
from .forces import ForceElement, Gravity, SpringDamper
from .hydraulics import HydraulicCylinder
from .drivers import read_driver
from .joints import JOINT_TYPES, DotEq, Joint, const_coef, make_joint
from .model import Assembly, MultibodyModel
from .sparse import SparseUnsupported
from .redundancy import InconsistentRedundancy, analyse
from .projection import read_projection
from .members import read_members
from .pointmass import attachment_problem, orientation_lock, read_distance_joint
from .rotations import rotate, atan2_cs
from .spec import Reader
from .build_forces import read_forces

# the accepted keys live in the case language's key table (dynsens/case_keys/)
TOP_KEYS = allowed("model.multibody")
JOINT_KEYS = allowed("multibody.joint")


@register("multibody")
def build_multibody(spec: dict, path: str, table: ParameterTable,
                    problems: ProblemCollector) -> MultibodyModel | None:
    """Read the ``model`` mapping (see docs/multibody.md)."""
    n0 = len(problems.problems)
    check_keys(spec, path, TOP_KEYS, problems, required=("bodies",))
    rd = Reader(table, problems)
    rd.read_bodies(spec.get("bodies"), f"{path}.bodies")
    joints = [orientation_lock(rd, b) for b in rd.bodies if b.point_mass]
    joints += _joints(rd, spec.get("joints", []), f"{path}.joints")
    forces: list[ForceElement] = []
    if spec.get("gravity") is not None:
        forces.append(Gravity(rd.vec3(spec["gravity"], f"{path}.gravity")))  # type: ignore[arg-type]
    cylinders: list[HydraulicCylinder] = []
    springs: list[SpringDamper] = []
    read_forces(rd, spec.get("forces", []), f"{path}.forces", forces, cylinders, springs)
    members = read_members(rd, spec.get("members"), f"{path}.members", springs, forces)
    assembly = _initial(rd, spec.get("initial", {}), f"{path}.initial")
    alpha, beta = _stabilization(spec.get("stabilization"), f"{path}.stabilization", problems)
    projection = read_projection(spec.get("projection"), f"{path}.projection", problems)
    scale = setting(spec, "constraint_scale", 1.0, path, problems, "> 0")
    drift_limit = setting(spec, "drift_limit", None, path, problems, "> 0", "(a length: bound on ‖Φ‖)")
    la = spec.get("linear_algebra", "auto")
    if la not in ("auto", "dense", "sparse"):
        problems.add(f"{path}.linear_algebra", f"expected auto, dense or sparse, found {la!r}")
    if not rd.bodies:
        problems.add(f"{path}.bodies", "no moving body")
    if len(problems.problems) > n0:
        return None
    sparse = None if la == "auto" else la == "sparse"

    def make() -> MultibodyModel:
        m = MultibodyModel(table, rd.bodies, rd.ground, joints, [*forces, *springs], cylinders,
                           rd.vec, rd.scal, assembly, alpha, beta, float(scale), springs=springs,
                           sparse=sparse)
        m.drift_limit = None if drift_limit is None else float(drift_limit)
        m.projection = projection
        m.point_mass_attachments = list(rd.point_mass_attachments)
        m.members = members
        m.entry_paths = _entry_paths(spec, path)
        return m
    try:
        model = make()
    except SparseUnsupported as exc:
        problems.add(f"{path}.linear_algebra", f"sparse: {exc}")
        return None
    if table.nominal is None or problems.problems:   # outside a case, or the design has problems:
        return model                                  # no initial design to analyse
    x0 = np.array([float(table.nominal.get(n, 0.0)) for n in table.design_names])
    if table.check(x0):      # an entry without a value there: the loader reports it at its path
        return model
    if _zero_length_springs(rd, model, x0):
        return None
    try:
        red = analyse(model, x0)
    except InconsistentRedundancy as exc:
        problems.add(f"{path}.joints", str(exc))
        return None
    except ModelError as exc:        # poses that overflow: reported with the case, not after it
        problems.add(f"{path}.bodies", str(exc))
        return None
    if red is None:
        return model
    # the joints keep only their independent equations; the model is rebuilt on them
    dropped = [(model.eq_owner[i], model.eqs[i]) for i in red.dropped]
    gone = {id(eq) for _, eq in dropped}
    dependent = {model.eq_owner[i].split(".", 1)[0] for i in red.dependent
                 if not model.eq_owner[i].endswith(".normalization")}
    for jt in joints:
        # all of the joint's equations, in its own order: its reactions are taken over all of
        # them (:mod:`.reaction_split`), whichever were left out
        jt.all_equations = tuple(zip(jt.labels, jt.eqs))
        keep = [k for k, eq in enumerate(jt.eqs) if id(eq) not in gone]
        jt.eqs = [jt.eqs[k] for k in keep]
        jt.labels = tuple(jt.labels[k] for k in keep)
    model = make()
    model.redundant = [(*owner.split(".", 1), eq) for owner, eq in dropped]  # type: ignore[misc]
    model.dependent_joints = [jt.name for jt in joints if jt.name in dependent]
    return model


def _joints(rd: Reader, spec: Any, path: str) -> list[Joint]:
    if not isinstance(spec, list):
        rd.problems.add(path, "expected a list of joints")
        return []
    out: list[Joint] = []
    by_name: dict[str, Joint] = {}
    for i, j in enumerate(spec):
        jp = f"{path}[{i}]"
        if not isinstance(j, dict):
            rd.problems.add(jp, f"expected a mapping, found {j!r}")
            continue
        kind = j.get("type")
        name = str(j.get("name", f"joint{i + 1}"))
        if name in by_name:
            rd.problems.add(f"{jp}.name", f"duplicate joint name '{name}'")
        if kind not in JOINT_TYPES:
            rd.problems.add(f"{jp}.type", f"unknown joint type {kind!r}{did_you_mean(kind, JOINT_TYPES)} "
                                          f"(known: {', '.join(JOINT_TYPES)})")
            continue
        if kind == "driving":
            jt = read_driver(rd, j, jp, name, by_name)
        elif kind == "distance":
            jt = read_distance_joint(rd, j, jp, name)
        else:
            jt = _joint(rd, j, jp, name, kind)
        if jt is not None:
            out.append(jt)
            by_name[name] = jt
    return out


def _joint(rd: Reader, j: dict, jp: str, name: str, kind: str) -> Joint | None:
    check_keys(j, jp, JOINT_KEYS, rd.problems, required=("type", "body_1", "body_2"))
    pair = rd.two_bodies(j, jp)
    if pair is None:
        return None
    b1, b2 = pair
    for role, b in (("body_1", b1), ("body_2", b2)):
        why = attachment_problem(kind, role, b)
        if why is not None:
            rd.problems.add(f"{jp}.{role}", why)
            return None
    keys: dict[str, str] = {"ex": "e_x", "ey": "e_y", "ez": "e_z"}
    if "marker_1" in j or "marker_2" in j:
        k1 = rd.marker(b1, j.get("marker_1"), f"{jp}.marker_1")
        k2 = rd.marker(b2, j.get("marker_2"), f"{jp}.marker_2")
        if k1 is None or k2 is None:
            return None
        keys["s1"], keys["s2"] = k1, k2
    elif "point" in j:
        pt = j["point"]
        if isinstance(pt, str):
            owner = b1 if pt in b1.markers else (b2 if pt in b2.markers else None)
            if owner is None:
                rd.problems.add(f"{jp}.point", f"no marker {pt!r} on '{b1.name}' or '{b2.name}'"
                                f"{did_you_mean(pt, list(b1.markers) + list(b2.markers))}")
                return None
            gfn = rd.global_point_recipe(owner, rd.marker_key(owner, pt))
        else:
            idx = rd.vec3(pt, f"{jp}.point")
            gfn = (lambda prm, _i=idx: np.array([prm.pv[k] for k in _i]))
        keys["s1"] = rd.local_point(b1, f"j:{name}.s1", gfn)
        keys["s2"] = rd.local_point(b2, f"j:{name}.s2", gfn)
    else:
        rd.problems.add(jp, "give the joint location: 'point' ([x, y, z] global at the initial pose, "
                            "or a marker name) or 'marker_1' and 'marker_2'")
        return None
    if kind != "spherical" or "axis" in j:
        if "axis" not in j and kind != "fixed":
            rd.problems.add(f"{jp}.axis", f"missing (the {kind} joint's axis, global at the initial pose)")
            return None
        axis = rd.vec3(j.get("axis"), f"{jp}.axis", [0.0, 0.0, 1.0])
        rd.table.require_nonzero(axis, f"{jp}.axis", "joint axis")
    else:
        axis = rd.vec3([0.0, 0.0, 1.0], f"{jp}.axis")
    keys.update(rd.frame_recipes(name, axis, b1, b2))
    rd.attached(b1, keys["s1"], f"the point of joint '{name}'")
    rd.attached(b2, keys["s2"], f"the point of joint '{name}'")
    jt = make_joint(name, kind, b1.index, b2.index, keys)
    jt.extra["drive"] = {"revolute": "angle", "prismatic": "slide"}.get(kind, "")
    return jt


def _entry_paths(spec: dict, path: str) -> dict[str, Any]:
    """YAML entries by name, for run-time errors (MultibodyModel.describe_equation): joints
    {name: 'model.joints[2] (revolute 'J1')'}, and per body the forces that name it."""
    joints: dict[str, str] = {}
    forces: dict[str, list[str]] = {}
    for key, out in (("joints", joints), ("forces", None)):
        items = spec.get(key)
        for i, item in enumerate(items if isinstance(items, list) else []):
            if not isinstance(item, dict):
                continue
            entry = f"{path}.{key}[{i}] ({item.get('type')} '{item.get('name', '')}')"
            if out is not None:
                out[str(item.get("name"))] = entry
                continue
            for v in item.values():
                for b in (v if isinstance(v, list) else [v]):
                    if isinstance(b, str) and entry not in forces.setdefault(b, []):
                        forces[b].append(entry)
    return {"joints": joints, "forces": forces, "bodies": f"{path}.bodies"}


def setting(spec: dict, key: str, default: Any, path: str, problems: ProblemCollector, rule: str = "",
            unit: str = "") -> Any:
    """The number ``spec[key]`` (``default`` when absent): finite and, with ``rule`` '> 0' or
    '>= 0', in range; otherwise a problem at ``path.key`` and the default."""
    v = spec.get(key, default)
    if v is default:
        return v
    x = finite_float(v) if not isinstance(v, bool) and isinstance(v, (int, float)) else None
    ok = x is not None
    if x is not None and rule:
        ok = x > 0 if rule == "> 0" else x >= 0
    if not ok:
        problems.add(f"{path}.{key}", f"expected a finite number{' ' + rule if rule else ''}"
                                      f"{' ' + unit if unit else ''}, found {number_text(v)}")
        return default
    return x


def _initial(rd: Reader, spec: Any, path: str) -> Assembly:
    a = Assembly()
    if not check_keys(spec, path, allowed("multibody.initial"), rd.problems):
        return a
    a.t0 = setting(spec, "time", 0.0, path, rd.problems)
    a.tol = setting(spec, "tolerance", 1e-12, path, rd.problems, "> 0")
    one = const_coef(1.0)
    for i, h in enumerate(spec.get("hold", []) or []):
        hp = f"{path}.hold[{i}]"
        if not isinstance(h, str) or "." not in h:
            rd.problems.add(hp, f"expected 'body.x|y|z|angle_z', found {h!r}")
            continue
        bname, coord = h.split(".", 1)
        body = rd.body(bname, hp)
        if body is None or body.index == GROUND:
            continue
        b = body.index
        if coord in ("x", "y", "z"):
            k = "xyz".index(coord)
            eq = DotEq([(one, Const(f"e_{coord}"), Point(b, "zero"))],
                       shift=lambda t, prm, _b=b, _k=k: (prm.bodies[_b].r0[_k], 0.0, 0.0))
        elif coord == "angle_z":
            def ang(prm: Any, _b: int = b) -> Any:
                xa = rotate(prm.bodies[_b].p0.reshape(4, 1), np.array([[1.0], [0.0], [0.0]]))[:, 0]
                return atan2_cs(xa[1], xa[0])
            X = Direction(b, "e_x")
            eq = DotEq([(lambda t, prm, _a=ang: (np.cos(_a(prm)), 0.0, 0.0), X, Const("e_y")),
                        (lambda t, prm, _a=ang: (-np.sin(_a(prm)), 0.0, 0.0), X, Const("e_x"))])
        else:
            rd.problems.add(hp, f"unknown coordinate {coord!r}{did_you_mean(coord, ('x', 'y', 'z', 'angle_z'))} "
                                "(hold x, y, z or angle_z of a body)")
            continue
        a.equations.append(eq)
        a.labels.append(f"hold {h}")
    for i, dspec in enumerate(spec.get("distances", []) or []):
        dp = f"{path}.distances[{i}]"
        if not check_keys(dspec, dp, allowed("multibody.distance"), rd.problems, required=("between", "value")):
            continue
        pair = dspec.get("between")
        if not isinstance(pair, list) or len(pair) != 2:
            rd.problems.add(f"{dp}.between", "expected [body.marker, body.marker]")
            continue
        m1, m2 = rd.marker_ref(pair[0], f"{dp}.between[0]"), rd.marker_ref(pair[1], f"{dp}.between[1]")
        il = rd.num(dspec.get("value"), f"{dp}.value", positive=True)
        if m1 is None or m2 is None:
            continue
        d = Diff(Point(m2[0].index, m2[1]), Point(m1[0].index, m1[1]))
        # (d·d − L²)/(2L) = 0: the distance equals L, in length units
        eq = DotEq([(lambda t, prm, _i=il: (0.5 / prm.pv[_i], 0.0, 0.0), d, d)],
                   shift=lambda t, prm, _i=il: (0.5 * prm.pv[_i], 0.0, 0.0))
        a.equations.append(eq)
        a.labels.append(f"distance {pair[0]}-{pair[1]}")
    return a


def _stabilization(st: Any, path: str, problems: ProblemCollector) -> tuple[float, float]:
    """Baumgarte's alpha and beta (1/s) of ``model.stabilization`` (0, 0 without it)."""
    if st is None or not check_keys(st, path, allowed("multibody.stabilization"), problems):
        return 0.0, 0.0
    return (setting(st, "alpha", 0.0, path, problems, ">= 0", "(1/s)"),
            setting(st, "beta", 0.0, path, problems, ">= 0", "(1/s)"))


def _zero_length_springs(rd: Reader, model: MultibodyModel, x0: np.ndarray) -> bool:
    """Reports every spring-damper whose two points coincide at the initial pose (its length is
    zero there and the direction of its force undefined); whether there was one."""
    prm = model.parameters(x0)
    found = False
    for fp, g1, g2 in rd.axial_ends:
        d = np.real(np.asarray(g2(prm)) - np.asarray(g1(prm)))
        if not np.linalg.norm(d) > 0.0:
            rd.problems.add(fp, f"expected two points apart at the initial pose, found both at "
                                f"{np.round(np.real(np.asarray(g1(prm))), 12).tolist()}: the spring's length "
                                "is zero there and the direction of its force undefined")
            found = True
    return found
