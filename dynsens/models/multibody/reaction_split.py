r"""The reactions of a redundant set: the minimum-norm multipliers over its joints' equations.

When joint equations are dependent (:mod:`.redundancy`), the motion is unique but the
multipliers are not: every λ with the same generalized constraint force J_Φᵀλ moves the
bodies alike, and the model's own λ (that of the independent equations kept in Φ, the left-out
ones at zero) is the split that follows the joints' order in the case file.  The reactions of
the joints of a dependent set are reported for one split fixed by a rule that does not see the
order (docs/multibody.md, "Redundant joints"):

    among all multipliers of the complete set of equations that give the model's constraint
    force, the one whose joint part has the least 2-norm.

With the kept rows J_k and the left-out rows J_d = C J_k (C = J_d J_kᵀ (J_k J_kᵀ)⁻¹, exact:
the left-out rows lie in the span of the kept ones), every such multiplier is
λ_k = λ⁰_k − Cᵀλ_d for some λ_d, and the joint part's norm ‖W λ_k‖² + ‖λ_d‖² (W: 1 on joint
rows, 0 on the Euler-parameter normalisations, whose multipliers are no reaction) is least for

    (I + C W Cᵀ) λ_d = C W λ⁰_k,      λ_k = λ⁰_k − Cᵀ λ_d.

The matrix is symmetric positive definite, so the split is unique; it is the same for any order
of the joints because it depends only on the set of admissible multipliers, which is.  Only the
rows of the dependent set enter (the joints with an equation in the left null space of J_Φ,
their bodies' normalisations): the multipliers outside it are unique and unchanged.  Every
operation is analytic (solves with plain transposes), so complex steps and design differences
through it give the derivatives of the split: its sensitivities (direct and adjoint) are those
of an ordinary output.  Units: the multipliers of the point equations are forces (N), those of
the axis equations moments (N·m): the norm mixes them as the equations are written.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from .assembly import jacobian_rows
from .bodies import GROUND
from .kernel import KParams

if TYPE_CHECKING:  # pragma: no cover
    from .joints import Equation, Joint
    from .model import MultibodyModel

Array = np.ndarray


class MinimumNormSplit:
    """The minimum-norm multipliers of a model's dependent joints at a state (module docstring).

    Built once per model; :meth:`joint` gives one joint's multipliers over all its equations and
    its generalized constraint force, for a plain or a batched state (all joints of one state
    share one evaluation).
    """

    def __init__(self, model: "MultibodyModel"):
        self.model = model
        joints = [jt for jt in model.joints if jt.name in set(model.dependent_joints)]
        bodies = {b for jt in joints for b in (jt.body_1, jt.body_2) if b != GROUND}
        norm_rows = [model.eq_owner.index(f"{b.name}.normalization") for b in model.bodies if b.index in bodies]
        joint_rows = [r for jt in joints for r in jt.rows]
        self.kept = np.array(joint_rows + norm_rows, int)               # rows of model.eqs
        self.weight = np.r_[np.ones(len(joint_rows)), np.zeros(len(norm_rows))]
        self.dropped: list[Equation] = [eq for j, _, eq in model.redundant if j in set(model.dependent_joints)]
        self.eqs = [model.eqs[i] for i in self.kept] + self.dropped
        # per joint: the positions of its equations (its own order) among self.eqs
        where = {id(eq): k for k, eq in enumerate(self.eqs)}
        self.positions = {jt.name: np.array([where[id(eq)] for _, eq in jt.all_equations], int)
                          for jt in joints}
        self.labels = {jt.name: tuple(lab for lab, _ in jt.all_equations) for jt in joints}
        self._last: tuple[Any, ...] | None = None

    def joint(self, jt: "Joint", t: float, q: Array, lam: Array, params: Any) -> tuple[Array, Array]:
        """(λ_J (B, n_J), Q_J (B, n_q)) for joint jt: its minimum-norm multipliers over all its
        equations (the order of ``all_equations``) and the generalized force J_Jᵀλ_J they exert
        (on both bodies), for states q (n_q,) or (B, n_q), λ likewise, and one parameter set
        (MBParams) or the model's stacked ones (KParams, one set or one per state)."""
        lam_all, J = self._split(t, q, lam, params)
        pos = self.positions[jt.name]
        lam_j = lam_all[:, pos]
        return lam_j, np.einsum("bi,bin->bn", lam_j, J[:, pos])

    def _split(self, t: float, q: Array, lam: Array, params: Any) -> tuple[Array, Array]:
        """(λ (B, n_s), J (B, n_s, n_q)) over self.eqs at the states, cached for the last call."""
        last = self._last
        if last is not None and last[0] is q and last[1] is lam and last[2] is params and last[3] == t:
            return last[4]
        Q, L = np.atleast_2d(q), np.atleast_2d(lam)
        B = max(Q.shape[0], L.shape[0], params.B if isinstance(params, KParams) else 1)
        Q, L = np.broadcast_to(Q, (B, Q.shape[1])), np.broadcast_to(L, (B, L.shape[1]))
        J = self._rows(t, Q, params)                                      # (B, n_s, n_q)
        n_k = self.kept.size
        Jk, Jd = J[:, :n_k], J[:, n_k:]
        # C = J_d J_kᵀ (J_k J_kᵀ)⁻¹, by the symmetric normal equations (plain transposes: analytic)
        C = np.swapaxes(np.linalg.solve(Jk @ np.swapaxes(Jk, 1, 2), Jk @ np.swapaxes(Jd, 1, 2)), 1, 2)
        lam0 = L[:, self.kept]
        CW = C * self.weight
        A = np.eye(C.shape[1]) + CW @ np.swapaxes(C, 1, 2)
        lam_d = np.linalg.solve(A, (CW @ lam0[:, :, None]))[:, :, 0]
        lam_k = lam0 - (np.swapaxes(C, 1, 2) @ lam_d[:, :, None])[:, :, 0]
        out = (np.concatenate([lam_k, lam_d], axis=1), J)
        self._last = (q, lam, params, t, out)
        return out

    def _rows(self, t: float, Q: Array, params: Any) -> Array:
        """J (B, n_s, n_q) of self.eqs at the states Q (B, n_q): one pass over the equations per
        distinct parameter set."""
        B = Q.shape[0]
        if isinstance(params, KParams):
            sets = params.prms if len(params.prms) > 1 else params.prms * B
        else:
            sets = [params] * B
        groups: dict[int, list[int]] = {}
        for b, prm in enumerate(sets):
            groups.setdefault(id(prm), []).append(b)
        dt = np.result_type(Q, *(np.asarray(sets[g[0]].pv) for g in groups.values()), float)
        J = np.zeros((B, len(self.eqs), Q.shape[1]), dt)
        for idx in groups.values():
            rows = jacobian_rows(self.eqs, np.ascontiguousarray(Q[idx].T), sets[idx[0]], t)   # (n_s, n_q, k)
            J[idx] = np.moveaxis(rows, 2, 0)
        return J


def split_of(model: "MultibodyModel") -> MinimumNormSplit | None:
    """The model's :class:`MinimumNormSplit` (built on first use), None without dependent joints."""
    if not model.dependent_joints:
        return None
    return model.reaction_split()


def split_is_timed(model: "MultibodyModel") -> bool:
    """Whether the split depends on t beyond the state: a driver among the dependent joints (its
    equation's coefficients are functions of time)."""
    from .outputs import reaction_is_timed
    return any(jt.kind == "driving" or reaction_is_timed(model, jt)
               for jt in model.joints if jt.name in set(model.dependent_joints))
