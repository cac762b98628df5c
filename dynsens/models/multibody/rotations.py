r"""Euler parameters (unit quaternions) and batched, complex-safe vector algebra.

Orientation of a body is described by the Euler parameters ``p = [e0, e1, e2, e3]``
(dimensionless, ``pᵀp = 1`` enforced as one constraint per body).  The rotation
matrix (body → global) is the *quadratic form*

.. math:: A(p) = Q(p, p), \qquad
   Q(a, b) = (a_0 b_0 - \mathbf a\cdot\mathbf b) I + \mathbf a\mathbf b^T + \mathbf b\mathbf a^T
             + a_0 \tilde{\mathbf b} + b_0 \tilde{\mathbf a}

with ``Q`` symmetric and bilinear.  Everything the multibody code needs follows from
that bilinearity, without any normalisation assumption:

* position of a body-fixed vector ``s̄``: ``A s̄ = Q(p,p) s̄``;
* its velocity ``2 Q(p, ṗ) s̄`` and acceleration ``2 Q(p, p̈) s̄ + 2 Q(ṗ, ṗ) s̄``;
* the Jacobian transpose applied to a force ``f`` (virtual work of ``f`` on ``A s̄``):
  ``∂(A s̄ · f)/∂p = 2 g(p, s̄, f)`` with :func:`gvec`.

The matrices of the classical formulation (Nikravesh, Haug) are ``G(p) = [-e, -ẽ + e0 I]``
(body angular velocity ``ω' = 2 G ṗ``) and ``E(p) = [-e, ẽ + e0 I]`` (global angular
velocity ``ω = 2 E ṗ``), ``A = E Gᵀ``.

Batch convention: every vector is an array of shape (3, k) (quaternions (4, k)); the
trailing axis is a batch of independent evaluations (used to form Jacobians by
complex step in one call).  Constant vectors may be given as (3, 1).  All functions
are complex-safe (no abs, no real parts).
"""
from __future__ import annotations

from typing import Any

import numpy as np

Array = np.ndarray


def dot(a: Array, b: Array) -> Array:
    """Column-wise dot product of (3, k) arrays → (1, k) (no conjugation)."""
    return np.sum(a * b, axis=0, keepdims=True)


