"""The drift guard of the index-1 form: ‖Φ‖ after every accepted step, against a limit.

The limit is ``model.drift_limit`` (length units) or, by default, 1 % of the mechanism's size
(the largest marker/joint vector).  Beyond it the positions no longer satisfy the joints: the
results would describe another mechanism, so the run stops.  The message names what was
measured — ‖Φ‖, the equation with the largest residual, and the conditioning of J_Φ at that
pose (σ_min/σ_max, 0 at a singular configuration) — and names the joints losing rank when
the pose is nearly singular.  It suggests no setting that would only hide the failure.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ...errors import ModelError
from ..base import StepState

if TYPE_CHECKING:  # pragma: no cover
    from .model import MultibodyModel

NEAR_SINGULAR = 1e-3      # σ_min/σ_max of J_Φ below this: the drift comes from a (near) singular pose


def drift_limit(model: "MultibodyModel", params: Any) -> float:
    """The bound on ‖Φ‖ (length units), cached with the parameters."""
    if model.drift_limit is not None:
        return model.drift_limit
    limit = params.ts.get("__drift_limit__")
    if limit is None:
        size = max((float(np.linalg.norm(np.real(v))) for v in params.vec.values()), default=1.0)
        limit = params.ts["__drift_limit__"] = 1e-2 * (size if size > 0 else 1.0)
    return float(limit)


def constraint_residuals(model: "MultibodyModel", t: float, s: StepState, params: Any) -> Any:
    """(Φ, Φ̇, Φ̈) (n_eq, 3) at (t, s), kept for the same state object: the guard after a step and
    the monitors recorded for it share one evaluation."""
    last = model.__dict__.get("_phi_last")
    if last is not None and last[0] == t and last[1] is s.q and last[2] is s.qd and last[3] is params:
        return last[4]
    Phi = model.constraint_levels(t, model.kinematics(s, params))[0][0]
    model.__dict__["_phi_last"] = (t, s.q, s.qd, params, Phi)
    return Phi


def check_drift(model: "MultibodyModel", t: float, s: StepState, params: Any) -> None:
    """ModelError when ‖Φ‖ at (t, s) exceeds the limit (module docstring)."""
    Phi = constraint_residuals(model, t, s, params)
    phi = np.real(Phi[:, 0])
    drift = float(np.linalg.norm(phi))
    limit = drift_limit(model, params)
    if drift <= limit:
        return
    from .assembly import dependent_equations, jacobian_rows
    worst = int(np.argmax(np.abs(phi)))
    J = np.real(jacobian_rows(model.eqs, np.real(s.q), params, t))
    sv = np.linalg.svd(J, compute_uv=False)
    ratio = float(sv[-1] / sv[0]) if sv.size and sv[0] > 0 else 0.0
    head = (f"constraint drift at t = {t:.6g} s: ‖Φ‖ = {drift:.3g} (2-norm of the position-level "
            f"residuals of the joints and normalisations) exceeds the limit {limit:.3g}; largest residual "
            f"{phi[worst]:.3g} in '{model.eq_owner[worst]}'; the constraint Jacobian has "
            f"σ_min/σ_max = {ratio:.2e} at this pose. ")
    if ratio < NEAR_SINGULAR:
        dep = dependent_equations(J, model.eq_owner, rel_tol=max(2.0 * ratio, 1e-12))
        names = {jt.name for jt in model.joints}
        joints = [o for o in (dep[2] if dep else []) if o in names]
        raise ModelError(head + f"The joints {', '.join(joints) or '(all)'} are (nearly) losing rank: the "
                         "mechanism is at or near a singular (dead-centre) configuration, which the "
                         "motion cannot be followed through.")
    raise ModelError(head + "J_Φ is regular at this pose, so the drift built up over the steps: "
                     "from the index-1 form itself (it grows about as Δt², and a smaller integrator.dt "
                     "lowers it) or from an earlier passage near a singular configuration; either way "
                     "the results no longer describe the mechanism.")
