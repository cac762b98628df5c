r"""Constraint equations and joints.

Every scalar constraint is of the form

.. math:: φ(q, t) = \sum_k c_k(t)\, (a_k · b_k) - s(t)

with vector terms a_k, b_k (points, body-fixed directions, point separations, constant
vectors; :mod:`.bodies`) and time coefficients c_k, s (constants or prescribed motions).
From the terms' values, velocities and accelerations each equation returns
``(Φ, Φ̇, Φ̈)`` where ``Φ̈ = J_Φ q̈ − F_c`` contains the acceleration-free part F_c of
method.md §1 (with ``F_c = −(J_Φ q̇)_q q̇ − 2 ∂J_Φ/∂t q̇ − Φ_tt``), and applies
``J_Φᵀ λ`` through the terms' transposed Jacobians.  The normalisation of the Euler
parameters ``pᵀp − 1 = 0`` is one :class:`NormEq` per body.

Joints (body_1 = i, body_2 = j; P_i, P_j the joint point fixed in each body,
d = P_j − P_i; (u_i, v_i, w_i) an orthonormal frame fixed in body i with w_i the joint
axis, u_j, v_j, w_j the same vectors fixed in body j at the initial pose):

================  ================================================  ===  =============
type              equations                                         #    force rows
================  ================================================  ===  =============
spherical         e_x·d, e_y·d, e_z·d (global components)           3    0-2
revolute          spherical + u_i·w_j, v_i·w_j                      5    0-2
cylindrical       u_i·d, v_i·d, u_i·w_j, v_i·w_j                    4    0-1
prismatic         cylindrical + u_i·v_j                             5    0-1
fixed             spherical + u_i·w_j, v_i·w_j, u_i·v_j             6    0-2
planar_pin        u_i·d, v_i·d (in-plane coincidence only)          2    0-1
distance          (d·d)/(2L) − L/2 (a rod; :mod:`.pointmass`)       1    –
driving (angle)   sin θ(t) (u_i·u_j) − cos θ(t) (v_i·u_j)           1    –
driving (slide)   w_i·d − s(t)                                      1    –
driving (body)    e_k·r_j − x(t)                                    1    –
driving (dist.)   (d·d)/(2L(t)) − L(t)/2                            1    –
================  ================================================  ===  =============

Position equations are in length units, so their multipliers are forces; the
orientation equations are dimensionless and their multipliers are moments.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from .bodies import GROUND, Const, Ctx, Diff, Direction, Point, Term

Array = np.ndarray
# a time coefficient: (t, params) -> (value, first derivative, second derivative).  The
# coefficients of the model's joints read only params.pv and use only broadcasting arithmetic,
# so that the stacked parameter sets (pv (B, n)) are evaluated in one call, each level a scalar
# or (B,), and a block of times t (K, 1) with them, each level (K, B)
Coef = Callable[..., tuple[Any, Any, Any]]  # coef(t, params) -> value, rate, acceleration


def const_coef(value: float) -> Coef:
    """A constant coefficient."""
    if value == 1.0:
        return ONE
    return lambda t, prm: (value, 0.0, 0.0)


def ONE(t: float, prm: Any) -> tuple[float, float, float]:
    """The unit coefficient (recognised by :class:`.kernel.Layout`: no per-step evaluation)."""
    return 1.0, 0.0, 0.0


class Prescribed:
    """A prescribed coordinate x(t): ``self(t, prm)`` returns (x, ẋ, ẍ) (units of the coordinate,
    per s, per s²); :meth:`sin` and :meth:`cos` give the coefficients of an angle driver."""

    def __call__(self, t: float, prm: Any) -> tuple[Any, Any, Any]:
        raise NotImplementedError

    def sin(self) -> Coef:
        def fn(t: float, prm: Any) -> tuple[Any, Any, Any]:
            th, thd, thdd = self(t, prm)
            s, c = np.sin(th), np.cos(th)
            return s, c * thd, -s * thd * thd + c * thdd
        return fn

    def cos(self, sign: float = 1.0) -> Coef:
        def fn(t: float, prm: Any) -> tuple[Any, Any, Any]:
            th, thd, thdd = self(t, prm)
            s, c = np.sin(th), np.cos(th)
            return sign * c, -sign * s * thd, sign * (-c * thd * thd - s * thdd)
        return fn


@dataclass(frozen=True)
class Motion(Prescribed):
    """Prescribed motion x(t) = offset + rate t + amplitude sin(2π f t + phase).

    Indices into the parameter vector; units of the driven coordinate (length or rad),
    rate per s, f in Hz, phase in rad.  Evaluated for one parameter set (pv (n,)) or for
    stacked ones (pv (B, n)) at once.
    """

    offset: int
    rate: int
    amplitude: int
    frequency: int
    phase: int

    def __call__(self, t: float, prm: Any) -> tuple[Any, Any, Any]:
        pv = prm.pv
        x0, v, a, f, ph = (pv[..., self.offset], pv[..., self.rate], pv[..., self.amplitude],
                           pv[..., self.frequency], pv[..., self.phase])
        w = 2.0 * np.pi * f
        s, c = np.sin(w * t + ph), np.cos(w * t + ph)
        return x0 + v * t + a * s, v + a * w * c, -a * w * w * s


class Equation:
    """One scalar constraint; subclasses give (Φ, Φ̇, Φ̈) and apply J_Φᵀ λ."""

    def evaluate(self, ctx: Ctx) -> tuple[Array, Array, Array]:
        raise NotImplementedError

    def apply(self, ctx: Ctx, lam: Array, out: Array) -> None:
        """out (n_q, k) += (∂φ/∂q)ᵀ λ."""
        raise NotImplementedError

    def push(self, ctx: Ctx, lam: Array) -> None:
        """Like apply, but accumulated in ctx until ctx.flush(out) (shared terms applied once)."""
        raise NotImplementedError


@dataclass(eq=False)
class DotEq(Equation):
    """φ = Σ c_k(t) (a_k·b_k) − s(t)."""

    terms: list[tuple[Coef, Term, Term]]
    shift: Coef | None = None

    def evaluate(self, ctx: Ctx) -> tuple[Array, Array, Array]:
        t, prm = ctx.t, ctx.params
        phi: Any = 0.0
        phid: Any = 0.0
        phidd: Any = 0.0
        for coef, a, b in self.terms:
            c, cd, cdd = coef(t, prm)
            D = (a.kin(ctx)[:, None] * b.kin(ctx)[None]).sum(2)      # all 9 dot products
            x = D[0, 0:1]
            xd = D[1, 0:1] + D[0, 1:2]
            xdd = D[2, 0:1] + 2.0 * D[1, 1:2] + D[0, 2:3]
            phi = phi + c * x
            phid = phid + cd * x + c * xd
            phidd = phidd + cdd * x + 2.0 * cd * xd + c * xdd
        if self.shift is not None:
            s, sd, sdd = self.shift(t, prm)
            phi, phid, phidd = phi - s, phid - sd, phidd - sdd
        return phi, phid, phidd

    def apply(self, ctx: Ctx, lam: Array, out: Array) -> None:
        self.push(ctx, lam)
        ctx.flush(out)

    def push(self, ctx: Ctx, lam: Array) -> None:
        """Accumulate this equation's J_Φᵀ λ as forces on its terms (applied by ctx.flush)."""
        for coef, a, b in self.terms:
            c = coef(ctx.t, ctx.params)[0]
            if a.bodies:
                ctx.push(a, c * lam * b.kin(ctx)[0])
            if b.bodies:
                ctx.push(b, c * lam * a.kin(ctx)[0])


