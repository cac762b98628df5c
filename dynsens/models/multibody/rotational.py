r"""Rotational spring-damper between two bodies about an axis.

With the frame (u_1, v_1, w_1) fixed in body_1 (w_1 the axis, global at the initial pose) and
u_2 fixed in body_2 (equal to u_1 at the initial pose), the relative rotation is

    θ = atan2(y, x),   x = u_1·u_2,   y = v_1·u_2        (rad, 0 at the initial pose)

the angle of u_2 about the axis (exact for bodies joined by a revolute about w; otherwise the
angle of u_2's projection on the plane ⟂ w_1).  The torque on body_2 about the axis is

    T = −(k (θ − θ_0) + c θ̇)                    (N·m; k in N·m/rad, c in N·m·s/rad)

and −T on body_1; its generalized force is T ∂θ/∂q (virtual work, δW = T δθ), with
∂θ = (x ∂y − y ∂x)/(x² + y²).  θ is measured within (−π, π): :meth:`RotationalSpringDamper.check_angle`
stops a run whose relative rotation passes ±0.9π rather than let the measure wrap.

The law is written once, in plain arithmetic (:func:`torque_law`, :func:`rotational_law`,
:func:`weight_rows`) that numpy arrays and the compiled kernel's scalars both evaluate, real or
complex: the multibody kernel holds x and y as two products of its own (:mod:`.kernel`), whose
weights in R1 = … − Q_ext are w_x = −T ∂θ/∂x, w_y = −T ∂θ/∂y; the term-by-term element below
(outputs, the reference of the tests) evaluates the same functions.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import ModelError
from ...solver._jit import register_jitable
from .bodies import Ctx, Direction
from .forces import ForceElement

Array = np.ndarray

# entries of rotational_law's result: the state, then the weights and their partials
ANGLE, RATE, TORQUE, W_X, W_Y = 0, 1, 2, 3, 4
LAW_SIZE = 13


@register_jitable          # (called by rotational_law, also when that is compiled)
def torque_law(th: Any, thd: Any, k: Any, c: Any, th0: Any) -> tuple[Any, Any, Any]:
    """Torque T = −(k (θ − θ_0) + c θ̇) (N·m) on body_2 and its partials ∂T/∂θ, ∂T/∂θ̇."""
    return -(k * (th - th0) + c * thd), -k, -c


def rotational_law(x: Any, y: Any, xd: Any, yd: Any, k: Any, c: Any, th0: Any) -> tuple:
    """The spring-damper at the products x = u_1·u_2, y = v_1·u_2 and their rates ẋ, ẏ, in
    plain arithmetic (numpy arrays or scalars, real or complex; the compiled kernel's too).

    Returns (θ, θ̇, T, w_x, w_y, ∂w_x/∂x, ∂w_x/∂y, ∂w_x/∂ẋ, ∂w_x/∂ẏ, ∂w_y/∂x, ∂w_y/∂y,
    ∂w_y/∂ẋ, ∂w_y/∂ẏ): the angle (rad, within (−π, π)), its rate (rad/s), the torque (N·m)
    and the weights w = −T ∂θ/∂(x, y) of the products in R1 (so that R1 += w_x ∂x/∂q +
    w_y ∂y/∂q is −Q_ext) with their partials.  atan2 carries a complex-step perturbation to
    first order (its real part from the real parts, the perturbation from ∂θ).
    """
    xr, yr = x.real, y.real
    r2 = x * x + y * y
    th = np.arctan2(yr, xr) + (xr * y - yr * x) / (xr * xr + yr * yr)
    th_x, th_y = -y / r2, x / r2                 # ∂θ/∂(x, y), also ∂θ̇/∂(ẋ, ẏ)
    thd = th_x * xd + th_y * yd
    T, T_th, T_thd = torque_law(th, thd, k, c, th0)
    thd_x = (yd - 2.0 * x * thd) / r2
    thd_y = -(xd + 2.0 * y * thd) / r2
    T_x, T_y = T_th * th_x + T_thd * thd_x, T_th * th_y + T_thd * thd_y
    T_xd, T_yd = T_thd * th_x, T_thd * th_y
    th_xx = 2.0 * x * y / (r2 * r2)              # ∂²θ: th_yy = −th_xx
    th_xy = (y * y - x * x) / (r2 * r2)
    return (th, thd, T, -T * th_x, -T * th_y,
            -(T_x * th_x + T * th_xx), -(T_y * th_x + T * th_xy), -T_xd * th_x, -T_yd * th_x,
            -(T_x * th_y + T * th_xy), -(T_y * th_y - T * th_xx), -T_xd * th_y, -T_yd * th_y)


def weight_rows(law: Any, jx: Any, jy: Any, dx: Any, dy: Any) -> tuple[Any, Any, Any, Any]:
    """(∂w_x/∂q, ∂w_y/∂q, ∂w_x/∂q̇, ∂w_y/∂q̇) from a :func:`rotational_law` result and the rows
    ∂x/∂q (jx), ∂y/∂q (jy), ∂ẋ/∂q (dx), ∂ẏ/∂q (dy) (∂ẋ/∂q̇ = ∂x/∂q)."""
    return (law[5] * jx + law[6] * jy + law[7] * dx + law[8] * dy,
            law[9] * jx + law[10] * jy + law[11] * dx + law[12] * dy,
            law[7] * jx + law[8] * jy, law[11] * jx + law[12] * jy)


@dataclass(eq=False)
class RotationalSpringDamper(ForceElement):
    """k, c, θ_0 by parameter index; u1, v1 (body_1) and u2 (body_2) directions."""

    name: str
    u1: Direction
    v1: Direction
    u2: Direction
    k: int
    c: int
    free_angle: int

    def constants(self, pv: Array) -> list[Any]:
        """[k, c, θ_0] of a parameter vector (complex-safe)."""
        return [pv[self.k], pv[self.c], pv[self.free_angle]]

    def _law(self, ctx: Ctx) -> tuple[tuple, Array, Array, Array]:
        """(:func:`rotational_law` of the batch in ctx, each (1, k); U1, V1, U2 values)."""
        full = Ctx(ctx.q, ctx.qd, np.zeros_like(ctx.q), ctx.params, ctx.t)
        U1, V1, U2 = (d.kin(full) for d in (self.u1, self.v1, self.u2))

        def dot(a: Array, b: Array) -> Array:
            return np.sum(a * b, axis=0, keepdims=True)
        law = rotational_law(dot(U1[0], U2[0]), dot(V1[0], U2[0]), dot(U1[1], U2[0]) + dot(U1[0], U2[1]),
                             dot(V1[1], U2[0]) + dot(V1[0], U2[1]), *self.constants(ctx.params.pv))
        return law, U1[0], V1[0], U2[0]

    def state(self, ctx: Ctx) -> tuple[Array, Array, Array]:
        """(θ, θ̇, T) each (1, k) for the batch in ctx."""
        law = self._law(ctx)[0]
        return law[ANGLE], law[RATE], law[TORQUE]

    def add(self, ctx: Ctx, out: Array) -> None:
        full = Ctx(ctx.q, ctx.qd, np.zeros_like(ctx.q), ctx.params, ctx.t)
        law, U1, V1, U2 = self._law(ctx)
        cx, cy = -law[W_X], -law[W_Y]            # Q_ext = −(w_x ∂(u1·u2) + w_y ∂(v1·u2))
        self.u1.apply(full, cx * U2, out)
        self.v1.apply(full, cy * U2, out)
        self.u2.apply(full, cx * U1 + cy * V1, out)

    def check_angle(self, t: float, th: float) -> None:
        """ModelError when the relative rotation θ (rad) at t (s) leaves (−0.9π, 0.9π)."""
        if abs(th) > 0.9 * np.pi:
            raise ModelError(
                f"rotational spring-damper '{self.name}': relative rotation θ = {th:.4g} rad at t = "
                f"{t:.6g} s; θ is measured within (−π, π) and runs stop beyond ±0.9π rather than let "
                "the measure wrap (one spring covers less than half a turn either way)")
