r"""Follower loads: nodal forces that turn with the node's rotation θ (plane models).

A follower load of magnitude a(t) = value·g(t) acts along the node's local axis e (x or y of
the node frame, which is the global frame rotated by the nodal rotation θ = q_rz):

.. math:: F(t, θ) = a(t)\,R(θ)\,e,\qquad ∂F/∂θ = a(t)\,R'(θ)\,e,

so F_ext depends on the state (the paper's F_ext(q)) and −∂F/∂θ enters ∂F_R/∂q.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..timefunctions import TimeFunction


@dataclass
class FollowerLoads:
    """Loads at DOFs (x, y, rz) of a node, local direction (ex, ey), amplitude index, time function."""

    dofs: list[tuple[int, int, int]] = field(default_factory=list)
    local: list[tuple[float, float]] = field(default_factory=list)
    amp: list[int] = field(default_factory=list)
    fn: list[TimeFunction] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.dofs)

    def _parts(self, t: float, qe: np.ndarray, pv: np.ndarray, k: int) -> tuple[Any, Any, Any, float, float]:
        ix, iy, ir = self.dofs[k]
        ex, ey = self.local[k]
        a = pv[..., self.amp[k]] * self.fn[k].value(t, pv)
        th = qe[..., ir]
        return a, np.cos(th), np.sin(th), ex, ey

    def force(self, t: float, qe: np.ndarray, pv: np.ndarray) -> np.ndarray:
        """F (..., n+1) at time t for extended states qe (..., n+1); pv may carry batch axes."""
        f = np.zeros(np.broadcast_shapes(qe.shape, pv.shape[:-1] + (qe.shape[-1],)), dtype=np.result_type(qe, pv))
        for k in range(len(self)):
            a, c, s, ex, ey = self._parts(t, qe, pv, k)
            ix, iy, _ = self.dofs[k]
            f[..., ix] += a * (c * ex - s * ey)
            f[..., iy] += a * (s * ex + c * ey)
        return f

    def tangent(self, t: float, qe: np.ndarray, pv: np.ndarray) -> tuple[list, list, list]:
        """(rows, cols, values) of ∂F/∂q (one state): only the columns of the rotations."""
        rows, cols, vals = [], [], []
        for k in range(len(self)):
            a, c, s, ex, ey = self._parts(t, qe, pv, k)
            ix, iy, ir = self.dofs[k]
            rows += [np.array([ix]), np.array([iy])]
            cols += [np.array([ir]), np.array([ir])]
            vals += [np.atleast_1d(a * (-s * ex - c * ey)), np.atleast_1d(a * (c * ex - s * ey))]
        return rows, cols, vals

    def design_touch(self) -> list[tuple[list[int], list[int]]]:
        """Per load: the parameter indices it reads and the DOFs it loads (column colouring)."""
        return [([self.amp[k], *self.fn[k].idx], list(self.dofs[k][:2])) for k in range(len(self))]
