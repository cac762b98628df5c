r"""Point masses and distance joints.

A body with ``point_mass: true`` has a mass and no rotational inertia.  It keeps the seven
coordinates of every body, with J' = 0, and an *orientation lock* — the three orientation
equations of a fixed joint to the ground, u_g·w_b, v_g·w_b, u_g·v_b — holds its Euler
parameters at the identity (the normalisation fixes the fourth).  The iteration matrix stays
regular: the rotational rows of M vanish, but the lock and the normalisation determine p̈.
A point mass carries no moment, so everything attached to it acts at its mass point:

* joints: ``spherical``, ``distance``, a ``planar_pin`` with the point mass as body_2, and body
  or distance drivers (joints with orientation equations would load the lock);
* forces: global point forces, spring-dampers and cylinders;
* every attachment point (marker or joint point) must coincide with the mass point; this is
  checked for each design at the assembly (:func:`check_attachments`).

The lock's multipliers (labels ``<body>.orientation.u.w`` …) are moments that vanish whenever
nothing applies a moment — which the rules above ensure.

A ``distance`` joint keeps two markers at a given distance L (a massless rod with spherical
ends): (d·d)/(2L) − L/2 = 0, d = P_2 − P_1, in length units; its multiplier is the rod force
along d (M q̈ + J_Φᵀλ = Q: −λ d/|d| on P_2).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import ModelError
from ...case_keys import allowed
from .._keys import check_keys
from .bodies import GROUND, BodyDef, Diff, Direction, Point
from .joints import DotEq, Joint, const_coef
from .spec import Reader

DISTANCE_KEYS = allowed("multibody.distance_joint")
POINT_MASS_JOINTS = ("spherical", "distance", "driving")


def orientation_lock(rd: Reader, body: BodyDef) -> Joint:
    """The three orientation equations of a fixed joint between the ground and ``body``."""
    name = f"{body.name}.orientation"
    keys = rd.frame_recipes(name, rd.vec3([0.0, 0.0, 1.0], f"{name}.axis"), rd.ground, body)
    u1, v1 = Direction(GROUND, keys["u1"]), Direction(GROUND, keys["v1"])
    v2, w2 = Direction(body.index, keys["v2"]), Direction(body.index, keys["w2"])
    one = const_coef(1.0)
    return Joint(name, "orientation_lock", GROUND, body.index,
                 [DotEq([(one, u1, w2)]), DotEq([(one, v1, w2)]), DotEq([(one, u1, v2)])],
                 labels=("u.w", "v.w", "u.v"))


def read_distance_joint(rd: Reader, j: dict, jp: str, name: str) -> Joint | None:
    """``{type: distance, body_1, body_2, marker_1, marker_2, length}``."""
    if not check_keys(j, jp, DISTANCE_KEYS, rd.problems,
                      required=("body_1", "body_2", "marker_1", "marker_2", "length")):
        return None
    pair = rd.two_bodies(j, jp)
    if pair is None:
        return None
    b1, b2 = pair
    k1, k2 = rd.marker(b1, j.get("marker_1"), f"{jp}.marker_1"), rd.marker(b2, j.get("marker_2"), f"{jp}.marker_2")
    il = rd.num(j.get("length"), f"{jp}.length", positive=True)
    if k1 is None or k2 is None or il < 0:
        return None
    rd.attached(b1, k1, f"marker_1 of joint '{name}'")
    rd.attached(b2, k2, f"marker_2 of joint '{name}'")
    d = Diff(Point(b2.index, k2), Point(b1.index, k1))
    eq = DotEq([(lambda t, prm, _i=il: (0.5 / prm.pv[..., _i], 0.0, 0.0), d, d)],
               shift=lambda t, prm, _i=il: (0.5 * prm.pv[..., _i], 0.0, 0.0))
    return Joint(name, "distance", b1.index, b2.index, [eq], labels=("rod",))


def attachment_problem(kind: str, role: str, body: BodyDef) -> str | None:
    """Why a joint of ``kind`` cannot attach to the point mass ``body`` as ``role`` (or None)."""
    if not body.point_mass:
        return None
    if kind in POINT_MASS_JOINTS or (kind == "planar_pin" and role == "body_2"):
        return None
    return (f"'{body.name}' is a point mass, which carries no moment: a {kind} joint"
            f"{' as body_1' if kind == 'planar_pin' else ''} would constrain its orientation; use a "
            "spherical or distance joint (or a planar_pin with the point mass as body_2)")


def check_attachments(model: Any, params: Any) -> None:
    """ModelError when a point attached to a point mass is not at its mass point (this design)."""
    for body_name, key, what in model.point_mass_attachments:
        v = np.real(np.asarray(params.vec[key])).ravel()
        size = 1.0 + max((float(np.linalg.norm(np.real(x))) for x in params.vec.values()), default=0.0)
        if float(np.linalg.norm(v)) > 1e-9 * size:
            raise ModelError(
                f"point mass '{body_name}': {what} is {np.linalg.norm(v):.4g} from its mass point; a "
                "point mass carries no moment, so joints and forces attach at its position (markers "
                "[0, 0, 0], joint points at the body's position)")
