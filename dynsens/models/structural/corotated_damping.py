r"""Stiffness-proportional damping on deformation rates: Rayleigh's β K acting in the element's
co-rotated frame, so that a member turning rigidly feels no damping force.

An element kind whose internal force is f = Bᵀ ∂Π/∂e, with local deformations e(u), their
Jacobian B = ∂e/∂u and the constant local stiffness D = ∂²Π/∂e², takes the damping force

.. math:: f_d = β\,Bᵀ D\,\dot e,\qquad \dot e = B\dot u,

the viscous twin of its elastic force.  A rigid motion leaves e, hence ė, zero; for small
rotations B is its initial value and f_d is β K₀ u̇, the classical Rayleigh term.  Its exact
Jacobians, with s = β D ė and H_m = ∂²e_m/∂u²:

.. math:: ∂f_d/∂\dot u = β\,Bᵀ D B,\qquad
          ∂f_d/∂u = \sum_m s_m H_m + β\,Bᵀ D\,[H_m \dot u]_m .

The element sets supply (B, H, D) through a :class:`Deformations` callable; the model sums the
forces and Jacobians here for all of them.  Everything is complex-safe and takes leading batch
axes in the forces.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

Array = np.ndarray
#: (qe (..., n+1), params, hessian) -> (B (..., n_e, m, k), H (n_e, m, k, k) or None, D (..., n_e, m, m))
Deformations = Callable[[Array, dict[str, Any], bool], tuple[Array, Array | None, Array]]


def damping_forces(B: Array, D: Array, ud: Array, beta: Any) -> Array:
    """f_d = β Bᵀ D B u̇ (..., n_e, k) for element velocities ud (..., n_e, k); beta broadcasts
    against (..., n_e)."""
    # sums written out term by term, not einsum or np.sum, and β D formed before it meets the
    # states: numpy's reductions change their order with the array's shape, and the batched
    # residuals of the design partials must have the bits of the single ones
    bD = np.asarray(beta)[..., None, None] * D
    m, k = B.shape[-2], B.shape[-1]
    rate = [_dot([B[..., a, j] for j in range(k)], [ud[..., j] for j in range(k)]) for a in range(m)]
    s = [_dot([bD[..., a, b] for b in range(m)], rate) for a in range(m)]
    return np.stack([_dot([B[..., a, j] for a in range(m)], s) for j in range(k)], axis=-1)


def _dot(x: list, y: list) -> Any:
    """Σ x_i y_i, left to right (elementwise arrays)."""
    total = x[0] * y[0]
    for a, b in zip(x[1:], y[1:]):
        total = total + a * b
    return total


def damping_jacobians(B: Array, H: Array, D: Array, ud: Array, beta: Any) -> tuple[Array, Array]:
    """(∂f_d/∂u, ∂f_d/∂u̇), each (n_e, k, k), at one state."""
    b = np.asarray(beta)[..., None, None]
    BD = np.einsum("emk,emn->enk", B, D)                  # (Bᵀ D)ᵀ: rows n, columns k
    s = np.asarray(beta)[..., None] * np.einsum("enk,ek->en", BD, ud)
    Hu = np.einsum("emkj,ek->emj", H, ud)                 # ∂ė/∂u (H symmetric)
    K = np.einsum("em,emkj->ekj", s, H) + b * np.einsum("enk,enj->ekj", BD, Hu)
    C = b * np.einsum("enk,enj->ekj", BD, B)
    return K, C


@dataclass
class DampedKind:
    """One element kind's share: its DOFs (n_e, k) into the extended vector, a (..., n_e·k) →
    (..., n) scatter, and its :data:`Deformations`."""

    idx: Array
    scatter: Callable[[Array], Array]
    deformations: Deformations


class CorotatedDamping:
    """β Bᵀ D ė summed over the element kinds of a model that turn with their elements."""

    def __init__(self, kinds: list[DampedKind], beta_index: int, n: int):
        self.kinds = [k for k in kinds if len(k.idx)]
        self.beta_index = beta_index
        self.n = n

    def __bool__(self) -> bool:
        return bool(self.kinds)

    def active(self, params: dict[str, Any]) -> bool:
        """Whether there is a damping force: kinds to damp and a β that is not zero (in any of
        the parameter sets, its imaginary part included)."""
        return bool(self.kinds) and bool(np.any(params["pv"][..., self.beta_index]))

    def force(self, qe: Array, qde: Array, params: dict[str, Any]) -> Array:
        """Nodal damping forces (..., n) at extended states qe, qde (..., n+1)."""
        beta = params["pv"][..., self.beta_index]
        f: Any = 0.0
        for kind in self.kinds:
            B, _, D = kind.deformations(qe, params, False)
            fe = damping_forces(B, D, qde[..., kind.idx], np.asarray(beta)[..., None])
            f = f + kind.scatter(fe.reshape(fe.shape[:-2] + (-1,)))
        return f

    def jacobians(self, qe: Array, qde: Array, params: dict[str, Any]) -> list[tuple[Array, Array, Array, Array]]:
        """Per kind (rows, cols, ∂f_d/∂u values, ∂f_d/∂u̇ values) at one state."""
        beta = params["pv"][self.beta_index]
        out = []
        for kind in self.kinds:
            B, H, D = kind.deformations(qe, params, True)
            assert H is not None
            K, C = damping_jacobians(B, H, D, qde[kind.idx], beta)
            k = kind.idx.shape[1]
            rows, cols = np.repeat(kind.idx, k, axis=1).ravel(), np.tile(kind.idx, (1, k)).ravel()
            out.append((rows, cols, K.ravel(), C.ravel()))
        return out
