"""The drift guard of the index-1 form: ‖Φ‖ after every accepted step, against a limit.

The limit is ``model.drift_limit`` (length units) or, by default, 1 % of the mechanism's size
(the largest marker/joint vector).  Beyond it the positions no longer satisfy the joints: the
results would describe another mechanism, so the run stops.  The message names what was
measured — ‖Φ‖, the equation with the largest residual, and the conditioning of J_Φ at that
pose (σ_min/σ_max, 0 at a singular configuration) — and names the joints losing rank when
the pose is nearly singular.  It suggests no setting that would only hide the failure.

The same naming serves the other messages about a mechanism's equations: the joints losing
rank at a singular iteration matrix (:func:`diagnose_singular`) and the YAML entry behind an
equation (:func:`describe_equation`).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from ...errors import ModelError
from ..base import StepState

if TYPE_CHECKING:  # pragma: no cover
    from .model import MultibodyModel

NEAR_SINGULAR = 1e-3      # σ_min/σ_max of J_Φ below this: the drift comes from a (near) singular pose


def norm2(v: Any) -> float:
    """2-norm of a real vector, as ``np.linalg.norm`` forms it (√(v·v)) without its dispatch
    (the guard runs after every step)."""
    return math.sqrt(float(v @ v))


def drift_limit(model: "MultibodyModel", params: Any) -> float:
    """The bound on ‖Φ‖ (length units): ``model.drift_limit``, else 1 % of the mechanism's size
    (:meth:`.bodies.MBParams.size`, formed once per parameter set)."""
    if model.drift_limit is not None:
        return model.drift_limit
    return 1e-2 * params.size()


def check_drift(model: "MultibodyModel", t: float, s: StepState, params: Any) -> None:
    """ModelError when ‖Φ‖ at (t, s) exceeds the limit (module docstring)."""
    Phi = model.constraint_residuals(t, s, params)
    phi = np.real(Phi[:, 0])
    drift = norm2(phi)
    limit = drift_limit(model, params)
    if drift <= limit:
        return
    from .assembly import jacobian_rows
    worst = int(np.argmax(np.abs(phi)))
    J = np.real(jacobian_rows(model.eqs, np.real(s.q), params, t))
    sv = np.linalg.svd(J, compute_uv=False)
    ratio = float(sv[-1] / sv[0]) if sv.size and sv[0] > 0 else 0.0
    head = (f"constraint drift at t = {t:.6g} s: ‖Φ‖ = {drift:.3g} (2-norm of the position-level "
            f"residuals of the joints and normalisations) exceeds the limit {limit:.3g}; largest residual "
            f"{phi[worst]:.3g} in '{model.eq_owner[worst]}'; the constraint Jacobian has "
            f"σ_min/σ_max = {ratio:.2e} at this pose. ")
    if ratio < NEAR_SINGULAR:
        found = losing_rank(model, J, max(2.0 * ratio, 1e-12))
        joints = found[3] if found else []
        raise ModelError(head + f"The joints {', '.join(joints) or '(all)'} are (nearly) losing rank: the "
                         "mechanism is at or near a singular (dead-centre) configuration, which the "
                         "motion cannot be followed through.")
    raise ModelError(head + "J_Φ is regular at this pose, so the drift built up over the steps: "
                     "from the index-1 form itself (it grows about as Δt², and a smaller integrator.dt "
                     "lowers it) or from an earlier passage near a singular configuration; either way "
                     "the results no longer describe the mechanism.")


def losing_rank(model: "MultibodyModel", J: Any, rel_tol: float
                ) -> tuple[int, list[str], list[str], list[str]] | None:
    """(rank, the dependent equations, their owners, the joints among the owners) of the
    constraint Jacobian J (n_eq, n_q) at singular values below rel_tol·σ_max; None at full rank."""
    from .assembly import dependent_equations
    dep = dependent_equations(J, model.eq_owner, rel_tol=rel_tol)
    if dep is None:
        return None
    rank, involved, owners = dep
    names = {jt.name for jt in model.joints}
    return rank, involved, owners, [o for o in owners if o in names]


def diagnose_singular(model: "MultibodyModel", t: float, s: StepState, params: Any, rel_tol: float = 1e-9) -> str:
    """The joints whose equations became linearly dependent at (t, s), from the rank of J_Φ; ''
    when J_Φ has full rank.

    The iteration matrix is judged singular at a pivot ratio of 1e-14; J_Φ at the same
    iterate is rank-deficient to the looser 1e-9·σ_max (it is met one Newton correction
    away from the singular configuration itself).  A looser ``rel_tol`` (e.g. 1e-2) names
    the joints of a pose *near* a singular one (a mechanism that locks).
    """
    from .assembly import jacobian_rows
    J = jacobian_rows(model.eqs, np.real(s.q), params, t)
    found = losing_rank(model, J, rel_tol)
    if found is None:
        return ""
    rank, involved, owners, joints = found
    joints = joints or owners            # no joint among them (normalisations only): every owner
    return (f"joint{'s' if len(joints) > 1 else ''} {', '.join(joints)} lose rank: the "
            f"constraint Jacobian has rank {rank} < {J.shape[0]} (dependent equations "
            f"{', '.join(involved)})")


def describe_equation(model: "MultibodyModel", k: int) -> str:
    """Unknown k named for a message: a body coordinate with its body's YAML entry and the
    forces naming it, or a constraint equation with its joint's YAML entry; '' for the others."""
    n_q, n_lam = model.traits.n_q, model.traits.n_lam
    paths = model.entry_paths
    if 0 <= k < n_q:
        body = model.bodies[k // 7].name
        forces = paths.get("forces", {}).get(body, [])
        return (f"coordinate {model.dof_labels()[k]} of body '{body}' ({paths.get('bodies', 'model.bodies')}.{body})"
                + (f", acted on by {', '.join(forces)}" if forces else ""))
    if n_q <= k < n_q + n_lam:
        owner = model.eq_owner[k - n_q]
        jt = next((j for j in model.joints if k - n_q in j.rows), None)
        name = jt.name if jt is not None else owner.rsplit(".", 1)[0]    # else: a normalization
        joint = paths.get("joints", {}).get(name)
        owner_body = next((b.name for b in model.bodies if name in (b.name, f"{b.name}.orientation")), None)
        if joint is None and owner_body is not None:     # Euler normalization, a point mass's lock
            joint = f"body '{owner_body}' ({paths.get('bodies', 'model.bodies')}.{owner_body})"
        return f"constraint {owner}" + (f" of {joint}" if joint else "")
    return ""
