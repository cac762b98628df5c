r"""Quantities of a multibody model that responses and events can read.

Spec forms (``quantity:`` in a case):

* ``{joint: J, kind: reaction_force}`` (3, global; the force the joint exerts on body_2,
  ``f = −(∂Φ_J/∂r_2)ᵀ λ_J``), ``reaction_force_norm`` (1, ``sqrt(f·f)``; for revolute,
  spherical, planar_pin and prismatic joints this is the norm of the multipliers of the
  joint's position-level equations, weir_model §3.4), ``reaction_moment`` (3, global, about
  the joint point on body_2), ``reaction_force_joint_frame`` (3, along u, v, w of the joint
  frame fixed in body_1), ``multipliers`` (the joint's λ); for a joint of a dependent set of
  redundant equations all of these come from the minimum-norm multipliers over all its
  equations, the left-out ones included (:mod:`.reaction_split`);
* ``{body: B, kind: position | velocity | acceleration | angle_z | angular_velocity |
  angular_velocity_z}`` (angle_z = direction of the body x-axis in the x–y plane, rad);
* ``{marker: body.marker, kind: position | velocity}``;
* ``{element: NAME, kind: K}`` for a flexible member (:mod:`.members`) or the element of a force
  law (:mod:`.force_law`; its ``output_kinds``), e.g. a hydraulic cylinder's ``stroke |
  stroke_rate | pressure_1 | pressure_2 | force | volume_1 | volume_2``, a spring's
  ``length | length_rate | force``, a rotational spring-damper's ``angle | angle_rate | torque``
  (torque on body_2 about the axis, N·m).

All functions are complex-safe.  Quantities that are linear in the state and independent of
the design are declared ``linear``; joint reaction forces, body angles and angular
velocities, cylinder and spring quantities are ``batched`` (evaluated from the kernel's
kinematics for all gradient directions in one call) and ``autonomous`` (a block of steps in
one call; reaction forces only when no product of the joint's own equations has a
time-dependent coefficient).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from ...errors import ProblemCollector
from .._keys import check_keys, did_you_mean
from ..base import Output, StepState
from .bodies import GROUND, Ctx, Point, angular_velocity
from .reaction_split import MinimumNormSplit, split_is_timed, split_of
from .rotations import E_mul, atan2_cs, cross

if TYPE_CHECKING:  # pragma: no cover
    from .model import MultibodyModel

JOINT_KINDS = ("reaction_force", "reaction_force_norm", "reaction_moment",
               "reaction_force_joint_frame", "multipliers")
BODY_KINDS = ("position", "velocity", "acceleration", "angle_z", "angular_velocity",
              "angular_velocity_z")
MARKER_KINDS = ("position", "velocity")


def _ctx(s: StepState, params: Any, t: float) -> Ctx:
    return Ctx(s.q[:, None], s.qd[:, None], s.qdd[:, None], params, t)


def _kin(model: "MultibodyModel", s: StepState, prm: Any) -> tuple[Any, Any, bool]:
    """(kinematics, multipliers (B, n_λ), batched) for a plain or a batched state."""
    return model.kinematics(s, prm), np.atleast_2d(s.lam), s.q.ndim == 2


def _out(v: Any, batched: bool) -> Any:
    """(B, k) for a batched call, (k,) otherwise, from v (B, k)."""
    return v if batched else v[0]


def _angle_z(e0: Any, e1: Any, e2: Any, e3: Any) -> Any:
    """Direction (rad) in the x–y plane of the body x-axis A(p)e_x = (e0² + e1² − e2² − e3²,
    2(e1e2 + e0e3), ·), from the Euler parameters (scalars or arrays, complex-safe)."""
    return atan2_cs(2.0 * (e1 * e2 + e0 * e3), e0 * e0 + e1 * e1 - e2 * e2 - e3 * e3)


def _reaction(model: "MultibodyModel", jt: Any) -> Callable[[float, StepState, Any], Any]:
    """f (3,) (or (B, 3)): force of joint jt on body_2 (body_1 when body_2 is the ground),
    −(∂Φ_J/∂r)ᵀλ_J, from the products of the joint's equations (batched)."""
    lay = model.layout
    prods = np.flatnonzero(lay.S[list(jt.rows)].any(axis=0))
    eq_of = np.argmax(lay.S[:, prods], axis=0)
    sign, b = (-1.0, jt.body_2) if jt.body_2 != GROUND else (1.0, jt.body_1)
    on_b = (lay.pb == b) * lay.is_point
    # side a of product p pulls with b and vice versa: weights on the swapped sides [b; a]
    mab = np.concatenate([lay.MA[prods] @ on_b, lay.MB[prods] @ on_b])       # (2 n_p,)
    swapped = np.concatenate([prods + lay.n_prod, prods])                    # rows of ABV[:, (s, p)]
    eq_twice = np.concatenate([eq_of, eq_of])
    prods_twice = np.concatenate([prods, prods])
    timed = reaction_is_timed(model, jt)

    def fn(t: float, s: StepState, prm: Any) -> Any:
        kin, lam, batched = _kin(model, s, prm)
        w = (sign * mab) * lam[:, eq_twice]
        if timed:
            w = w * model.coefficients(t, kin.kp)[0][:, prods_twice, 0]
        sides = kin.ABV[:, :, :, 0].reshape(kin.ABV.shape[0], -1, 3)[:, swapped]   # (B, 2 n_p, 3)
        f = (w[:, None, :] @ sides)[:, 0]
        return _out(f, batched)
    return fn


