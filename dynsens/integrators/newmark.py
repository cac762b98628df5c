r"""Newmark-β with the acceleration as primary unknown (method.md §2).

Predictor from step i-1 and corrector with the new accelerations (and, for first-order
states, the same γ-rule):

.. math::

   q^{pred} = q + Δt\,\dot q + (½-β)Δt^2 \ddot q, \qquad
   \dot q^{pred} = \dot q + (1-γ)Δt\,\ddot q, \qquad p^{pred} = p + (1-γ)Δt\,\dot p

   q_i = q^{pred} + βΔt^2 \ddot q_i,\quad \dot q_i = \dot q^{pred} + γΔt\,\ddot q_i,\quad
   p_i = p^{pred} + γΔt\,\dot p_i

Both maps are linear in the state, so the same code predicts and corrects the primal
vectors (n,) and the sensitivity matrices (n, m).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..models.base import StepState


class Prediction(NamedTuple):
    """Predicted q, q̇, p (the parts of the new state that do not depend on z)."""

    q: np.ndarray
    qd: np.ndarray
    p: np.ndarray


@dataclass(frozen=True)
class Newmark:
    """Newmark-β scheme; β and γ dimensionless (defaults ¼, ½: average acceleration)."""

    beta: float = 0.25
    gamma: float = 0.5

    @property
    def order(self) -> int:
        """Order of accuracy: 2 for γ = ½, 1 otherwise."""
        return 2 if abs(self.gamma - 0.5) < 1e-14 else 1

    def coefficients(self, dt: float) -> tuple[float, float, float]:
        """(c_q, c_qd, c_p) = (∂q/∂q̈, ∂q̇/∂q̈, ∂p/∂ṗ) of the corrector for step size dt (s)."""
        return self.beta * dt * dt, self.gamma * dt, self.gamma * dt

    def predict(self, s: StepState, dt: float) -> Prediction:
        """Predictor from the state at the previous step (vectors or (n, m) matrices)."""
        b, g = self.beta, self.gamma
        return Prediction(
            s.q + dt * s.qd + (0.5 - b) * dt * dt * s.qdd,
            s.qd + (1.0 - g) * dt * s.qdd,
            s.p + (1.0 - g) * dt * s.pd,
        )

    def correct(self, pred: Prediction, qdd: np.ndarray, lam: np.ndarray, pd: np.ndarray,
                dt: float) -> StepState:
        """New state from the prediction and the new unknowns z = (q̈, λ, ṗ)."""
        c_q, c_qd, c_p = self.coefficients(dt)
        return StepState(pred.q + c_q * qdd, pred.qd + c_qd * qdd, qdd, lam,
                         pred.p + c_p * pd, pd)


def make_scheme(name: str, beta: float = 0.25, gamma: float = 0.5) -> Newmark:
    """Build the time-integration scheme named in a case.

    Raises ValueError for γ < ½ (negative numerical damping, unstable) and warns for
    β < γ/2 (only conditionally stable) and γ > ½ (numerical damping, first order).
    """
    if name != "newmark":
        raise ValueError(f"unknown scheme {name!r} (known: newmark)")
    if gamma < 0.5:
        raise ValueError(f"integrator.gamma = {gamma}: must be >= 0.5 (gamma < 1/2 gives "
                         "negative numerical damping and an unstable scheme)")
    if beta < 0:
        raise ValueError(f"integrator.beta = {beta}: must be >= 0")
    if beta < gamma / 2:
        warnings.warn(f"integrator.beta = {beta} < gamma/2 = {gamma / 2}: Newmark is only "
                      "conditionally stable; keep dt below the stability limit or use beta = 1/4",
                      stacklevel=2)
    if gamma > 0.5:
        warnings.warn(f"integrator.gamma = {gamma} > 1/2 adds numerical damping and the scheme "
                      "is only first-order accurate", stacklevel=2)
    return Newmark(beta=beta, gamma=gamma)


def zeros_like_state(s: StepState, m: int | None = None) -> StepState:
    """A StepState of zeros shaped like ``s`` (with m columns when given)."""
    if m is None:
        return StepState(*(np.zeros_like(v) for v in s))
    return StepState(*(np.zeros((v.shape[0], m), dtype=v.dtype) for v in s))


__all__ = ["Newmark", "Prediction", "make_scheme", "zeros_like_state"]