@dataclass(eq=False)
class NormEq(Equation):
    """Euler-parameter normalisation pᵀp − 1 = 0 of one body."""

    body: int

    def evaluate(self, ctx: Ctx) -> tuple[Array, Array, Array]:
        _, _, _, p, pd, pdd = ctx.body(self.body)
        return (np.sum(p * p, axis=0, keepdims=True) - 1.0,
                2.0 * np.sum(p * pd, axis=0, keepdims=True),
                2.0 * np.sum(p * pdd + pd * pd, axis=0, keepdims=True))

    def apply(self, ctx: Ctx, lam: Array, out: Array) -> None:
        a = 7 * self.body + 3
        out[a:a + 4] += 2.0 * lam * ctx.q[a:a + 4]

    def push(self, ctx: Ctx, lam: Array) -> None:
        """Applied directly (no shared terms)."""
        ctx.pending.append((self, lam))


JOINT_TYPES = ("revolute", "prismatic", "spherical", "cylindrical", "fixed", "planar_pin", "distance",
               "driving")
N_EQUATIONS = {"spherical": 3, "revolute": 5, "cylindrical": 4, "prismatic": 5, "fixed": 6,
               "planar_pin": 2, "distance": 1, "driving": 1}
FORCE_ROWS = {"spherical": (0, 1, 2), "revolute": (0, 1, 2), "cylindrical": (0, 1),
              "prismatic": (0, 1), "fixed": (0, 1, 2), "planar_pin": (0, 1), "driving": ()}