def reaction_is_timed(model: "MultibodyModel", jt: Any) -> bool:
    """Whether the reaction of joint jt depends on t beyond the state: some product of its
    equations has a time-dependent coefficient (a driving joint's own equation)."""
    lay = model.layout
    prods = set(np.flatnonzero(lay.S[list(jt.rows)].any(axis=0)).tolist())
    return any(i in prods for i, _ in lay.coefs)


def _split_reaction(model: "MultibodyModel", split: MinimumNormSplit, jt: Any
                    ) -> Callable[[float, StepState, Any], Any]:
    """f (3,) (or (B, 3)): force of joint jt of a dependent set on body_2 (body_1 when body_2 is
    the ground), −(∂Φ_J/∂r)ᵀλ_J over all its equations with the minimum-norm multipliers
    (:mod:`.reaction_split`; batched)."""
    sign, b = (-1.0, jt.body_2) if jt.body_2 != GROUND else (1.0, jt.body_1)

    def fn(t: float, s: StepState, prm: Any) -> Any:
        return _out(sign * split.joint(jt, t, s.q, s.lam, prm)[1][:, 7 * b:7 * b + 3], s.q.ndim == 2)
    return fn


def _axial(model: "MultibodyModel", el: Any, kind: str) -> Callable[[float, StepState, Any], Any]:
    """A spring's or cylinder's quantity (1,) (or (B, 1)) from the kernel (batched)."""
    lay = model.layout
    i = lay.axial.index(el)

    def fn(t: float, s: StepState, prm: Any) -> Any:
        kin, _, batched = _kin(model, s, prm)
        x = kin.X[:, lay.n_cp + i]
        L = np.sqrt(x[:, 0])
        c = kin.kp.ec[i]
        if kind in ("length", "stroke", "volume_1", "volume_2"):
            v = L if kind == "length" else L - c[:, 2]
            if kind in ("volume_1", "volume_2"):
                v = el._volumes(v, c)[0 if kind == "volume_1" else 1]
            return _out(v[:, None], batched)
        Ld = x[:, 1] / (2.0 * L)
        if kind in ("length_rate", "stroke_rate"):
            v = Ld
        else:
            j = getattr(el, "p_index", 0)
            P = el.law(L, Ld, np.atleast_2d(s.p)[:, j:j + el.n_pressures], t, kin.kp.pv, c)[0]
            v = P if kind == "force" and el in model.cylinders else -P
        return _out(v[:, None], batched)
    return fn


def _joint_load(model: "MultibodyModel", jt: Any, t: float, s: StepState, params: Any
                ) -> tuple[Any, Any, Ctx]:
    """(f, n) force (3,) on body_2 and moment (3,) about its joint point; global frame.  A joint
    of a dependent set exerts the force of its minimum-norm multipliers (:mod:`.reaction_split`)."""
    ctx = _ctx(s, params, t)
    split = split_of(model)
    if split is not None and jt.name in split.positions:
        out = split.joint(jt, t, s.q, s.lam, params)[1][0][:, None]
    else:
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
    heads = [k for k in _RESOLVERS if k in spec]
    if len(heads) != 1:
        problems.add(path, "name exactly one of 'joint', 'body', 'marker', 'element'")
        return None
    head = heads[0]
    check_keys(spec, path, (head, "kind"), problems, required=("kind",))
    name, kind = spec[head], spec.get("kind")
    if not isinstance(name, str):
        problems.add(f"{path}.{head}", f"expected the name of one {head}, found {name!r}")
        return None
    return _RESOLVERS[head](model, name, kind, path, problems)


