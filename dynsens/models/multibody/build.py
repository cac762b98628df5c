"""``@register("multibody")``: build a :class:`MultibodyModel` from a case's ``model`` mapping.

All problems are collected with their YAML paths (unknown keys with did-you-mean hints,
unknown bodies/markers/joints, missing entries); the builder returns None when any was
found, and the case loader raises them together.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import ProblemCollector
from .._keys import check_keys, did_you_mean
from ..base import ParameterTable
from ..registry import register
from ..timefunctions import build_time_function
from .bodies import GROUND, BodyDef, Const, Diff, Direction, Point
from .forces import ForceElement, Gravity, PointForce, SpringDamper, Torque
from .hydraulics import HydraulicCylinder
from .joints import JOINT_TYPES, DotEq, Joint, Motion, const_coef, make_driver, make_joint
from .model import Assembly, MultibodyModel
from .rotations import rotate, atan2_cs
from .spec import Reader

TOP_KEYS = ("type", "units", "gravity", "bodies", "joints", "forces", "initial", "stabilization",
            "constraint_scale", "drift_limit")
JOINT_KEYS = ("name", "type", "body_1", "body_2", "point", "marker_1", "marker_2", "axis")
DRIVER_KEYS = ("name", "type", "joint", "body", "coordinate", "offset", "rate", "amplitude",
               "frequency", "phase")
FORCE_KEYS = {
    "point_force": ("type", "name", "body", "point", "force", "frame", "function"),
    "torque": ("type", "name", "body", "torque", "frame", "function"),
    "spring_damper": ("type", "name", "body_1", "body_2", "point_1", "point_2", "stiffness",
                      "damping", "cubic_stiffness", "free_length"),
    "hydraulic_cylinder": ("type", "name", "body_1", "body_2", "point_1", "point_2", "bore", "rod",
                           "area_1", "area_2", "length_0", "stroke_max", "bulk_modulus",
                           "dead_volume_1", "dead_volume_2", "tank_conductance", "tank_pressure",
                           "damping", "pump_flow", "pump_function", "initial_pressures"),
}


@register("multibody")
def build_multibody(spec: dict, path: str, table: ParameterTable,
                    problems: ProblemCollector) -> MultibodyModel | None:
    """Read the ``model`` mapping (see the README's multibody section)."""
    n0 = len(problems.problems)
    check_keys(spec, path, TOP_KEYS, problems, required=("bodies",))
    rd = Reader(table, problems)
    rd.read_bodies(spec.get("bodies"), f"{path}.bodies")
    joints = _joints(rd, spec.get("joints", []), f"{path}.joints")
    forces: list[ForceElement] = []
    if spec.get("gravity") is not None:
        forces.append(Gravity(rd.vec3(spec["gravity"], f"{path}.gravity")))  # type: ignore[arg-type]
    cylinders: list[HydraulicCylinder] = []
    springs: list[SpringDamper] = []
    _forces(rd, spec.get("forces", []), f"{path}.forces", forces, cylinders, springs)
    assembly = _initial(rd, spec.get("initial", {}), f"{path}.initial")
    alpha = beta = 0.0
    st = spec.get("stabilization")
    if st is not None and check_keys(st, f"{path}.stabilization", ("alpha", "beta"), problems):
        for key in ("alpha", "beta"):
            v = st.get(key, 0.0)
            if not isinstance(v, (int, float)) or v < 0:
                problems.add(f"{path}.stabilization.{key}", f"expected a number >= 0 (1/s), found {v!r}")
        alpha, beta = float(st.get("alpha", 0.0)), float(st.get("beta", 0.0))
    scale = spec.get("constraint_scale", 1.0)
    if not isinstance(scale, (int, float)) or scale <= 0:
        problems.add(f"{path}.constraint_scale", f"expected a number > 0, found {scale!r}")
        scale = 1.0
    drift_limit = spec.get("drift_limit")
    if drift_limit is not None and (isinstance(drift_limit, bool) or not isinstance(drift_limit, (int, float))
                                    or drift_limit <= 0):
        problems.add(f"{path}.drift_limit", f"expected a length > 0 (bound on ‖Φ‖), found {drift_limit!r}")
        drift_limit = None
    if not rd.bodies:
        problems.add(f"{path}.bodies", "no moving body")
    if len(problems.problems) > n0:
        return None
    model = MultibodyModel(table, rd.bodies, rd.ground, joints, forces + springs, cylinders,
                           rd.vec, rd.scal, assembly, alpha, beta, float(scale), springs=springs)
    model.drift_limit = None if drift_limit is None else float(drift_limit)
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
            jt = _driver(rd, j, jp, name, by_name)
        else:
            jt = _joint(rd, j, jp, name, kind)
        if jt is not None:
            out.append(jt)
            by_name[name] = jt
    return out


def _joint(rd: Reader, j: dict, jp: str, name: str, kind: str) -> Joint | None:
    check_keys(j, jp, JOINT_KEYS, rd.problems, required=("type", "body_1", "body_2"))
    b1, b2 = rd.body(j.get("body_1"), f"{jp}.body_1"), rd.body(j.get("body_2"), f"{jp}.body_2")
    if b1 is None or b2 is None:
        return None
    if b1 is b2:
        rd.problems.add(f"{jp}.body_2", "a joint needs two different bodies")
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
    jt = make_joint(name, kind, b1.index, b2.index, keys)
    jt.extra["drive"] = {"revolute": "angle", "prismatic": "slide"}.get(kind, "")
    return jt


def _motion(rd: Reader, j: dict, jp: str, offset_default: Any = 0.0) -> Motion:
    return Motion(rd.num(j.get("offset", offset_default), f"{jp}.offset"),
                  rd.num(j.get("rate", 0.0), f"{jp}.rate"),
                  rd.num(j.get("amplitude", 0.0), f"{jp}.amplitude"),
                  rd.num(j.get("frequency", 0.0), f"{jp}.frequency"),
                  rd.num(j.get("phase", 0.0), f"{jp}.phase"))


def _driver(rd: Reader, j: dict, jp: str, name: str, by_name: dict[str, Joint]) -> Joint | None:
    check_keys(j, jp, DRIVER_KEYS, rd.problems)
    if "joint" in j:
        target = by_name.get(j["joint"])
        if target is None:
            rd.problems.add(f"{jp}.joint", f"unknown joint {j['joint']!r} (a driver must follow the "
                                           f"joint it drives){did_you_mean(j['joint'], by_name)}")
            return None
        coord = j.get("coordinate", target.extra.get("drive") or None)
        allowed = {"revolute": ("angle",), "prismatic": ("slide",), "cylindrical": ("angle", "slide")}
        if coord not in allowed.get(target.kind, ()):
            rd.problems.add(f"{jp}.coordinate", f"a {target.kind} joint can be driven in "
                            f"{' or '.join(allowed.get(target.kind, ())) or 'nothing'}; found {coord!r}")
            return None
        target.extra["drive"] = coord
        jt = make_driver(name, target, _motion(rd, j, jp))
        target.extra["drive"] = {"revolute": "angle", "prismatic": "slide"}.get(target.kind, "")
        return jt
    body = rd.body(j.get("body"), f"{jp}.body")
    coord = j.get("coordinate")
    if body is None or body.index == GROUND:
        return None
    if coord not in ("x", "y", "z"):
        rd.problems.add(f"{jp}.coordinate", f"a body driver prescribes x, y or z of the COM; found {coord!r}")
        return None
    k = "xyz".index(coord)
    motion = _motion(rd, j, jp)
    b = body.index

    r0 = body.position[k]

    def shift(t: float, prm: Any) -> tuple[Any, Any, Any]:
        # relative to the given initial COM coordinate (read from pv: see joints.Coef)
        x, xd, xdd = motion(t, prm)
        return prm.pv[..., r0] + x, xd, xdd
    eq = DotEq([(const_coef(1.0), Const(f"e_{coord}"), Point(b, "zero"))], shift=shift)
    return Joint(name, "driving", GROUND, b, [eq], labels=("drive",))


def _point(rd: Reader, body: BodyDef, spec: Any, path: str, key: str) -> Point | None:
    k = rd.point_on(body, spec, path, key)
    return None if k is None else Point(body.index, k)


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
    if not check_keys(spec, path, ("hold", "distances", "time", "tolerance"), rd.problems):
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
        if not check_keys(dspec, dp, ("between", "value"), rd.problems, required=("between", "value")):
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
