"""``@register("multibody")``: build a :class:`MultibodyModel` from a case's ``model`` mapping.

All problems are collected with their YAML paths (unknown keys with did-you-mean hints,
unknown bodies/markers/joints, missing entries); the builder returns None when any was
found, and the case loader raises them together.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import ProblemCollector
from ...case_keys import FORCE_TYPES, allowed
from .._keys import check_keys, did_you_mean
from ..parameters import ParameterTable
from ..registry import register
from ..timefunctions import build_time_function
from .bodies import GROUND, BodyDef, Const, Diff, Direction, Point
from .forces import ForceElement, Gravity, PointForce, SpringDamper, Torque
from .hydraulics import HydraulicCylinder
from .drivers import read_driver
from .joints import JOINT_TYPES, DotEq, Joint, const_coef, make_joint
from .model import Assembly, MultibodyModel
from .sparse import SparseUnsupported
from .redundancy import InconsistentRedundancy, analyse
from .projection import read_projection
from .pointmass import attachment_problem, orientation_lock, read_distance_joint
from .rotational import RotationalSpringDamper
from .rotations import rotate, atan2_cs
from .spec import Reader

# the accepted keys live in the case language's key table (dynsens/case_keys/)
TOP_KEYS = allowed("model.multibody")
JOINT_KEYS = allowed("multibody.joint")
FORCE_KEYS = {kind: allowed(f"multibody.{kind}") for kind in FORCE_TYPES}


@register("multibody")
def build_multibody(spec: dict, path: str, table: ParameterTable,
                    problems: ProblemCollector) -> MultibodyModel | None:
    """Read the ``model`` mapping (see the README's multibody section)."""
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
    _forces(rd, spec.get("forces", []), f"{path}.forces", forces, cylinders, springs)
    assembly = _initial(rd, spec.get("initial", {}), f"{path}.initial")
    alpha = beta = 0.0
    st = spec.get("stabilization")
    if st is not None and check_keys(st, f"{path}.stabilization", allowed("multibody.stabilization"), problems):
        for key in ("alpha", "beta"):
            v = st.get(key, 0.0)
            if not isinstance(v, (int, float)) or v < 0:
                problems.add(f"{path}.stabilization.{key}", f"expected a number >= 0 (1/s), found {v!r}")
        alpha, beta = float(st.get("alpha", 0.0)), float(st.get("beta", 0.0))
    projection = read_projection(spec.get("projection"), f"{path}.projection", problems)
    scale = spec.get("constraint_scale", 1.0)
    if not isinstance(scale, (int, float)) or scale <= 0:
        problems.add(f"{path}.constraint_scale", f"expected a number > 0, found {scale!r}")
        scale = 1.0
    drift_limit = spec.get("drift_limit")
    if drift_limit is not None and (isinstance(drift_limit, bool) or not isinstance(drift_limit, (int, float))
                                    or drift_limit <= 0):
        problems.add(f"{path}.drift_limit", f"expected a length > 0 (bound on ‖Φ‖), found {drift_limit!r}")
        drift_limit = None
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
    try:
        red = analyse(model, x0)
    except InconsistentRedundancy as exc:
        problems.add(f"{path}.joints", str(exc))
        return None
    if red is None:
        return model
    # the joints keep only their independent equations; the model is rebuilt on them
    dropped = [(model.eq_owner[i], model.eqs[i]) for i in red.dropped]
    gone = {id(eq) for _, eq in dropped}
    for jt in joints:
        keep = [k for k, eq in enumerate(jt.eqs) if id(eq) not in gone]
        jt.eqs = [jt.eqs[k] for k in keep]
        jt.labels = tuple(jt.labels[k] for k in keep)
    model = make()
    model.redundant = [(*owner.split(".", 1), eq) for owner, eq in dropped]  # type: ignore[misc]
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


def _point(rd: Reader, body: BodyDef, spec: Any, path: str, key: str) -> Point | None:
    k = rd.point_on(body, spec, path, key)
    return None if k is None else Point(body.index, k)


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


def _forces(rd: Reader, spec: Any, path: str, forces: list, cylinders: list, springs: list) -> None:
    if not isinstance(spec, list):
        rd.problems.add(path, "expected a list of force elements")
        return
    names: set[str] = set()
    n_p = 0
    for i, f in enumerate(spec):
        fp = f"{path}[{i}]"
        if not isinstance(f, dict) or f.get("type") not in FORCE_KEYS:
            kind = f.get("type") if isinstance(f, dict) else f
            rd.problems.add(f"{fp}.type", f"unknown force type {kind!r}{did_you_mean(kind, FORCE_KEYS)} "
                                          f"(known: {', '.join(FORCE_KEYS)})")
            continue
        kind = f["type"]
        name = str(f.get("name", f"{kind}{i + 1}"))
        if name in names:
            rd.problems.add(f"{fp}.name", f"duplicate force name '{name}'")
        names.add(name)
        check_keys(f, fp, FORCE_KEYS[kind], rd.problems)
        if kind in ("point_force", "torque"):
            body = rd.body(f.get("body"), f"{fp}.body")
            frame = f.get("frame", "global")
            if frame not in ("global", "body"):
                rd.problems.add(f"{fp}.frame", f"expected 'global' or 'body', found {frame!r}")
            fn = build_time_function(f.get("function"), f"{fp}.function", rd.table, rd.problems)
            vkey = "force" if kind == "point_force" else "torque"
            if vkey not in f:
                rd.problems.add(f"{fp}.{vkey}", "missing ([x, y, z])")
            idx = rd.vec3(f.get(vkey), f"{fp}.{vkey}", [0.0, 0.0, 0.0])
            if body is None or fn is None:
                continue
            if body.point_mass and (kind == "torque" or frame == "body"):
                rd.problems.add(f"{fp}.{'type' if kind == 'torque' else 'frame'}",
                                f"'{body.name}' is a point mass, which has no orientation and carries no "
                                "moment: apply a force in global axes at its position")
                continue
            if kind == "point_force":
                pt = _point(rd, body, f.get("point"), f"{fp}.point", f"f:{name}.point")
                if pt is not None:
                    forces.append(PointForce(name, pt, idx, frame, fn))  # type: ignore[arg-type]
            else:
                forces.append(Torque(name, body.index, idx, frame, fn))  # type: ignore[arg-type]
            continue
        b1, b2 = rd.body(f.get("body_1"), f"{fp}.body_1"), rd.body(f.get("body_2"), f"{fp}.body_2")
        if b1 is None or b2 is None:
            continue
        if kind == "rotational_spring_damper":
            if b1.point_mass or b2.point_mass:
                rd.problems.add(f"{fp}.body_{1 if b1.point_mass else 2}", "a point mass has no orientation: "
                                                                          "a rotational spring cannot act on it")
                continue
            rot = _rotational(rd, f, fp, name, b1, b2)
            if rot is not None:
                forces.append(rot)
            continue
        P1 = _point(rd, b1, f.get("point_1"), f"{fp}.point_1", f"f:{name}.p1")
        P2 = _point(rd, b2, f.get("point_2"), f"{fp}.point_2", f"f:{name}.p2")
        if P1 is None or P2 is None:
            continue
        d = Diff(P2, P1)
        if kind == "spring_damper":
            free = f.get("free_length")
            key = f"{name}.L0"
            if free is None or free == "initial":
                g1 = rd.global_point_recipe(b1, P1.key)
                g2 = rd.global_point_recipe(b2, P2.key)
                rd.scal.append((key, lambda prm, _a=g1, _b=g2: np.sqrt(np.sum((_b(prm) - _a(prm)) ** 2))))
            else:
                il = rd.num(free, f"{fp}.free_length", positive=True)
                rd.scal.append((key, lambda prm, _i=il: prm.pv[_i]))
            springs.append(SpringDamper(name, d, rd.num(f.get("stiffness", 0.0), f"{fp}.stiffness"),
                                        rd.num(f.get("cubic_stiffness", 0.0), f"{fp}.cubic_stiffness"),
                                        rd.num(f.get("damping", 0.0), f"{fp}.damping"), key))
            continue
        cyl = _cylinder(rd, f, fp, name, d, n_p)
        if cyl is not None:
            cylinders.append(cyl)
            n_p += 2


def _rotational(rd: Reader, f: dict, fp: str, name: str, b1: BodyDef, b2: BodyDef
                ) -> RotationalSpringDamper | None:
    if b1 is b2:
        rd.problems.add(f"{fp}.body_2", "a rotational spring-damper needs two different bodies")
        return None
    if "axis" not in f:
        rd.problems.add(f"{fp}.axis", "missing (the axis of the relative rotation, global at the initial pose)")
        return None
    keys = rd.frame_recipes(f"f:{name}", rd.vec3(f.get("axis"), f"{fp}.axis"), b1, b2)
    return RotationalSpringDamper(
        name, Direction(b1.index, keys["u1"]), Direction(b1.index, keys["v1"]), Direction(b2.index, keys["u2"]),
        rd.num(f.get("stiffness", 0.0), f"{fp}.stiffness"), rd.num(f.get("damping", 0.0), f"{fp}.damping"),
        rd.num(f.get("free_angle", 0.0), f"{fp}.free_angle"))


def _cylinder(rd: Reader, f: dict, fp: str, name: str, d: Diff, p_index: int) -> HydraulicCylinder | None:
    idx: dict[str, int] = {}
    req = ("length_0", "stroke_max", "bulk_modulus", "dead_volume_1", "dead_volume_2", "pump_flow")
    for key in req:
        if key not in f:
            rd.problems.add(f"{fp}.{key}", "missing")
        idx[key] = rd.num(f.get(key, 1.0), f"{fp}.{key}", positive=key != "pump_flow")
    idx["tank_conductance"] = rd.num(f.get("tank_conductance", 0.0), f"{fp}.tank_conductance", nonnegative=True)
    idx["tank_pressure"] = rd.num(f.get("tank_pressure", 0.0), f"{fp}.tank_pressure")
    idx["damping"] = rd.num(f.get("damping", 0.0), f"{fp}.damping", nonnegative=True)
    if ("bore" in f) == ("area_1" in f):
        rd.problems.add(fp, "give exactly one of 'bore' (piston diameter) or 'area_1' (piston area)")
        return None
    if "bore" in f:
        ib = rd.num(f["bore"], f"{fp}.bore", positive=True)
        rd.scal.append((name + ".A1", lambda prm, _i=ib: np.pi / 4.0 * prm.pv[_i] ** 2))
    else:
        ia = rd.num(f["area_1"], f"{fp}.area_1", positive=True)
        rd.scal.append((name + ".A1", lambda prm, _i=ia: prm.pv[_i]))
    if "rod" in f:
        ir = rd.num(f["rod"], f"{fp}.rod", positive=True)
        rd.scal.append((name + ".A2", lambda prm, _i=ir, _n=name: prm.scal[_n + ".A1"]
                        - np.pi / 4.0 * prm.pv[_i] ** 2))
    elif "area_2" in f:
        ia2 = rd.num(f["area_2"], f"{fp}.area_2", positive=True)
        rd.scal.append((name + ".A2", lambda prm, _i=ia2: prm.pv[_i]))
    else:
        rd.problems.add(fp, "give 'rod' (rod diameter) or 'area_2' (rod-side annulus area)")
        return None
    pump = build_time_function(f.get("pump_function"), f"{fp}.pump_function", rd.table, rd.problems)
    ini = f.get("initial_pressures", "static")
    initial: Any = "static"
    p2 = idx["tank_pressure"]
    if isinstance(ini, list) and len(ini) == 2:
        if ini[0] != "static":
            initial = rd.num(ini[0], f"{fp}.initial_pressures[0]")
        p2 = rd.num(ini[1], f"{fp}.initial_pressures[1]")
    elif ini != "static":
        rd.problems.add(f"{fp}.initial_pressures", f"expected 'static' or [p1 | static, p2], found {ini!r}")
    if pump is None:
        return None
    return HydraulicCylinder(name, d, idx, pump, p_index, initial, p2)


def _initial(rd: Reader, spec: Any, path: str) -> Assembly:
    a = Assembly()
    if not check_keys(spec, path, allowed("multibody.initial"), rd.problems):
        return a
    for key, default in (("time", 0.0), ("tolerance", 1e-12)):
        v = spec.get(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or (key == "tolerance" and v <= 0):
            rd.problems.add(f"{path}.{key}", f"expected a {'positive ' if key == 'tolerance' else ''}"
                                             f"number, found {v!r}")
    a.t0 = float(spec["time"]) if isinstance(spec.get("time"), (int, float)) else 0.0
    a.tol = float(spec["tolerance"]) if isinstance(spec.get("tolerance"), (int, float)) else 1e-12
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
