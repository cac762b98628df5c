r"""Nonlinear viscous dampers: F = c·|v|^α·sign v, regularized at rest.

The law c|v|^α sign v (0 < α < 1 for the fluid dampers of building and bridge practice) has an
infinite slope at v = 0 for α < 1, where every run starts.  Each damper therefore uses the
smooth law

.. math:: F(v) = c\,v\,(v^2 + ε^2)^{(α-1)/2},\qquad
          F'(v) = c\,(v^2 + ε^2)^{(α-3)/2}\,(α v^2 + ε^2),

with the relative velocity v = q̇_a − q̇_b and a velocity scale ε (``regularization``): F equals
c|v|^α sign v to a relative (α−1)ε²/(2v²) once |v| ≫ ε, and F' is its exact derivative (the
Newton matrix and the sensitivities use it).  Complex-safe (no abs, no sign).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class NonlinearDampers:
    """Dampers between DOF pairs (index n: ground or a fixed DOF) with parameter indices."""

    names: list[str] = field(default_factory=list)
    dofs: list[list[int]] = field(default_factory=list)
    c: list[int] = field(default_factory=list)
    alpha: list[int] = field(default_factory=list)
    eps: list[int] = field(default_factory=list)

    def freeze(self) -> None:
        """Index arrays for vectorized evaluation."""
        self.idx = np.array(self.dofs, dtype=int).reshape(-1, 2)
        self.c_idx, self.alpha_idx, self.eps_idx = (np.array(v, int) for v in (self.c, self.alpha, self.eps))

    def __len__(self) -> int:
        return len(self.names)

    def velocity(self, qde: np.ndarray) -> np.ndarray:
        """Relative velocities v (..., n_e) from extended velocities (..., n+1)."""
        return qde[..., self.idx[:, 0]] - qde[..., self.idx[:, 1]]

    def force(self, v: np.ndarray, pv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Forces F(v) and slopes F'(v) (..., n_e); ``pv`` may carry leading batch axes."""
        c, a, eps = pv[..., self.c_idx], pv[..., self.alpha_idx], pv[..., self.eps_idx]
        s = v * v + eps * eps
        F = c * v * s ** ((a - 1) / 2)
        dF = c * s ** ((a - 3) / 2) * (a * v * v + eps * eps)
        return F, dF

    def tangent(self, qde: np.ndarray, pv: np.ndarray) -> tuple[list, list, list]:
        """(rows, cols, values) of ∂F/∂q̇ for one state."""
        _, dF = self.force(self.velocity(qde), pv)
        a, b = self.idx[:, 0], self.idx[:, 1]
        return [a, b, a, b], [a, b, b, a], [dF, dF, -dF, -dF]

    def design_touch(self) -> list[tuple[list[int], np.ndarray]]:
        """Per damper: the parameter indices it reads and its DOFs (column colouring)."""
        return [([self.c_idx[e], self.alpha_idx[e], self.eps_idx[e]], self.idx[e]) for e in range(len(self))]
