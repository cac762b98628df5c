r"""Rigid bodies, their coordinates, and kinematic vector terms.

Coordinates: body ``i`` (0-based, ground excluded) owns ``q[7i:7i+3] = r`` (global
position of the centre of mass, length unit of the case) and ``q[7i+3:7i+7] = p``
(Euler parameters, see :mod:`.rotations`).  The ground has no coordinates
(index ``GROUND = -1``; r = 0, A = I).

Inertia (Euler-parameter form, Nikravesh/Haug): with the kinetic energy
``T = ½ m ṙᵀṙ + 2 ṗᵀ Gᵀ J' G ṗ`` (``J'`` the inertia tensor about the COM in body
axes), Lagrange's equations are exactly

    m r̈ = F,        4 Gᵀ J' G p̈ − 8 G(ṗ)ᵀ J' G(ṗ) p = 2 Eᵀ n  (+ constraint forces)

valid for any p (no normalisation assumed); the mass matrix ``4 GᵀJ'G`` is singular
along p and becomes regular together with the normalisation constraint pᵀp − 1 = 0.

Vector terms (:class:`Point`, :class:`Direction`, :class:`Diff`, :class:`Const`) give a
vector's value, velocity and acceleration for a batch of states, and apply a "force"
``f`` through the transposed Jacobian (``out += (∂v/∂q)ᵀ f``).  All joints and force
elements are built from them, so J_Φ, Φ̇ and Φ̈ are consistent by construction.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .rotations import E_mul, G_mul, GT_mul, gvec, qbil, rotate

GROUND = -1
Array = np.ndarray


@dataclass
class BodyDef:
    """A body as read from the case: indices into the parameter vector.

    Attributes
    ----------
    name : body name.
    index : body number (0-based; coordinates q[7 index : 7 index + 7]).
    mass : index of the mass (mass unit).
    inertia : 6 indices (xx, yy, zz, xy, xz, yz) of the inertia tensor about the COM in
        body axes (mass · length²).
    position : 3 indices, COM at t0 (initial guess of the assembly).
    orientation : ("axis", axis indices (3), angle index) or ("ep", 4 indices) or ("identity",).
    velocity, angular_velocity : 3 indices each (global frame; length/s, rad/s).
    markers : name → (3 indices, frame) with frame ``body`` (coordinates relative to the
        COM in body axes) or ``global`` (global coordinates in the initial pose).
    """

    name: str
    index: int
    mass: int = -1
    inertia: tuple[int, ...] = ()
    position: tuple[int, ...] = ()
    orientation: tuple[Any, ...] = ("identity",)
    velocity: tuple[int, ...] = ()
    angular_velocity: tuple[int, ...] = ()
    markers: dict[str, tuple[tuple[int, ...], str]] = field(default_factory=dict)


@dataclass
class BodyParams:
    """Evaluated body data for one design (complex-safe)."""

    mass: Any
    inertia: Array          # (3, 3) about the COM, body axes
    r0: Array               # (3,) COM at t0 (guess)
    p0: Array               # (4,) Euler parameters at t0 (guess, normalised)
    v0: Array               # (3,) COM velocity (guess)
    w0: Array               # (3,) angular velocity, global (guess)


@dataclass
class MBParams:
    """System parameters of a multibody model for one design.

    pv : the evaluated parameter vector; bodies : per moving body; vec : body-fixed or
    global vectors (3, 1) by key (marker positions, joint points and axes in body axes);
    scal : derived scalars by key (free lengths, areas); x : the design.
    """

    pv: Array
    bodies: list[BodyParams]
    vec: dict[str, Array]
    scal: dict[str, Any]
    x: Array


class Ctx:
    """Batched state (q, q̇, q̈ each (n_q, k)) plus parameters and a per-call cache."""

    def __init__(self, q: Array, qd: Array, qdd: Array, params: MBParams, t: float):
        self.q, self.qd, self.qdd, self.params, self.t = q, qd, qdd, params, t
        self.cache: dict[int, tuple[Array, Array, Array]] = {}
        self.k = q.shape[1]
        dt = np.result_type(q, qd, qdd, float)
        self._zero3 = np.zeros((3, 1), dt)
        self._p_ground = np.array([[1.0], [0.0], [0.0], [0.0]], dt)
        self._zero4 = np.zeros((4, 1), dt)

    def body(self, i: int) -> tuple[Array, Array, Array, Array, Array, Array]:
        """(r, ṙ, r̈, p, ṗ, p̈) of body i; constants for the ground."""
        if i == GROUND:
            z3, z4 = self._zero3, self._zero4
            return z3, z3, z3, self._p_ground, z4, z4
        a = 7 * i
        q, qd, qdd = self.q, self.qd, self.qdd
        return (q[a:a + 3], qd[a:a + 3], qdd[a:a + 3],
                q[a + 3:a + 7], qd[a + 3:a + 7], qdd[a + 3:a + 7])


class Term:
    """A vector quantity of the state; see the module docstring."""

    def kin(self, ctx: Ctx) -> tuple[Array, Array, Array]:
        """(value, velocity, acceleration), each (3, k), cached per call."""
        key = id(self)
        hit = ctx.cache.get(key)
        if hit is None:
            hit = self._kin(ctx)
            ctx.cache[key] = hit
        return hit

    def _kin(self, ctx: Ctx) -> tuple[Array, Array, Array]:
        raise NotImplementedError

    def apply(self, ctx: Ctx, f: Array, out: Array) -> None:
        """out (n_q, k) += (∂value/∂q)ᵀ f for f (3, k)."""
        raise NotImplementedError

    @property
    def bodies(self) -> tuple[int, ...]:
        return ()


@dataclass(eq=False)
class Point(Term):
    """Point fixed in body ``body`` at body-frame offset params.vec[key] from the COM."""

    body: int
    key: str

    def _kin(self, ctx: Ctx) -> tuple[Array, Array, Array]:
        s = ctx.params.vec[self.key]
        r, rd, rdd, p, pd, pdd = ctx.body(self.body)
        if self.body == GROUND:
            z = np.zeros((3, ctx.k), np.result_type(s, ctx.q))
            return s + z, z, z
        return (r + rotate(p, s), rd + 2.0 * qbil(p, pd, s),
                rdd + 2.0 * qbil(p, pdd, s) + 2.0 * qbil(pd, pd, s))

    def apply(self, ctx: Ctx, f: Array, out: Array) -> None:
        if self.body == GROUND:
            return
        a = 7 * self.body
        p = ctx.q[a + 3:a + 7]
        out[a:a + 3] += f
        out[a + 3:a + 7] += 2.0 * gvec(p, ctx.params.vec[self.key], f)

    @property
    def bodies(self) -> tuple[int, ...]:
        return (self.body,)


@dataclass(eq=False)
class Direction(Term):
    """Body-fixed vector params.vec[key] (body axes) of body ``body``, in global components."""

    body: int
    key: str

    def _kin(self, ctx: Ctx) -> tuple[Array, Array, Array]:
        s = ctx.params.vec[self.key]
        if self.body == GROUND:
            z = np.zeros((3, ctx.k), np.result_type(s, ctx.q))
            return s + z, z, z
        _, _, _, p, pd, pdd = ctx.body(self.body)
        return rotate(p, s), 2.0 * qbil(p, pd, s), 2.0 * qbil(p, pdd, s) + 2.0 * qbil(pd, pd, s)

    def apply(self, ctx: Ctx, f: Array, out: Array) -> None:
        if self.body == GROUND:
            return
        a = 7 * self.body
        out[a + 3:a + 7] += 2.0 * gvec(ctx.q[a + 3:a + 7], ctx.params.vec[self.key], f)

    @property
    def bodies(self) -> tuple[int, ...]:
        return (self.body,)


@dataclass(eq=False)
class Const(Term):
    """A constant global vector params.vec[key]."""

    key: str

    def _kin(self, ctx: Ctx) -> tuple[Array, Array, Array]:
        s = ctx.params.vec[self.key]
        z = np.zeros((3, ctx.k), np.result_type(s, ctx.q))
        return s + z, z, z

    def apply(self, ctx: Ctx, f: Array, out: Array) -> None:
        return


@dataclass(eq=False)
class Diff(Term):
    """Difference a − b of two terms (e.g. the separation of two joint points)."""

    a: Term
    b: Term

    def _kin(self, ctx: Ctx) -> tuple[Array, Array, Array]:
        ka, kb = self.a.kin(ctx), self.b.kin(ctx)
        return ka[0] - kb[0], ka[1] - kb[1], ka[2] - kb[2]

    def apply(self, ctx: Ctx, f: Array, out: Array) -> None:
        self.a.apply(ctx, f, out)
        self.b.apply(ctx, -f, out)

    @property
    def bodies(self) -> tuple[int, ...]:
        return tuple(dict.fromkeys(self.a.bodies + self.b.bodies))


def inertial_forces(ctx: Ctx, n_bodies: int, out: Array) -> None:
    """out (n_q, k) += M(q) q̈ − Q_v(q, q̇) for all bodies (Euler-parameter form)."""
    for i, bp in enumerate(ctx.params.bodies):
        r, rd, rdd, p, pd, pdd = ctx.body(i)
        a = 7 * i
        J = bp.inertia
        out[a:a + 3] += bp.mass * rdd
        out[a + 3:a + 7] += 4.0 * GT_mul(p, J @ G_mul(p, pdd)) - 8.0 * GT_mul(pd, J @ G_mul(pd, p))


def angular_velocity(p: Array, pd: Array) -> Array:
    """Global angular velocity ω = 2 E(p) ṗ (rad/s), (3, k)."""
    return 2.0 * E_mul(p, pd)