def _known_kind(kind: Any, kinds: tuple[str, ...], what: str, path: str, problems: ProblemCollector,
                listed: bool = True) -> bool:
    """Whether kind is one of kinds; otherwise reports it under ``path.kind`` (with the list when ``listed``)."""
    if kind in kinds:
        return True
    known = f" (known: {', '.join(kinds)})" if listed else ""
    problems.add(f"{path}.kind", f"unknown {what} quantity {kind!r}{did_you_mean(kind, kinds)}{known}")
    return False


_JOINT_LABELS = {"reaction_force": ("Fx", "Fy", "Fz"), "reaction_force_norm": ("F",),
                 "reaction_moment": ("Mx", "My", "Mz"), "reaction_force_joint_frame": ("Fu", "Fv", "Fw")}


def _joint_output(model: "MultibodyModel", name: str, kind: Any, path: str,
                  problems: ProblemCollector) -> Output | None:
    """A joint's reaction or multipliers (JOINT_KINDS)."""
    joints = {j.name: j for j in model.joints}
    if name not in joints:
        problems.add(f"{path}.joint", f"unknown joint {name!r}{did_you_mean(name, joints)} "
                                      f"(joints: {', '.join(joints)})")
        return None
    jt = joints[name]
    if not _known_kind(kind, JOINT_KINDS, "joint", path, problems):
        return None
    # a joint of a dependent set: its minimum-norm multipliers over all its equations
    split = split_of(model)
    if split is not None and name not in split.positions:
        split = None
    if kind == "multipliers":
        return _multipliers(model, jt, split)
    if jt.kind == "driving":
        problems.add(f"{path}.kind", "a driving constraint has only 'multipliers'")
        return None
    labs = tuple(f"{name}.{c}" for c in _JOINT_LABELS[kind])
    if kind in ("reaction_force", "reaction_force_norm"):
        force = _reaction(model, jt) if split is None else _split_reaction(model, split, jt)
        timed = reaction_is_timed(model, jt) if split is None else split_is_timed(model)

        def rfn(t: float, s: StepState, prm: Any, _k: str = kind) -> Any:
            f = force(t, s, prm)
            return f if _k == "reaction_force" else np.sqrt(np.sum(f * f, axis=-1, keepdims=True))
        # t enters only through time-dependent coefficients of the joint's own products
        return Output(rfn, labs, batched=True, autonomous=not timed)

    def fn(t: float, s: StepState, prm: Any, _jt: Any = jt, _k: str = kind) -> Any:
        f, n, ctx = _joint_load(model, _jt, t, s, prm)
        if _k == "reaction_moment":
            return n
        u, v, w = (d.kin(ctx)[0][:, 0] for d in _jt.frame_1)
        return np.array([np.sum(u * f), np.sum(v * f), np.sum(w * f)])
    return Output(fn, labs)


def _multipliers(model: "MultibodyModel", jt: Any, split: MinimumNormSplit | None) -> Output:
    """A joint's multipliers: its own λ, or the minimum-norm ones of its dependent set."""
    name = jt.name
    if split is not None:
        return Output(lambda t, s, prm, _s=split: _out(_s.joint(jt, t, s.q, s.lam, prm)[0], s.q.ndim == 2),
                      tuple(f"{name}.{lab}" for lab in split.labels[name]),
                      batched=True, autonomous=not split_is_timed(model))
    rows = np.array(jt.rows)
    return Output(lambda t, s, prm: s.lam[rows], tuple(f"{name}.{lab}" for lab in jt.labels), linear=True)


_BODY_COMPONENTS = {"position": ("x", "y", "z"), "velocity": ("vx", "vy", "vz"),
                    "acceleration": ("ax", "ay", "az"), "angle_z": ("angle_z",),
                    "angular_velocity": ("wx", "wy", "wz"), "angular_velocity_z": ("wz",)}