EQ_LABELS = {
    "spherical": ("x", "y", "z"),
    "revolute": ("x", "y", "z", "u.w", "v.w"),
    "cylindrical": ("u.d", "v.d", "u.w", "v.w"),
    "prismatic": ("u.d", "v.d", "u.w", "v.w", "u.v"),
    "fixed": ("x", "y", "z", "u.w", "v.w", "u.v"),
    "planar_pin": ("u.d", "v.d"),
    "driving": ("drive",),
}


@dataclass(eq=False)
class Joint:
    """A joint: its equations, the rows it owns in λ, and what outputs need.

    Attributes
    ----------
    name, kind : as in the case.
    body_1, body_2 : body indices (GROUND = -1).
    eqs : its scalar equations; ``rows`` their positions in Φ / λ (set by the model).
    point_2 : the joint point on body 2 (reaction moments are taken about it).
    frame_1 : (u_i, v_i, w_i) directions of the joint frame fixed in body 1.
    all_equations : (label, equation) of all its equations, set when redundant equations were
        left out of Φ (``eqs`` and ``labels`` keep the independent ones).
    """

    name: str
    kind: str
    body_1: int
    body_2: int
    eqs: list[Equation]
    point_2: Point | None = None
    frame_1: tuple[Direction, Direction, Direction] | None = None
    rows: tuple[int, ...] = ()
    force_rows: tuple[int, ...] = ()
    labels: tuple[str, ...] = ()
    extra: dict[str, Any] = field(default_factory=dict)
    # (label, equation) of all its equations when some of a redundant set were left out of Φ
    all_equations: tuple[tuple[str, Equation], ...] = ()


def make_joint(name: str, kind: str, b1: int, b2: int, keys: dict[str, str]) -> Joint:
    """Equations of a standard joint; ``keys`` name the params.vec entries.

    keys: s1, s2 (joint point in body 1/2 axes), u1, v1, w1 (frame in body 1 axes),
    u2, v2, w2 (same frame in body 2 axes), ex, ey, ez (global basis).
    """
    one = const_coef(1.0)
    P1, P2 = Point(b1, keys["s1"]), Point(b2, keys["s2"])
    d = Diff(P2, P1)
    u1, v1, w1 = Direction(b1, keys["u1"]), Direction(b1, keys["v1"]), Direction(b1, keys["w1"])
    u2, v2, w2 = Direction(b2, keys["u2"]), Direction(b2, keys["v2"]), Direction(b2, keys["w2"])
    ex, ey, ez = Const(keys["ex"]), Const(keys["ey"]), Const(keys["ez"])
    sph: list[Equation] = [DotEq([(one, ex, d)]), DotEq([(one, ey, d)]), DotEq([(one, ez, d)])]
    par: list[Equation] = [DotEq([(one, u1, w2)]), DotEq([(one, v1, w2)])]
    tra: list[Equation] = [DotEq([(one, u1, d)]), DotEq([(one, v1, d)])]
    lock: list[Equation] = [DotEq([(one, u1, v2)])]
    eqs = {"spherical": sph, "revolute": sph + par, "cylindrical": tra + par,
           "prismatic": tra + par + lock, "fixed": sph + par + lock, "planar_pin": tra}[kind]
    return Joint(name, kind, b1, b2, eqs, point_2=P2, frame_1=(u1, v1, w1),
                 force_rows=FORCE_ROWS[kind], labels=EQ_LABELS[kind],
                 extra={"d": d, "u2": u2, "w1": w1})


def make_driver(name: str, target: Joint | None, motion: Prescribed, *, body: int = GROUND,
                axis_key: str = "", origin_key: str = "") -> Joint:
    """A driving constraint on a joint's coordinate (angle of a revolute/cylindrical,
    slide of a prismatic/cylindrical) or on a body's COM coordinate along a global axis."""
    if target is not None:
        u1, v1, w1 = target.frame_1  # type: ignore[misc]
        u2 = target.extra["u2"]
        if target.extra.get("drive") == "angle":
            eq = DotEq([(motion.sin(), u1, u2), (motion.cos(-1.0), v1, u2)])
        else:
            eq = DotEq([(const_coef(1.0), w1, target.extra["d"])], shift=motion)
        return Joint(name, "driving", target.body_1, target.body_2, [eq], labels=("drive",),
                     extra={"target": target.name})
    eq = DotEq([(const_coef(1.0), Const(axis_key), Point(body, origin_key))], shift=motion)
    return Joint(name, "driving", GROUND, body, [eq], labels=("drive",))