def cross(a: Array, b: Array) -> Array:
    """Column-wise cross product of (3, k) arrays (broadcasting over k)."""
    return np.stack([a[1] * b[2] - a[2] * b[1],
                     a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def norm(a: Array) -> Array:
    """Complex-safe Euclidean norm sqrt(a·a) of (3, k) columns → (1, k)."""
    return np.sqrt(dot(a, a))


def qbil(a: Array, b: Array, s: Array) -> Array:
    """Q(a, b) s for quaternions a, b (4, k) and a vector s (3, k); see module docstring."""
    av, bv = a[1:], b[1:]
    return ((a[:1] * b[:1] - dot(av, bv)) * s + av * dot(bv, s) + bv * dot(av, s)
            + a[:1] * cross(bv, s) + b[:1] * cross(av, s))


def rotate(p: Array, s: Array) -> Array:
    """A(p) s: body-fixed vector s (3, k) in global components."""
    return qbil(p, p, s)


def gvec(a: Array, s: Array, f: Array) -> Array:
    """g (4, k) with gᵀ b = (Q(a, b) s)·f for every b; so ∂(A(p)s·f)/∂p = 2 g(p, s, f)."""
    av = a[1:]
    sf = dot(s, f)
    g0 = a[:1] * sf + dot(cross(av, s), f)
    gv = -av * sf + f * dot(av, s) + s * dot(av, f) + a[:1] * cross(s, f)
    return np.concatenate([g0, gv])


def G_mul(a: Array, b: Array) -> Array:
    """G(a) b (3, k) for quaternions a, b (4, k)."""
    av, bv = a[1:], b[1:]
    return -av * b[:1] - cross(av, bv) + a[:1] * bv


def GT_mul(a: Array, w: Array) -> Array:
    """G(a)ᵀ w (4, k) for a quaternion a (4, k) and a vector w (3, k)."""
    av = a[1:]
    return np.concatenate([-dot(av, w), cross(av, w) + a[:1] * w])


def E_mul(a: Array, b: Array) -> Array:
    """E(a) b (3, k); the global angular velocity is ω = 2 E(p) ṗ (rad/s)."""
    av, bv = a[1:], b[1:]
    return -av * b[:1] + cross(av, bv) + a[:1] * bv


def ET_mul(a: Array, w: Array) -> Array:
    """E(a)ᵀ w (4, k); a global torque n acts on p through 2 E(p)ᵀ n."""
    av = a[1:]
    return np.concatenate([-dot(av, w), -cross(av, w) + a[:1] * w])


def from_axis_angle(axis: Array, angle: Any) -> Array:
    """Euler parameters (4,) of a rotation by ``angle`` (rad) about ``axis`` (3,), complex-safe."""
    axis = np.asarray(axis)
    n = np.sqrt(np.sum(axis * axis))
    half = 0.5 * angle
    return np.concatenate([[np.cos(half)], np.sin(half) * axis / n])


def rotation_matrix(p: Array) -> Array:
    """A(p) (3, 3) for a single quaternion p (4,)."""
    cols = [rotate(np.asarray(p).reshape(4, 1), np.eye(3)[:, j:j + 1])[:, 0] for j in range(3)]
    return np.stack(cols, axis=1)


def atan2_cs(y: Array, x: Array) -> Array:
    """atan2 that carries a complex-step perturbation (first order in the imaginary part)."""
    if not (np.iscomplexobj(y) or np.iscomplexobj(x)):
        return np.arctan2(y, x)
    yr, xr = np.real(y), np.real(x)
    return np.arctan2(yr, xr) + (xr * y - yr * x) / (xr * xr + yr * yr)


def perpendicular_pair(w: Array) -> tuple[Array, Array]:
    """Unit vectors u, v (3,) with (u, v, w) right-handed orthonormal, for a unit w (3,).

    u is built from the global basis vector least aligned with w (chosen on real parts),
    so the pair depends smoothly on w near a given design.
    """
    k = int(np.argmin(np.abs(np.real(w))))
    e = np.zeros(3)
    e[k] = 1.0
    u = cross(w.reshape(3, 1), e.reshape(3, 1))[:, 0]
    u = u / np.sqrt(np.sum(u * u))
    v = cross(w.reshape(3, 1), u.reshape(3, 1))[:, 0]
    return u, v


def rmatmul(A: Array, X: Array) -> Array:
    """A @ X for a real A and a real or complex X (complex matmul with mixed types is very
    slow in numpy, so the real and imaginary parts are multiplied separately)."""
    if np.iscomplexobj(X):
        return (A @ X.real) + 1j * (A @ X.imag)
    return A @ X


def matmul_real(X: Array, A: Array) -> Array:
    """X @ A for a real A and a real or complex X (see :func:`rmatmul`)."""
    if np.iscomplexobj(X):
        return (X.real @ A) + 1j * (X.imag @ A)
    return X @ A


def _tensors() -> tuple[Array, Array, Array]:
    """Constant tensors of the bilinear forms: Q(a,b)_ab = T[a,b,k,l] a_k b_l,
    G(a) b = Gt[i,k,l] a_k b_l, E(a) b = Et[i,k,l] a_k b_l."""
    E4, I3 = np.eye(4), np.eye(3)
    T = np.zeros((3, 3, 4, 4))
    Gt = np.zeros((3, 4, 4))
    Et = np.zeros((3, 4, 4))
    for k in range(4):
        for l in range(4):
            a, b = E4[:, k:k + 1], E4[:, l:l + 1]
            Gt[:, k, l] = G_mul(a, b)[:, 0]
            Et[:, k, l] = E_mul(a, b)[:, 0]
            for j in range(3):
                T[:, j, k, l] = qbil(a, b, I3[:, j:j + 1])[:, 0]
    return T, Gt, Et


T_Q, T_G, T_E = _tensors()


def point_tensor(s: Array) -> Array:
    """Ts (3, 4, 4) with Q(a, b) s = Ts[:, k, l] a_k b_l for a constant vector s (3,) or (3, 1)."""
    return np.einsum("abkl,b->akl", T_Q, np.asarray(s).reshape(3))
