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
from typing import TYPE_CHECKING, Any

import numpy as np

from .rotations import E_mul, point_tensor, rmatmul

if TYPE_CHECKING:  # pragma: no cover
    from .kernel import KParams, Layout

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
    point_mass : no inertia; its orientation is held by an orientation lock (:mod:`.pointmass`).
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
    point_mass: bool = False


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
class ParamsCache:
    """What is derived from one :class:`MBParams` and kept with it (the only state kept on a
    parameter set).  Every entry is a function of the set's values alone, which never change
    after :meth:`.model.MultibodyModel.parameters` formed them; the cache lives and dies with
    the set (a new design is a new set), so nothing is ever dropped.

    point_tensors : point tensor of ``vec[key]`` (:func:`.rotations.point_tensor`) by key, as
        :meth:`Ctx.ts` forms them.
    kernels : the kernel parameters of the set (B = 1) per kernel :class:`.kernel.Layout`
        (keyed by the layout object: the model's own, and the left-out redundant equations'
        of :mod:`.redundancy`), as :func:`.kernel.kernel_params` forms them.
    size : the mechanism's size (length units), the largest norm of the set's vectors (1 when
        all are zero), the scale of the default drift limit (:mod:`.drift`).
    """

    point_tensors: dict[str, Array] = field(default_factory=dict)
    kernels: dict["Layout", "KParams"] = field(default_factory=dict)
    size: float | None = None


@dataclass
class MBParams:
    """System parameters of a multibody model for one design.

    pv : the evaluated parameter vector; bodies : per moving body; vec : body-fixed or
    global vectors (3, 1) by key (marker positions, joint points and axes in body axes);
    scal : derived scalars by key (free lengths, areas); x : the design; cache : what is
    derived from these values and kept with them (:class:`ParamsCache`).  The values are never
    changed once formed: the caches depend on it.
    """

    pv: Array
    bodies: list[BodyParams]
    vec: dict[str, Array]
    scal: dict[str, Any]
    x: Array
    cache: ParamsCache = field(default_factory=ParamsCache, init=False, repr=False, compare=False)

    def size(self) -> float:
        """The mechanism's size (length units): the largest norm of the vectors (real parts),
        1 when there are none or all are zero; formed once per set."""
        if self.cache.size is None:
            size = max((float(np.linalg.norm(np.real(v))) for v in self.vec.values()), default=1.0)
            self.cache.size = size if size > 0 else 1.0
        return self.cache.size


class Ctx:
    """Batched state (q, q̇, q̈ each (n_q, k)) plus parameters and a per-call cache."""

    def __init__(self, q: Array, qd: Array, qdd: Array, params: MBParams, t: float):
        self.q, self.qd, self.qdd, self.params, self.t = q, qd, qdd, params, t
        self.cache: dict[int, Array] = {}   # Term.kin: (3, 3, k) per term
        self.forces: dict[int, tuple["Term", Array]] = {}
        self.pending: list[tuple[Any, Array]] = []
        self._ps: dict[int, Array] = {}
        self.k = q.shape[1]
        dt = np.result_type(q, qd, qdd, float)
        self._zero3 = np.zeros((3, 1), dt)
        self._p_ground = np.array([[1.0], [0.0], [0.0], [0.0]], dt)
        self._zero4 = np.zeros((4, 1), dt)

    def ts(self, key: str) -> Array:
        """point_tensor of params.vec[key], cached with the parameters."""
        cache = self.params.cache.point_tensors
        t = cache.get(key)
        if t is None:
            t = point_tensor(self.params.vec[key])
            cache[key] = t
        return t

    def pstack(self, i: int) -> Array:
        """[p, ṗ, p̈] (3, 4, k) of moving body i, cached per call."""
        L = self._ps.get(i)
        if L is None:
            a = 7 * i + 3
            L = np.stack([self.q[a:a + 4], self.qd[a:a + 4], self.qdd[a:a + 4]])
            self._ps[i] = L
        return L

    def rstack(self, i: int) -> Array:
        """[r, ṙ, r̈] (3, 3, k) of moving body i."""
        a = 7 * i
        return np.stack([self.q[a:a + 3], self.qd[a:a + 3], self.qdd[a:a + 3]])

    def push(self, term: "Term", f: Array) -> None:
        """Accumulate a force f (3, k) on ``term``; :meth:`flush` applies all of them."""
        if not term.bodies or all(b == GROUND for b in term.bodies):
            return
        key = id(term)
        hit = self.forces.get(key)
        self.forces[key] = (term, f if hit is None else hit[1] + f)

    def flush(self, out: Array) -> None:
        """out += Σ (∂term/∂q)ᵀ f over the accumulated forces."""
        for term, f in self.forces.values():
            term.apply(self, f, out)
        self.forces.clear()
        for eq, lam in self.pending:
            eq.apply(self, lam, out)
        self.pending.clear()

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

    def kin(self, ctx: Ctx) -> Array:
        """(value, velocity, acceleration) stacked (3, 3, k), cached per call."""
        key = id(self)
        hit = ctx.cache.get(key)
        if hit is None:
            parts = self._kin(ctx)
            hit = parts if isinstance(parts, np.ndarray) else np.stack(np.broadcast_arrays(*parts))
            ctx.cache[key] = hit
        return hit

    def _kin(self, ctx: Ctx) -> tuple[Array, Array, Array] | Array:
        raise NotImplementedError

    def apply(self, ctx: Ctx, f: Array, out: Array) -> None:
        """out (n_q, k) += (∂value/∂q)ᵀ f for f (3, k)."""
        raise NotImplementedError

    @property
    def bodies(self) -> tuple[int, ...]:
        return ()


