r"""Quantities of a multibody model that responses and events can read.

Spec forms (``quantity:`` in a case):

* ``{joint: J, kind: reaction_force}`` (3, global; the force the joint exerts on body_2,
  ``f = −(∂Φ_J/∂r_2)ᵀ λ_J``), ``reaction_force_norm`` (1, ``sqrt(f·f)``; for revolute,
  spherical, planar_pin and prismatic joints this is the norm of the multipliers of the
  joint's position-level equations, weir_model §3.4), ``reaction_moment`` (3, global, about
  the joint point on body_2), ``reaction_force_joint_frame`` (3, along u, v, w of the joint
  frame fixed in body_1), ``multipliers`` (the joint's λ);
* ``{body: B, kind: position | velocity | acceleration | angle_z | angular_velocity |
  angular_velocity_z}`` (angle_z = direction of the body x-axis in the x–y plane, rad);
* ``{marker: body.marker, kind: position | velocity}``;
* ``{element: CYL, kind: stroke | stroke_rate | pressure_1 | pressure_2 | force | volume_1 |
  volume_2}`` for hydraulic cylinders, ``{element: SPRING, kind: length | length_rate | force}``.

All functions are complex-safe.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from ...errors import ProblemCollector
from .._keys import check_keys, did_you_mean
from ..base import Output, StepState
from .bodies import GROUND, Ctx, Point, angular_velocity
from .rotations import E_mul, atan2_cs, cross, rotate

if TYPE_CHECKING:  # pragma: no cover
    from .model import MultibodyModel

JOINT_KINDS = ("reaction_force", "reaction_force_norm", "reaction_moment",
               "reaction_force_joint_frame", "multipliers")
BODY_KINDS = ("position", "velocity", "acceleration", "angle_z", "angular_velocity",
              "angular_velocity_z")
MARKER_KINDS = ("position", "velocity")
CYL_KINDS = ("stroke", "stroke_rate", "pressure_1", "pressure_2", "force", "volume_1", "volume_2")
SPRING_KINDS = ("length", "length_rate", "force")


def _ctx(s: StepState, params: Any, t: float) -> Ctx:
    return Ctx(s.q[:, None], s.qd[:, None], s.qdd[:, None], params, t)


def _joint_load(model: "MultibodyModel", jt: Any, t: float, s: StepState, params: Any
                ) -> tuple[Any, Any, Ctx]:
    """(f, n) force (3,) on body_2 and moment (3,) about its joint point; global frame."""
    ctx = _ctx(s, params, t)
    dt = np.result_type(s.q, s.lam, params.pv, float)
    out = np.zeros((model.traits.n_q, 1), dt)
    for r, eq in zip(jt.rows, jt.eqs):
        eq.apply(ctx, s.lam[r:r + 1].reshape(1, 1), out)
    sign, b = (-1.0, jt.body_2) if jt.body_2 != GROUND else (1.0, jt.body_1)
    a = 7 * b
    f = sign * out[a:a + 3, 0]
    Qp = sign * out[a + 3:a + 7]
    p = s.q[a + 3:a + 7].reshape(4, 1)
    n_com = 0.5 * E_mul(p, Qp)[:, 0]
    if jt.point_2 is not None:
        pt = jt.point_2 if jt.body_2 != GROUND else jt.extra["d"].b
        arm = pt.kin(ctx)[0][:, 0] - s.q[a:a + 3]
        n = n_com - cross(arm.reshape(3, 1), f.reshape(3, 1))[:, 0]
    else:
        n = n_com
    return f, n, ctx


def resolve_output(model: "MultibodyModel", spec: Any, path: str,
                   problems: ProblemCollector) -> Output | None:
    """Output for a quantity spec, or None after reporting the problem under ``path``."""
    if not isinstance(spec, dict):
        problems.add(path, f"expected a mapping such as {{joint: NAME, kind: reaction_force}}, found {spec!r}")
        return None
    heads = [k for k in ("joint", "body", "marker", "element") if k in spec]
    if len(heads) != 1:
        problems.add(path, "name exactly one of 'joint', 'body', 'marker', 'element'")
        return None
    head = heads[0]
    check_keys(spec, path, (head, "kind"), problems, required=("kind",))
    name, kind = spec[head], spec.get("kind")
    fn: Callable[[float, StepState, Any], Any]
    if head == "joint":
        joints = {j.name: j for j in model.joints}
        if name not in joints:
            problems.add(f"{path}.joint", f"unknown joint {name!r}{did_you_mean(name, joints)} "
                                          f"(joints: {', '.join(joints)})")
            return None
        jt = joints[name]
        if kind not in JOINT_KINDS:
            problems.add(f"{path}.kind", f"unknown joint quantity {kind!r}{did_you_mean(kind, JOINT_KINDS)} "
                                         f"(known: {', '.join(JOINT_KINDS)})")
            return None
        if kind == "multipliers":
            rows = np.array(jt.rows)
            return Output(lambda t, s, prm: s.lam[rows], tuple(f"{name}.{lab}" for lab in jt.labels))
        if jt.kind == "driving" and kind != "multipliers":
            problems.add(f"{path}.kind", "a driving constraint has only 'multipliers'")
            return None

        def fn(t: float, s: StepState, prm: Any, _jt: Any = jt, _k: str = kind) -> Any:
            f, n, ctx = _joint_load(model, _jt, t, s, prm)
            if _k == "reaction_force":
                return f
            if _k == "reaction_force_norm":
                return np.atleast_1d(np.sqrt(np.sum(f * f)))
            if _k == "reaction_moment":
                return n
            u, v, w = (d.kin(ctx)[0][:, 0] for d in _jt.frame_1)
            return np.array([np.sum(u * f), np.sum(v * f), np.sum(w * f)])
        labels = {"reaction_force": ("Fx", "Fy", "Fz"), "reaction_force_norm": ("F",),
                  "reaction_moment": ("Mx", "My", "Mz"), "reaction_force_joint_frame": ("Fu", "Fv", "Fw")}
        return Output(fn, tuple(f"{name}.{c}" for c in labels[kind]))
    if head == "body":
        body = next((b for b in model.bodies if b.name == name), None)
        if body is None:
            names = [b.name for b in model.bodies]
            problems.add(f"{path}.body", f"unknown body {name!r}{did_you_mean(name, names)} "
                                         f"(moving bodies: {', '.join(names)})")
            return None
        if kind not in BODY_KINDS:
            problems.add(f"{path}.kind", f"unknown body quantity {kind!r}{did_you_mean(kind, BODY_KINDS)} "
                                         f"(known: {', '.join(BODY_KINDS)})")
            return None
        a = 7 * body.index

        def fn(t: float, s: StepState, prm: Any, _k: str = kind) -> Any:
            if _k == "position":
                return s.q[a:a + 3]
            if _k == "velocity":
                return s.qd[a:a + 3]
            if _k == "acceleration":
                return s.qdd[a:a + 3]
            p = s.q[a + 3:a + 7].reshape(4, 1)
            if _k == "angle_z":
                xa = rotate(p, np.array([[1.0], [0.0], [0.0]]))[:, 0]
                return np.atleast_1d(atan2_cs(xa[1], xa[0]))
            w = angular_velocity(p, s.qd[a + 3:a + 7].reshape(4, 1))[:, 0]
            return w if _k == "angular_velocity" else w[2:3]
        labs = {"position": ("x", "y", "z"), "velocity": ("vx", "vy", "vz"),
                "acceleration": ("ax", "ay", "az"), "angle_z": ("angle_z",),
                "angular_velocity": ("wx", "wy", "wz"), "angular_velocity_z": ("wz",)}[kind]
        return Output(fn, tuple(f"{name}.{c}" for c in labs), "rad" if kind == "angle_z" else "")
    if head == "marker":
        from .spec import Reader
        if not isinstance(name, str) or "." not in name:
            problems.add(f"{path}.marker", f"expected 'body.marker', found {name!r}")
            return None
        bname, mname = name.split(".", 1)
        bodies = {b.name: b for b in model.bodies}
        bodies["ground"] = model.ground
        if bname not in bodies or mname not in bodies[bname].markers:
            allm = [f"{b.name}.{m}" for b in bodies.values() for m in b.markers]
            problems.add(f"{path}.marker", f"unknown marker {name!r}{did_you_mean(name, allm)}")
            return None
        if kind not in MARKER_KINDS:
            problems.add(f"{path}.kind", f"unknown marker quantity {kind!r}{did_you_mean(kind, MARKER_KINDS)}")
            return None
        pt = Point(bodies[bname].index, Reader.marker_key(bodies[bname], mname))
        i = 0 if kind == "position" else 1
        return Output(lambda t, s, prm: pt.kin(_ctx(s, prm, t))[i][:, 0],
                      tuple(f"{name}.{c}" for c in ("x", "y", "z")))
    cyls = {c.name: c for c in model.cylinders}
    springs = {sp.name: sp for sp in model.springs}
    if name in cyls:
        cyl = cyls[name]
        if kind not in CYL_KINDS:
            problems.add(f"{path}.kind", f"unknown cylinder quantity {kind!r}{did_you_mean(kind, CYL_KINDS)} "
                                         f"(known: {', '.join(CYL_KINDS)})")
            return None

        def fn(t: float, s: StepState, prm: Any, _k: str = kind) -> Any:
            ctx = _ctx(s, prm, t)
            j = cyl.p_index
            if _k == "pressure_1":
                return s.p[j:j + 1]
            if _k == "pressure_2":
                return s.p[j + 1:j + 2]
            if _k == "force":
                return cyl.force(ctx, s.p[:, None])[:, 0]
            sv, sd, _ = cyl.kinematics(ctx)
            if _k == "stroke":
                return sv[:, 0]
            if _k == "stroke_rate":
                return sd[:, 0]
            V1, V2 = cyl.volumes(sv, prm)
            return (V1 if _k == "volume_1" else V2)[:, 0]
        return Output(fn, (f"{name}.{kind}",))
    if name in springs:
        spr = springs[name]
        if kind not in SPRING_KINDS:
            problems.add(f"{path}.kind", f"unknown spring quantity {kind!r}{did_you_mean(kind, SPRING_KINDS)}")
            return None
        i = SPRING_KINDS.index(kind)
        return Output(lambda t, s, prm: spr.state(_ctx(s, prm, t))[i][:, 0], (f"{name}.{kind}",))
    allnames = list(cyls) + list(springs)
    problems.add(f"{path}.element", f"unknown element {name!r}{did_you_mean(name, allnames)} "
                                    f"(elements: {', '.join(allnames) or 'none'})")
    return None
