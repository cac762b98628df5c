"""The ``forces`` list of a multibody case: spring-dampers, hydraulic cylinders, point forces,
torques and rotational spring-dampers, read into force elements (part of
:func:`.build.build_multibody`; problems collected with their YAML paths)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ...case_keys import FORCE_TYPES, allowed
from .._keys import check_keys, did_you_mean
from ..timefunctions import build_time_function
from .bodies import BodyDef, Diff, Direction, Point
from .forces import PointForce, SpringDamper, Torque
from .hydraulics import HydraulicCylinder
from .rotational import RotationalSpringDamper
from .spec import Reader

FORCE_KEYS = {kind: allowed(f"multibody.{kind}") for kind in FORCE_TYPES}


def _point(rd: Reader, body: BodyDef, spec: Any, path: str, key: str) -> Point | None:
    k = rd.point_on(body, spec, path, key)
    return None if k is None else Point(body.index, k)


@dataclass
class _Elements:
    """Where the force elements read go: ``forces`` (point forces, torques, rotational
    spring-dampers), ``cylinders``, ``springs``; ``n_p`` pressures of the cylinders so far."""

    forces: list
    cylinders: list
    springs: list
    n_p: int = 0


def read_forces(rd: Reader, spec: Any, path: str, forces: list, cylinders: list, springs: list) -> None:
    """Read the ``forces`` list ``spec`` at ``path``: point forces, torques and rotational
    spring-dampers are appended to ``forces``, hydraulic cylinders to ``cylinders``,
    spring-dampers to ``springs``; problems go to rd.problems."""
    if not isinstance(spec, list):
        rd.problems.add(path, "expected a list of force elements")
        return
    names: set[str] = set()
    out = _Elements(forces, cylinders, springs)
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
        _READERS[kind](rd, f, fp, name, kind, out)


def _applied(rd: Reader, f: dict, fp: str, name: str, kind: str, out: _Elements) -> None:
    """A ``point_force`` or a ``torque``: a vector times a time function, in global or body axes."""
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
        return
    if body.point_mass and (kind == "torque" or frame == "body"):
        rd.problems.add(f"{fp}.{'type' if kind == 'torque' else 'frame'}",
                        f"'{body.name}' is a point mass, which has no orientation and carries no "
                        "moment: apply a force in global axes at its position")
        return
    if kind == "point_force":
        pt = _point(rd, body, f.get("point"), f"{fp}.point", f"f:{name}.point")
        if pt is not None:
            out.forces.append(PointForce(name, pt, idx, frame, fn))  # type: ignore[arg-type]
    else:
        out.forces.append(Torque(name, body.index, idx, frame, fn))  # type: ignore[arg-type]


def _two_bodies(rd: Reader, f: dict, fp: str) -> tuple[BodyDef, BodyDef] | None:
    """The bodies ``body_1`` and ``body_2`` an element connects (None after a problem)."""
    b1, b2 = rd.body(f.get("body_1"), f"{fp}.body_1"), rd.body(f.get("body_2"), f"{fp}.body_2")
    return None if b1 is None or b2 is None else (b1, b2)


def _attachments(rd: Reader, f: dict, fp: str, name: str) -> tuple[BodyDef, Point, BodyDef, Point] | None:
    """The bodies an axial element connects and its points on them, ``point_1`` and ``point_2``."""
    bodies = _two_bodies(rd, f, fp)
    if bodies is None:
        return None
    b1, b2 = bodies
    P1 = _point(rd, b1, f.get("point_1"), f"{fp}.point_1", f"f:{name}.p1")
    P2 = _point(rd, b2, f.get("point_2"), f"{fp}.point_2", f"f:{name}.p2")
    return None if P1 is None or P2 is None else (b1, P1, b2, P2)


def _rotational_element(rd: Reader, f: dict, fp: str, name: str, kind: str, out: _Elements) -> None:
    """A ``rotational_spring_damper`` between two rigid bodies."""
    bodies = _two_bodies(rd, f, fp)
    if bodies is None:
        return
    b1, b2 = bodies
    if b1.point_mass or b2.point_mass:
        rd.problems.add(f"{fp}.body_{1 if b1.point_mass else 2}", "a point mass has no orientation: "
                                                                  "a rotational spring cannot act on it")
        return
    rot = _rotational(rd, f, fp, name, b1, b2)
    if rot is not None:
        out.forces.append(rot)


def _spring(rd: Reader, f: dict, fp: str, name: str, kind: str, out: _Elements) -> None:
    """A ``spring_damper`` between two points; its free length given or that of the initial pose."""
    ends = _attachments(rd, f, fp, name)
    if ends is None:
        return
    b1, P1, b2, P2 = ends
    free = f.get("free_length")
    key = f"{name}.L0"
    if free is None or free == "initial":
        g1 = rd.global_point_recipe(b1, P1.key)
        g2 = rd.global_point_recipe(b2, P2.key)
        rd.scal.append((key, lambda prm, _a=g1, _b=g2: np.sqrt(np.sum((_b(prm) - _a(prm)) ** 2))))
    else:
        il = rd.num(free, f"{fp}.free_length", positive=True)
        rd.scal.append((key, lambda prm, _i=il: prm.pv[_i]))
    out.springs.append(SpringDamper(name, Diff(P2, P1), rd.num(f.get("stiffness", 0.0), f"{fp}.stiffness"),
                                    rd.num(f.get("cubic_stiffness", 0.0), f"{fp}.cubic_stiffness"),
                                    rd.num(f.get("damping", 0.0), f"{fp}.damping"), key))


def _cylinder_element(rd: Reader, f: dict, fp: str, name: str, kind: str, out: _Elements) -> None:
    """A ``hydraulic_cylinder`` between two points, with its two chamber pressures as states."""
    ends = _attachments(rd, f, fp, name)
    if ends is None:
        return
    _, P1, _, P2 = ends
    cyl = _cylinder(rd, f, fp, name, Diff(P2, P1), out.n_p)
    if cyl is not None:
        out.cylinders.append(cyl)
        out.n_p += 2


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


# one reader per force type (FORCE_TYPES), all called alike
_READERS: dict[str, Callable[[Reader, dict, str, str, str, _Elements], None]] = {
    "point_force": _applied, "torque": _applied, "spring_damper": _spring,
    "rotational_spring_damper": _rotational_element, "hydraulic_cylinder": _cylinder_element}