def _constant_kin(ctx: Ctx, key: str) -> tuple[Array, Array, Array]:
    """A global vector params.vec[key] that does not move: value, zero rate, zero acceleration."""
    s = ctx.params.vec[key]
    z = np.zeros((3, ctx.k), np.result_type(s, ctx.q))
    return s + z, z, z


@dataclass(eq=False)
class Direction(Term):
    """Body-fixed vector params.vec[key] (body axes) of body ``body``, in global components."""

    body: int
    key: str

    def _kin(self, ctx: Ctx) -> tuple[Array, Array, Array] | Array:
        if self.body == GROUND:
            return _constant_kin(ctx, self.key)
        return _quad_kin(ctx.ts(self.key), ctx.pstack(self.body))

    def _apply_rotation(self, ctx: Ctx, f: Array, out: Array) -> int:
        """Add the Euler-parameter part of the generalized force; returns the body's offset in q."""
        a = 7 * self.body
        out[a + 3:a + 7] += 2.0 * _jt_apply(ctx.ts(self.key), ctx.q[a + 3:a + 7], f)
        return a

    def apply(self, ctx: Ctx, f: Array, out: Array) -> None:
        if self.body != GROUND:
            self._apply_rotation(ctx, f, out)

    @property
    def bodies(self) -> tuple[int, ...]:
        return (self.body,)


@dataclass(eq=False)
class Point(Direction):
    """Point fixed in body ``body`` at body-frame offset params.vec[key] from the COM."""

    def _kin(self, ctx: Ctx) -> tuple[Array, Array, Array] | Array:
        if self.body == GROUND:
            return _constant_kin(ctx, self.key)
        return ctx.rstack(self.body) + _quad_kin(ctx.ts(self.key), ctx.pstack(self.body))

    def apply(self, ctx: Ctx, f: Array, out: Array) -> None:
        if self.body != GROUND:
            a = self._apply_rotation(ctx, f, out)
            out[a:a + 3] += f


@dataclass(eq=False)
class Const(Term):
    """A constant global vector params.vec[key]."""

    key: str

    def _kin(self, ctx: Ctx) -> tuple[Array, Array, Array] | Array:
        return _constant_kin(ctx, self.key)

    def apply(self, ctx: Ctx, f: Array, out: Array) -> None:
        return


@dataclass(eq=False)
class Diff(Term):
    """Difference a − b of two terms (e.g. the separation of two joint points)."""

    a: Term
    b: Term

    def _kin(self, ctx: Ctx) -> tuple[Array, Array, Array] | Array:
        return self.a.kin(ctx) - self.b.kin(ctx)

    def apply(self, ctx: Ctx, f: Array, out: Array) -> None:
        self.a.apply(ctx, f, out)
        self.b.apply(ctx, -f, out)

    @property
    def bodies(self) -> tuple[int, ...]:
        return tuple(dict.fromkeys(self.a.bodies + self.b.bodies))


def _jt_apply(Ts: Array, p: Array, f: Array) -> Array:
    """g (4, k) = Σ_{a,l} Ts[a,k,l] p_l f_a, i.e. ½ ∂(A(p)s·f)/∂p."""
    fp = (f[:, None, :] * p[None, :, :]).reshape(12, -1)
    return rmatmul(Ts.transpose(1, 0, 2).reshape(4, 12), fp)


def _quad_kin(Ts: Array, L: Array) -> Array:
    """Stacked [A(p)s, 2Q(p,ṗ)s, 2Q(p,p̈)s + 2Q(ṗ,ṗ)s] (3, 3, k) for L = [p, ṗ, p̈] (3, 4, k)."""
    tmp = rmatmul(Ts.transpose(0, 2, 1).reshape(12, 4), L[:2]).reshape(2, 1, 3, 4, -1)   # [i, ., a, l, n]
    W = (tmp * L[None, :, None]).sum(3)                                            # [i, j, a, n]
    return np.stack([W[0, 0], 2.0 * W[1, 0], 2.0 * (W[0, 2] + W[1, 1])])


def angular_velocity(p: Array, pd: Array) -> Array:
    """Global angular velocity ω = 2 E(p) ṗ (rad/s), (3, k)."""
    return 2.0 * E_mul(p, pd)