def _body_output(model: "MultibodyModel", name: str, kind: Any, path: str,
                 problems: ProblemCollector) -> Output | None:
    """A moving body's motion (BODY_KINDS)."""
    body = next((b for b in model.bodies if b.name == name), None)
    if body is None:
        names = [b.name for b in model.bodies]
        problems.add(f"{path}.body", f"unknown body {name!r}{did_you_mean(name, names)} "
                                     f"(moving bodies: {', '.join(names)})")
        return None
    if not _known_kind(kind, BODY_KINDS, "body", path, problems):
        return None
    a = 7 * body.index
    body_labels = tuple(f"{name}.{c}" for c in _BODY_COMPONENTS[kind])
    if kind in ("position", "velocity", "acceleration"):
        field = {"position": "q", "velocity": "qd", "acceleration": "qdd"}[kind]
        return Output(lambda t, s, prm: getattr(s, field)[a:a + 3], body_labels, linear=True)

    def fn(t: float, s: StepState, prm: Any, _k: str = kind) -> Any:
        if _k == "angle_z":
            # (one state, at every step for an event: its scalars, not arrays of one entry)
            e = s.q[a + 3:a + 7] if s.q.ndim == 1 else s.q[:, a + 3:a + 7].T     # (4,) or (4, B)
            angle = _angle_z(e[0], e[1], e[2], e[3])
            return np.array([angle]) if s.q.ndim == 1 else angle[:, None]
        p = np.atleast_2d(s.q)[:, a + 3:a + 7].T                     # (4, B)
        v = angular_velocity(p, np.atleast_2d(s.qd)[:, a + 3:a + 7].T)
        v = v if _k == "angular_velocity" else v[2:3]
        return v.T if s.q.ndim == 2 else v[:, 0]
    return Output(fn, body_labels, "rad" if kind == "angle_z" else "", batched=True, autonomous=True)


def _marker_output(model: "MultibodyModel", name: str, kind: Any, path: str,
                   problems: ProblemCollector) -> Output | None:
    """A marker's position or velocity (MARKER_KINDS), ``body.marker``."""
    from .spec import Reader
    if "." not in name:
        problems.add(f"{path}.marker", f"expected 'body.marker', found {name!r}")
        return None
    bname, mname = name.split(".", 1)
    bodies = {b.name: b for b in model.bodies}
    bodies["ground"] = model.ground
    if bname not in bodies or mname not in bodies[bname].markers:
        allm = [f"{b.name}.{m}" for b in bodies.values() for m in b.markers]
        problems.add(f"{path}.marker", f"unknown marker {name!r}{did_you_mean(name, allm)}")
        return None
    if not _known_kind(kind, MARKER_KINDS, "marker", path, problems, listed=False):
        return None
    pt = Point(bodies[bname].index, Reader.marker_key(bodies[bname], mname))
    i = 0 if kind == "position" else 1
    return Output(lambda t, s, prm: pt.kin(_ctx(s, prm, t))[i][:, 0],
                  tuple(f"{name}.{c}" for c in ("x", "y", "z")))


def _element_output(model: "MultibodyModel", name: str, kind: Any, path: str,
                    problems: ProblemCollector) -> Output | None:
    """A force element's quantity: a flexible member's (:mod:`.members`; first, as a bar member is
    also among the springs), or that of an element of a force law (:mod:`.force_law`)."""
    from .force_law import load_laws
    from .members import member_output
    families: list[tuple[list[Any], Callable[..., Output | None]]] = [(model.members, member_output)]
    families += [(law.elements(model), law.output) for law in load_laws().values()]
    for elements, resolve in families:
        el = next((e for e in elements if e.name == name), None)
        if el is not None:
            return resolve(model, el, kind, path, problems)
    allnames = list(dict.fromkeys(e.name for elements, _ in families for e in elements))
    problems.add(f"{path}.element", f"unknown element {name!r}{did_you_mean(name, allnames)} "
                                    f"(elements: {', '.join(allnames) or 'none'})")
    return None


# one resolver per spec head (its key in the quantity mapping)
_RESOLVERS: dict[str, Callable[["MultibodyModel", str, Any, str, ProblemCollector], Output | None]] = {
    "joint": _joint_output, "body": _body_output, "marker": _marker_output, "element": _element_output}
