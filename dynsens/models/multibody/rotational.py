r"""Rotational spring-damper between two bodies about an axis.

With the frame (u_1, v_1, w_1) fixed in body_1 (w_1 the axis, global at the initial pose) and
u_2 fixed in body_2 (equal to u_1 at the initial pose), the relative rotation is

    θ = atan2(v_1·u_2, u_1·u_2)                 (rad, 0 at the initial pose)

the angle of u_2 about the axis (exact for bodies joined by a revolute about w; otherwise the
angle of u_2's projection on the plane ⟂ w_1).  The torque on body_2 about the axis is

    T = −(k (θ − θ_0) + c θ̇)                    (N·m; k in N·m/rad, c in N·m·s/rad)

and −T on body_1; its generalized force is T ∂θ/∂q (virtual work, δW = T δθ), with
∂θ = (x ∂y − y ∂x)/(x² + y²), x = u_1·u_2, y = v_1·u_2, applied through the directions'
transposed Jacobians, so it is consistent with the joints' terms and complex-safe.  θ is
measured within (−π, π): :meth:`RotationalSpringDamper.check` stops a run whose relative
rotation passes ±0.9π rather than let the measure wrap.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import ModelError
from .bodies import Ctx, Direction
from .forces import ForceElement
from .rotations import atan2_cs

Array = np.ndarray


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

    def state(self, ctx: Ctx) -> tuple[Array, Array, Array, Array, Array]:
        """(θ, θ̇, T, x, y) each (1, k) for the batch in ctx."""
        full = Ctx(ctx.q, ctx.qd, np.zeros_like(ctx.q), ctx.params, ctx.t)
        U1, V1, U2 = (d.kin(full) for d in (self.u1, self.v1, self.u2))
        x = np.sum(U1[0] * U2[0], axis=0, keepdims=True)
        y = np.sum(V1[0] * U2[0], axis=0, keepdims=True)
        xd = np.sum(U1[1] * U2[0] + U1[0] * U2[1], axis=0, keepdims=True)
        yd = np.sum(V1[1] * U2[0] + V1[0] * U2[1], axis=0, keepdims=True)
        r2 = x * x + y * y
        th = atan2_cs(y, x)
        thd = (x * yd - y * xd) / r2
        pv = ctx.params.pv
        T = -(pv[self.k] * (th - pv[self.free_angle]) + pv[self.c] * thd)
        return th, thd, T, x, y

    def add(self, ctx: Ctx, out: Array) -> None:
        full = Ctx(ctx.q, ctx.qd, np.zeros_like(ctx.q), ctx.params, ctx.t)
        _, _, T, x, y = self.state(ctx)
        U1, V1, U2 = (d.kin(full)[0] for d in (self.u1, self.v1, self.u2))
        r2 = x * x + y * y
        cy, cx = T * x / r2, -T * y / r2          # T ∂θ = cy ∂(v1·u2) + cx ∂(u1·u2)
        self.v1.apply(full, cy * U2, out)
        self.u1.apply(full, cx * U2, out)
        self.u2.apply(full, cy * V1 + cx * U1, out)

    def check(self, t: float, ctx: Ctx) -> None:
        """ModelError when the relative rotation leaves (−0.9π, 0.9π)."""
        th = float(np.real(self.state(ctx)[0][0, 0]))
        if abs(th) > 0.9 * np.pi:
            raise ModelError(
                f"rotational spring-damper '{self.name}': relative rotation θ = {th:.4g} rad at t = "
                f"{t:.6g} s; θ is measured within (−π, π) and runs stop beyond ±0.9π rather than let "
                "the measure wrap (one spring covers less than half a turn either way)")
