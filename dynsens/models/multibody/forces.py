r"""Applied forces: gravity, point forces, torques, point-to-point spring-dampers.

Each element adds its generalized force ``Q_ext`` (n_q, k) to an accumulator through
the transposed Jacobians of the vector terms (virtual work), for a batch of states:

* gravity: ``m g`` on every moving body's COM (g a global vector, length/s²);
* point force ``f(t) = F·φ(t)`` at a point of a body, F given in global axes or in
  body axes (a follower force, ``f = A(p) F̄``); φ a dimensionless time function;
* torque ``n(t) = N·φ(t)``, global (``Q_p = 2 Eᵀ n``) or body axes (``Q_p = 2 Gᵀ n̄``);
* spring-damper between points P_1 (body_1) and P_2 (body_2), tension positive:
  ``F = k (L − L0) + k3 (L − L0)³ + c L̇``, ``L = sqrt(d·d)``, ``d = P_2 − P_1``,
  ``L̇ = d·ḋ / L``; ``−F d/L`` acts on P_2 and ``+F d/L`` on P_1.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..timefunctions import TimeFunction
from .actuators import AxialElement
from .bodies import GROUND, Ctx, Diff, Point
from .rotations import ET_mul, GT_mul, dot, rotate

Array = np.ndarray


class ForceElement:
    """Base class: ``add(ctx, out)`` adds Q_ext; ``name`` for outputs.

    Elements with ``closed_form = True`` also give Q_ext for a batch of entries directly from
    (t, q, parameter vectors) and its exact q-Jacobian (:meth:`add_batch`, :meth:`add_jacobian`):
    the residual then needs no per-entry context and the linearization no complex step.
    Elements with ``exact_jacobians = True`` keep the per-entry residual (:meth:`add`) but give
    their exact q- and q̇-Jacobians (:meth:`add_jacobians`).
    """

    name: str
    closed_form = False
    exact_jacobians = False

    def add(self, ctx: Ctx, out: Array) -> None:
        raise NotImplementedError

    def add_batch(self, t: float, q: Array, pv: Array, out: Array) -> None:
        """out (E, n_q) += Q_ext at time t (s) of the states q (E, n_q) with the parameter
        vectors pv (E or 1, n_pv)."""
        raise NotImplementedError

    def add_jacobian(self, t: float, q: Array, pv: Array, out: Array) -> None:
        """out (n_q, n_q) += ∂Q_ext/∂q at one state q (n_q,), parameter vector pv (n_pv,)."""
        raise NotImplementedError

    def add_jacobians(self, t: float, q: Array, qd: Array, prm: Any, Kq: Array, Kqd: Array) -> None:
        """Kq += ∂Q_ext/∂q, Kqd += ∂Q_ext/∂q̇ (n_q, n_q) at one state q, q̇ (n_q,), parameters prm."""
        raise NotImplementedError


@dataclass(eq=False)
class Gravity(ForceElement):
    """Weight of every moving body; g = pv[idx] (3 entries, length/s²)."""

    idx: tuple[int, int, int]
    name: str = "gravity"

    def add(self, ctx: Ctx, out: Array) -> None:
        g = np.array([ctx.params.pv[i] for i in self.idx]).reshape(3, 1)
        for i, bp in enumerate(ctx.params.bodies):
            out[7 * i:7 * i + 3] += bp.mass * g


def _amplitude(ctx: Ctx, idx: tuple[int, int, int], fn: TimeFunction) -> Array:
    """The vector (3, 1) of parameter entries ``idx`` scaled by the time function at ctx.t."""
    pv = ctx.params.pv
    return np.array([pv[i] for i in idx]).reshape(3, 1) * fn.value(ctx.t, pv)


@dataclass(eq=False)
class PointForce(ForceElement):
    """Force F φ(t) (force unit) at ``point``; ``frame`` is ``global`` or ``body``."""

    name: str
    point: Point
    idx: tuple[int, int, int]
    frame: str
    fn: TimeFunction

    def force(self, ctx: Ctx) -> Array:
        F = _amplitude(ctx, self.idx, self.fn)
        if self.frame == "body" and self.point.body != GROUND:
            a = 7 * self.point.body
            return rotate(ctx.q[a + 3:a + 7], F)
        return F + np.zeros((3, ctx.k))

    def add(self, ctx: Ctx, out: Array) -> None:
        self.point.apply(ctx, self.force(ctx), out)


def _bilinear_tensor(product: Any) -> Array:
    """T (3, 16) with product(p, n) = M(n) p, M(n) = (n @ T).reshape(4, 4), for a quaternion
    product linear in p and in n (E(p)ᵀn, G(p)ᵀn): the images of the unit quaternions."""
    eye = np.eye(4)
    return np.stack([product(eye, np.repeat(e[:, None], 4, axis=1)) for e in np.eye(3)]).reshape(3, 16)


_T_ET, _T_GT = _bilinear_tensor(ET_mul), _bilinear_tensor(GT_mul)


@dataclass(eq=False)
class Torque(ForceElement):
    """Torque N φ(t) (force·length) on ``body``; ``frame`` is ``global`` or ``body``.

    Q_p = 2 E(p)ᵀ n (global) or 2 G(p)ᵀ n̄ (body axes) is linear in p: Q_p = 2 M(n) p, and
    ∂Q_p/∂p = 2 M(n); there is no q̇ dependence.
    """

    name: str
    body: int
    idx: tuple[int, int, int]
    frame: str
    fn: TimeFunction
    closed_form = True

    def add(self, ctx: Ctx, out: Array) -> None:
        if self.body == GROUND:
            return
        n = _amplitude(ctx, self.idx, self.fn)
        a = 7 * self.body
        p = ctx.q[a + 3:a + 7]
        n = n + 0 * p[:3]
        out[a + 3:a + 7] += 2.0 * (GT_mul(p, n) if self.frame == "body" else ET_mul(p, n))

    def _matrices(self, t: float, pv: Array) -> Array:
        """2 M(n) (E, 4, 4) for the torques n = N φ(t) of parameter vectors pv (E, n_pv)."""
        phi = np.asarray(self.fn.value(t, pv))
        n = pv[:, list(self.idx)] * (phi[:, None] if phi.ndim else phi)
        return (2.0 * n @ (_T_GT if self.frame == "body" else _T_ET)).reshape(-1, 4, 4)

    def add_batch(self, t: float, q: Array, pv: Array, out: Array) -> None:
        if self.body == GROUND:
            return
        a = 7 * self.body
        out[:, a + 3:a + 7] += (self._matrices(t, pv) @ q[:, a + 3:a + 7, None])[..., 0]

    def add_jacobian(self, t: float, q: Array, pv: Array, out: Array) -> None:
        if self.body == GROUND:
            return
        a = 7 * self.body
        out[a + 3:a + 7, a + 3:a + 7] += self._matrices(t, pv[None])[0]


def spring_law(L: Any, Ld: Any, k: Any, k3: Any, cd: Any, L0: Any) -> tuple[Any, Any, Any]:
    """Push force P = −F of a spring-damper (tension F = k e + k3 e³ + c L̇, e = L − L0) and
    its partials ∂P/∂L, ∂P/∂L̇, in plain arithmetic (numpy arrays, real or complex, and the
    compiled kernel's scalars alike)."""
    e = L - L0
    return -(k * e + k3 * e * e * e + cd * Ld), -(k + 3.0 * k3 * e * e), -cd


@dataclass(eq=False)
class SpringDamper(ForceElement, AxialElement):
    """Point-to-point spring-damper; parameters k, k3, c, L0 by parameter index.

    ``free_length`` is a key of params.scal (the free length L0, length unit).
    """

    name: str
    d: Diff
    k: int
    k3: int
    c: int
    free_length: str

    n_pressures = 0

    def constants(self, prm: Any) -> Array:
        """[k, k3, c, L0] for one parameter set (complex-safe)."""
        pv = prm.pv
        return np.array([pv[self.k], pv[self.k3], pv[self.c], prm.scal[self.free_length]])

    def law(self, L: Array, Ld: Array, p: Array, t: float, pv: Array, c: Array) -> tuple:
        """Push force P = −F (tension F positive) and its partials for length L and rate L̇
        (arrays of any shape; c the :meth:`constants` with the same leading shape + (4,)).

        Returns (P, P_L, P_L̇, P_p, h, h_L, h_L̇, h_p) in the form of
        :meth:`.hydraulics.HydraulicCylinder.law` (a spring has no pressure states).
        """
        P, P_L, P_Ld = spring_law(L, Ld, *(c[..., i] for i in range(4)))
        return P, P_L, P_Ld + 0 * L, [], [], [], [], []

    law_kind = 0

    def state(self, ctx: Ctx) -> tuple[Array, Array, Array]:
        """(L, L̇, F) each (1, k): length, rate and tension force."""
        dv, dd, _ = self.d.kin(ctx)
        L = np.sqrt(dot(dv, dv))
        Ld = dot(dv, dd) / L
        F = -self.law(L, Ld, np.zeros(0), ctx.t, ctx.params.pv, self.constants(ctx.params))[0]
        return L, Ld, F

    def add(self, ctx: Ctx, out: Array) -> None:
        dv = self.d.kin(ctx)[0]
        L, _, F = self.state(ctx)
        self.d.apply(ctx, -F * dv / L, out)


def total_force_on(elements: list[ForceElement], ctx: Ctx, out: Array) -> Any:
    """Add all elements' generalized forces to out (n_q, k)."""
    for el in elements:
        el.add(ctx, out)
    return out
