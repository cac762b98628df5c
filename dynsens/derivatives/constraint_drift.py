"""The constraint residual of the design sensitivities of a mechanism, per step.

The constraints Φ(q(x), x, t) = 0 hold for every design, so their total derivative vanishes:

    J_Φ ∇q_j + ∂Φ/∂x_j = 0            (position level)
    d/dx_j Φ̇(q, q̇, x, t) = 0          (velocity level)

at every step.  The index-1 form enforces these only at the acceleration level, like the
state's own drift ‖Φ‖, ‖Φ̇‖ (``/monitors/constraint_position|velocity``).  From the stored
state and sensitivity histories, each residual is one complex-step directional derivative of
the model's constraint levels along (∇q_j, ∇q̇_j, e_j): exact to round-off, no extra partials.
The largest over the design variables, per step, goes to ``/monitors`` as
``sensitivity_constraint_position`` and ``sensitivity_constraint_velocity``, with their
scale ``max_j ‖J_Φ ∇q_j‖`` as ``sensitivity_constraint_scale``.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..models.base import StepState

_H = 1e-30


def sensitivity_constraint_residual(model: Any, result: Any) -> dict[str, np.ndarray] | None:
    """Per-step residual norms (N,) of the sensitivities' position and velocity constraints, or
    None when the model has no constraint levels or the histories of q, q̇ and their
    sensitivities were not stored."""
    hist, shist = result.history, result.sensitivity_history
    if not hasattr(model, "constraint_levels") or not model.traits.n_lam:
        return None
    if not all(k in hist for k in ("q", "qd")) or not all(k in shist for k in ("q", "qd")):
        return None
    x = np.real(np.asarray(result.x, dtype=complex))
    m = x.size
    params0 = model.parameters(x)
    params_j = [model.parameters(x + 1j * _H * np.eye(m)[j]) for j in range(m)]
    n = result.time.size
    out = {k: np.zeros(n) for k in ("sensitivity_constraint_position", "sensitivity_constraint_velocity",
                                    "sensitivity_constraint_scale")}
    for k in range(n):
        q, qd = hist["q"][k], hist["qd"][k]
        qdd = hist["qdd"][k] if "qdd" in hist else np.zeros_like(q)
        zeros = np.zeros(0)
        for j in range(m):
            dq, dqd = shist["q"][k][:, j], shist["qd"][k][:, j]
            s = StepState(q + 1j * _H * dq, qd + 1j * _H * dqd, qdd.astype(complex), zeros, zeros, zeros)
            total = np.imag(model.constraint_levels(result.time[k], model.kinematics(s, params_j[j]))[0][0]) / _H
            state_part = np.imag(model.constraint_levels(result.time[k], model.kinematics(s, params0))[0][0]) / _H
            out["sensitivity_constraint_position"][k] = max(out["sensitivity_constraint_position"][k],
                                                            float(np.linalg.norm(total[:, 0])))
            out["sensitivity_constraint_velocity"][k] = max(out["sensitivity_constraint_velocity"][k],
                                                            float(np.linalg.norm(total[:, 1])))
            out["sensitivity_constraint_scale"][k] = max(out["sensitivity_constraint_scale"][k],
                                                         float(np.linalg.norm(state_part[:, 0])))
    return out
