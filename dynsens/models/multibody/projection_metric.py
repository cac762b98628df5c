r"""The metric of the constraint projection (:mod:`.projection`, ``model.projection.metric``).

``euclidean`` moves (q, q̇) to the nearest consistent state in the plain 2-norm; ``mass`` in the
norm of the mass matrix W(q) = diag(m I, 4 GᵀJ'G) of each body:

    min (q* − q)ᵀ W (q* − q)  s.t. Φ(q*) = 0     →  q* = q + W⁻¹ J₀ᵀ ν
    min (q̇* − q̇)ᵀ W (q̇* − q̇)  s.t. Φ̇ = 0        →  q̇* = q̇ − W⁻¹ J₀ᵀ κ

so a correction does not move momentum between bodies of very different masses (a 1e-6 kg cart
on a pole keeps the pole's motion; in the 2-norm the cart's and the pole's coordinates are moved
alike).  4GᵀJ'G is singular along p itself (the Euler-parameter normalisation carries it):
the rotational block is 4GᵀJ'G + c p pᵀ with c = 4 tr(J')/3, the mean of the other three
eigenvalues, so W is positive definite and the normalisation's correction has the inertia's
scale; since [G; pᵀ] is orthogonal for a unit p, W⁻¹ = Gᵀ(4J')⁻¹G + p pᵀ/c.  A body without
rotational inertia (a point mass) takes m I₄ there.  W is taken at the solved state q (like J₀)
and is complex-safe in q and the design (mass and inertia), so the complex-step derivatives of
the projection see its dependence on both.
"""
from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from .rotations import G_mul

Array = np.ndarray


class InverseMetric:
    """W⁻¹ at k configurations, as per-body 7×7 blocks (k, n_b, 7, 7)."""

    def __init__(self, blocks: Array):
        self.blocks = blocks

    def times(self, X: Array) -> Array:
        """(n_q, k): column b is W_b⁻¹ X[:, b] (X (n_q, k), or (n_q, 1) for every b)."""
        k, n_b = self.blocks.shape[:2]
        Xb = np.broadcast_to(X, (X.shape[0], k)).T.reshape(k, n_b, 7, 1)
        return (self.blocks @ Xb).reshape(k, 7 * n_b).T

    def matrix(self, b: int, sparse: bool) -> Any:
        """W⁻¹ of configuration b, dense (n_q, n_q) or CSC."""
        if sparse:
            return sp.block_diag(list(self.blocks[b]), format="csc")
        return self.blocks_dense()[b]

    def blocks_dense(self) -> Array:
        """W_b⁻¹ of every configuration, dense (k, n_q, n_q)."""
        k, n_b = self.blocks.shape[:2]
        out = np.zeros((k, 7 * n_b, 7 * n_b), self.blocks.dtype)
        for i in range(n_b):
            out[:, 7 * i:7 * i + 7, 7 * i:7 * i + 7] = self.blocks[:, i]
        return out


def inverse_metric(Q: Array, params: Any) -> InverseMetric:
    """W⁻¹(q) (module docstring) at the k configurations Q (n_q, k); complex-safe."""
    n_q, k = Q.shape
    n_b = n_q // 7
    assert 7 * n_b == n_q == 7 * len(params.bodies), "seven coordinates per moving body"
    dtype = np.result_type(Q, params.pv, float)
    blocks = np.zeros((k, n_b, 7, 7), dtype)
    eye4 = np.eye(4)
    for i, bp in enumerate(params.bodies):
        a = 7 * i
        blocks[:, i, :3, :3] = np.eye(3) / bp.mass
        p = Q[a + 3:a + 7]                                                       # (4, k)
        Jb = np.asarray(bp.inertia)
        c = 4.0 * (Jb[0, 0] + Jb[1, 1] + Jb[2, 2]) / 3.0
        if np.real(c) <= 0.0:                        # a point mass: no rotational inertia
            blocks[:, i, 3:, 3:] = eye4 / bp.mass
            continue
        G = np.stack([G_mul(p, np.repeat(eye4[:, j:j + 1], k, axis=1)) for j in range(4)], axis=-1)  # (3, k, 4)
        G = G.transpose(1, 0, 2)                                                 # (k, 3, 4)
        P = p.T[:, :, None]                                                      # (k, 4, 1)
        Wr = 4.0 * G.transpose(0, 2, 1) @ Jb @ G + c * (P @ P.transpose(0, 2, 1))
        blocks[:, i, 3:, 3:] = np.linalg.inv(Wr)
    return InverseMetric(blocks)


__all__ = ["InverseMetric", "inverse_metric"]
