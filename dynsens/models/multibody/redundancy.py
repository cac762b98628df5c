r"""Redundant joint equations: found once, at the case's initial design, and kept out of Φ.

A closed loop can carry more joint equations than it removes freedoms (the Bricard
mechanism: six revolutes, 30 equations for 5 × 6 freedoms, one of them redundant
everywhere; a planar four-bar written with spatial revolutes: three).  The constraint
Jacobian J_Φ then has rank r < n_eq and the index-1 iteration matrix is singular.

What is done (docs/multibody.md, "Redundant joints"):

1. At load, the case's initial design x0 is assembled by minimum-norm Gauss–Newton on all
   equations (joints, normalisations, holds, distances), which converges for consistent
   redundant sets too.
2. The rank of J_Φ at that pose is read from its singular values (σ ≤ 1e-8 σ_max count as
   zero).  Full rank: nothing changes.
3. Consistent redundancy (Φ = 0 reached): the equations are taken in case order —
   normalisations first, then the joints' equations in the order the joints are listed —
   and each one whose Jacobian row lies in the span of the rows already kept is dropped
   (relative distance ≤ 1e-6).  The model is built on the kept, independent set; its
   multipliers are those of the kept equations, i.e. the dropped equations carry zero
   multiplier — one split of a statically indeterminate reaction, which follows the joints'
   order.  The joints of the dependent set (:func:`dependent_equations`) therefore report
   their reactions from the minimum-norm split over all their equations instead, which does
   not (:mod:`.reaction_split`).
4. Inconsistent redundancy (dependent rows and Φ ≠ 0 at the least-squares pose) is refused,
   naming the smallest set of joints whose equations are dependent.
5. A dependency that holds at the initial pose only — the dropped rows leave the kept rows'
   span at poses next to it on the kept equations' manifold — is a singular configuration,
   not a redundancy, and is refused as such.

During the run :func:`check_dependency` verifies at every step that each dropped
equation's row is still in the span of the kept rows; a change of rank is an error naming
the time and the joints, never a silently different mechanism.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ...errors import ModelError
from .assembly import guess, jacobian_rows
from .bodies import Ctx

if TYPE_CHECKING:  # pragma: no cover
    from .kernel import Layout
    from .model import MultibodyModel

Array = np.ndarray
RANK_TOL = 1e-8          # singular values ≤ RANK_TOL σ_max count as zero at the assembled pose
SPAN_TOL = 1e-6          # a row this close (relative) to the kept rows' span is dependent
RUN_TOL = 1e-3           # during the run: a dropped row this far off the span has become independent
HUGE_POSITION = 1e150    # beyond it squared lengths overflow (1.8e308): no constraint equation is finite


@dataclass
class Redundancy:
    """The outcome of the analysis: dropped equations (indices into model.eqs), the rank."""

    dropped: list[int]
    rank: int
    n_eq: int
    dependent: list[int]     # the equations of the dependent set(s): the support of null(J_Φᵀ)


class InconsistentRedundancy(Exception):
    """Dependent joint equations that cannot hold together; the message names the joints."""


def _ctx(q: Array, params: Any, t: float) -> Ctx:
    Q = q.reshape(-1, 1)
    return Ctx(Q, np.zeros_like(Q), np.zeros_like(Q), params, t)


def least_squares_pose(model: "MultibodyModel", params: Any, iterations: int = 60) -> Array:
    """q near the given poses minimising ‖Φ_c‖ (joints, normalisations, holds, distances) by
    minimum-norm Gauss–Newton steps; converges to Φ_c = 0 for consistent redundant sets."""
    eqs = model.eqs + model.assembly.equations
    t0 = model.assembly.t0
    q = np.real(guess(model, params)).astype(float)
    scale = 1.0 + np.linalg.norm(q)
    for _ in range(iterations):
        phi = np.real(model.constraint_values(_ctx(q, params, t0), eqs)[0][:, 0])
        J = np.real(jacobian_rows(eqs, q, params, t0))
        dq = np.linalg.lstsq(J, -phi, rcond=1e-10)[0]
        q = q + dq
        if np.linalg.norm(dq) <= 1e-14 * scale:
            break
    return q


def check_poses(model: "MultibodyModel", params: Any) -> None:
    """ModelError naming the bodies whose given pose is not finite or so large (|r| > HUGE_POSITION)
    that the constraint equations overflow, or the joints whose equations at the given poses are
    not finite (an overflowing marker or joint point): the rank of J_Φ has no meaning there."""
    q = np.real(guess(model, params))
    t0 = model.assembly.t0
    with np.errstate(all="ignore"):
        J = np.real(jacobian_rows(model.eqs, q, params, t0))
        phi = np.real(model.constraint_values(_ctx(q, params, t0), model.eqs)[0][:, 0])
    bad = [f"body '{b.name}' at position [{', '.join(f'{v:.3g}' for v in q[7 * k:7 * k + 3])}]"
           for k, b in enumerate(model.bodies)
           if not (np.all(np.isfinite(q[7 * k:7 * k + 7])) and np.max(np.abs(q[7 * k:7 * k + 3])) <= HUGE_POSITION)]
    if not bad:
        rows = np.flatnonzero(~(np.isfinite(phi) & np.all(np.isfinite(J), axis=1)))
        bad = [f"joint '{j}'" for j in dict.fromkeys(model.eq_owner[i].split(".")[0] for i in rows)]
    if bad:
        raise ModelError(
            f"the constraint equations at the initial configuration are not finite (they overflow) for "
            f"{', '.join(bad)}: give body positions of magnitude below {HUGE_POSITION:g}, and markers "
            "and joint points of the mechanism's size")


def _rank(J: Array) -> int:
    if J.shape[0] == 0:
        return 0
    if not np.all(np.isfinite(J)):
        # overflowing coordinates (|q| ~ 1e300): the SVD would fail to converge
        raise ModelError("the constraint Jacobian at the initial configuration is not finite: check the "
                         "bodies' positions, markers and joint points for overflowing values")
    sv = np.linalg.svd(J, compute_uv=False)
    return int(np.sum(sv > RANK_TOL * max(sv[0], 1e-300)))


def independent_rows(J: Array, order: list[int]) -> list[int]:
    """Rows of J taken in ``order``, each kept when it is not (relatively) in the span of the
    rows kept before it (modified Gram–Schmidt, twice for round-off)."""
    basis: list[Array] = []
    kept = []
    for i in order:
        r = J[i].astype(float)
        n0 = np.linalg.norm(r)
        for _ in range(2):
            for b in basis:
                r = r - (b @ r) * b
        if n0 > 0 and np.linalg.norm(r) > SPAN_TOL * n0:
            basis.append(r / np.linalg.norm(r))
            kept.append(i)
    return kept


def smallest_dependent_joints(model: "MultibodyModel", J: Array) -> list[str]:
    """A minimal set of joints whose equations (with the normalisations) are dependent:
    start from all joints, drop each one whose removal leaves a dependent set."""
    norm_rows = [i for i, lab in enumerate(model.eq_owner) if lab.endswith(".normalization")]
    rows = {jt.name: list(jt.rows) for jt in model.joints}

    def dependent(names: list[str]) -> bool:
        sel = norm_rows + [i for n in names for i in rows[n]]
        return _rank(J[sel]) < len(sel)

    chosen = [jt.name for jt in model.joints]
    for name in list(chosen):
        trial = [n for n in chosen if n != name]
        if dependent(trial):
            chosen = trial
    return chosen


def analyse(model: "MultibodyModel", x: Array) -> Redundancy | None:
    """Redundant joint equations at the initial design x (module docstring); None when J_Φ has
    full rank there or the mechanism cannot be assembled (the run then reports why).
    Raises InconsistentRedundancy for dependent equations that cannot all hold, ModelError for
    given poses whose equations overflow (:func:`check_poses`)."""
    params = model.parameters(np.asarray(x, float))
    check_poses(model, params)
    try:
        q = least_squares_pose(model, params)
    except (np.linalg.LinAlgError, FloatingPointError, ValueError):
        return None
    if not np.all(np.isfinite(q)):
        return None
    t0 = model.assembly.t0
    J = np.real(jacobian_rows(model.eqs, q, params, t0))
    n_eq = J.shape[0]
    phi = np.real(model.constraint_values(_ctx(q, params, t0), model.eqs)[0][:, 0])
    size = 1.0 + np.linalg.norm(q)
    if np.linalg.norm(phi) > 1e-8 * size:
        # not assembled: at a least-squares stationary point with Φ ≠ 0 the rows are always
        # dependent, so only a rank defect already present at the given poses (dependent
        # everywhere) is an inconsistent redundancy; otherwise the assembly reports the failure
        Jg = np.real(jacobian_rows(model.eqs, np.real(guess(model, params)), params, t0))
        rank_g = _rank(Jg)
        if rank_g == n_eq:
            return None
        joints = smallest_dependent_joints(model, Jg)
        raise InconsistentRedundancy(
            f"inconsistent redundant joints: the equations of joints {', '.join(joints)} are "
            f"linearly dependent (constraint Jacobian rank {rank_g} < {n_eq} at the given poses) "
            f"and cannot all hold together (least-squares residual ‖Φ‖ = {np.linalg.norm(phi):.3e} "
            "at the poses nearest the given ones); check these joints' points and axes, or give "
            "one of them fewer equations (e.g. a revolute as a spherical or planar_pin joint)")
    rank = _rank(J)
    if rank == n_eq:
        return None
    norm_rows = [i for i, lab in enumerate(model.eq_owner) if lab.endswith(".normalization")]
    order = norm_rows + [i for i in range(n_eq) if i not in set(norm_rows)]
    kept = set(independent_rows(J, order))
    dropped = [i for i in range(n_eq) if i not in kept]
    if len(kept) != rank:
        raise InconsistentRedundancy(
            f"redundant joints: the rank of the constraint Jacobian ({rank} of {n_eq}) is not "
            "clear-cut at the initial pose (a singular configuration?); give an initial pose "
            f"away from it. Joints involved: {', '.join(smallest_dependent_joints(model, J))}")
    if not _persists(model, params, q, sorted(kept), dropped):
        joints = smallest_dependent_joints(model, J)
        raise InconsistentRedundancy(
            f"the initial pose is a singular configuration: the equations of joints {', '.join(joints)} "
            f"are linearly dependent there (constraint Jacobian rank {rank} < {n_eq}) but not at "
            "poses next to it, so they are not redundant joints; give an initial pose away from "
            "the singular one (e.g. another held angle)")
    return Redundancy(dropped, rank, n_eq, dependent_equations(J, rank))


def dependent_equations(J: Array, rank: int) -> list[int]:
    """Rows of J (n_eq, n_q) that take part in a linear dependency: those on which some vector of
    the left null space (J_Φᵀ n = 0; the last n_eq − rank left singular vectors) is non-zero.
    Their multipliers are not unique; every other row's multiplier is."""
    U = np.linalg.svd(J)[0]
    weight = np.linalg.norm(U[:, rank:], axis=1)
    return [int(i) for i in np.flatnonzero(weight > SPAN_TOL)]


def _persists(model: "MultibodyModel", params: Any, q: Array, kept: list[int], dropped: list[int]) -> bool:
    """Whether the dropped rows stay in the kept rows' span at poses next to q on the kept
    equations' manifold (a redundancy), not only at q itself (a singular configuration).

    Two steps of 1e-4 × the mechanism's size along the kept manifold's tangents, each closed
    again by minimum-norm Gauss–Newton; a fully constrained (static) manifold has nothing to test."""
    t0 = model.assembly.t0
    eqs_k = [model.eqs[i] for i in kept]
    eqs_d = [model.eqs[i] for i in dropped]
    Jk = np.real(jacobian_rows(eqs_k, q, params, t0))
    _, sv, Vt = np.linalg.svd(Jk)
    null = Vt[int(np.sum(sv > RANK_TOL * sv[0])):]
    if null.shape[0] == 0:
        return True
    size = 1.0 + np.linalg.norm(q)
    rng = np.random.default_rng(0)
    for _ in range(2):
        c = rng.standard_normal(null.shape[0])
        q1 = q + 1e-4 * size * (c / np.linalg.norm(c)) @ null
        for _ in range(20):
            phi = np.real(model.constraint_values(_ctx(q1, params, t0), eqs_k)[0][:, 0])
            step = np.linalg.lstsq(np.real(jacobian_rows(eqs_k, q1, params, t0)), -phi, rcond=1e-12)[0]
            q1 = q1 + step
            if np.linalg.norm(step) <= 1e-14 * size:
                break
        J1 = np.real(jacobian_rows(eqs_k + eqs_d, q1, params, t0))
        if len(independent_rows(J1, list(range(J1.shape[0])))) > len(kept):
            return False
    return True


def check_values(model: "MultibodyModel", t: float, q: Array, params: Any, kept_norm: float,
                 phi: Array | None = None) -> None:
    """ModelError when an equation left out does not hold at (t, q) although the kept ones do
    (‖Φ_kept‖ = kept_norm): the dependency found at the initial design does not hold here (another
    design, or equations that conflict as time goes on, such as two drivers of one freedom).
    ``phi``: the left-out equations' values at (t, q) when already known."""
    from .drift import drift_limit
    red = model.redundant
    if phi is None:
        phi = np.real(model.constraint_values(_ctx(np.real(q), params, t), [eq for _, _, eq in red])[0][:, 0])
    bound = max(1e-4 * drift_limit(model, params), 100.0 * kept_norm)
    bad = np.flatnonzero(np.abs(phi) > bound)
    if bad.size:
        names = ", ".join(f"{red[i][0]}.{red[i][1]} = {phi[i]:.3g}" for i in bad)
        raise ModelError(
            f"redundant joints at t = {t:.6g} s: the equation(s) {names}, left out as implied by the "
            f"others at the initial design, do not hold here while the kept equations hold to "
            f"{kept_norm:.3g}: the redundancy does not persist (a design other than the initial one, "
            "or equations that conflict as time goes on, e.g. two drivers of one freedom)")


@dataclass(frozen=True)
class DroppedEquations:
    """The redundant equations left out of Φ as a kernel of their own (built once per model,
    :meth:`.model.MultibodyModel.dropped_equations`).

    layout : their kernel layout; S : its products-to-equations map (sparse: no dense product);
    probe : fixed random combinations (n_d, 4) of their rows, the first test of
    :func:`check_dependency` (each leaves the kept rows' span when any row does).
    """

    layout: "Layout"
    S: Any
    probe: Array

    @classmethod
    def of(cls, model: "MultibodyModel") -> "DroppedEquations":
        """The left-out equations of ``model`` (``model.redundant``)."""
        from .kernel import Layout
        eqs = [eq for _, _, eq in model.redundant]
        lay = Layout(model.layout.n_b, eqs, [], [])
        return cls(lay, sp.csr_matrix(lay.S), np.random.default_rng(0).standard_normal((len(eqs), 4)))


def dropped_values_and_rows(model: "MultibodyModel", t: float, q: Array, params: Any) -> tuple[Array, Array]:
    """(Φ_d (n_d,), J_d (n_d, n_q)) of the left-out equations at (t, q), real parts: by the
    compiled kernel on a layout of their own when their terms have unit coefficients and no
    shifts (joints' equations), term by term otherwise."""
    from . import compiled as cc
    from . import compiled_linearization as clin
    from .kernel import kernel_params
    from .kernel_compiled import CompiledKin
    eqs = [eq for _, _, eq in model.redundant]
    dropped = model.dropped_equations()
    lay, S = dropped.layout, dropped.S
    q = np.real(q)
    if lay.coefs or lay.shifts or not cc.enabled() or lay.n_eq != lay.n_cp:
        return (np.real(model.constraint_values(_ctx(q, params, t), eqs)[0][:, 0]),
                np.real(jacobian_rows(eqs, q, params, t)))
    kp = kernel_params(lay, params)      # kept with the set, apart from the model layout's
    z = np.zeros_like(q)[None]
    kin = CompiledKin(lay, kp, q[None], z, z)
    cl = kin.arrays
    G = clin.product_rows(kin.C[0], kin.ABV[0], cl.pb, cl.is_point, cl.side_ptr, cl.side_prim, cl.side_coef,
                        lay.n_q)
    return np.real(S @ kin.X[0, :, 0]), np.real(S @ G[:, 0])


def _span_distance(Jk: Any, R: Array) -> Array:
    """Relative distance of each row of R from the span of the rows of Jk (sparse): the sparse
    normal equations first, a rank-revealing least-squares solve to confirm a distance beyond
    RUN_TOL (near a singular configuration of the kept rows J_k J_kᵀ is nearly singular)."""
    size = np.maximum(np.linalg.norm(R, axis=1), 1e-300)
    try:
        with np.errstate(all="ignore"):
            coef = spla.splu(sp.csc_matrix(Jk @ Jk.T)).solve(np.ascontiguousarray(Jk @ R.T))
            off = np.linalg.norm(R - (Jk.T @ coef).T, axis=1) / size
    except RuntimeError:             # exactly singular normal equations: decide below
        off = np.full(R.shape[0], np.inf)
    if not np.all(off <= RUN_TOL):
        Jkd = Jk.toarray()
        coef = np.linalg.lstsq(Jkd.T, R.T, rcond=1e-10)[0]
        off = np.linalg.norm(R - coef.T @ Jkd, axis=1) / size
    return off


def check_dependency(model: "MultibodyModel", t: float, state: Any, params: Any) -> None:
    """ModelError when a dropped equation's row has left the span of the kept rows at (t, state):
    the rank of the joints' equations changed during the run.

    The distance of each dropped row J_d from the span of the kept rows J_k is
    ‖J_d − cᵀJ_k‖ with J_k J_kᵀ c = J_k J_dᵀ (sparse normal equations: J_k has a few bodies'
    columns per row); a distance beyond RUN_TOL is confirmed by a rank-revealing least-squares
    solve before it is reported (at a singular configuration of the kept equations, such as the
    flat pose of a parallelogram loop, J_k J_kᵀ is nearly singular while the dropped rows stay
    in the span: the run goes on)."""
    red = model.redundant
    if not red:
        return
    n_q, n_lam = model.traits.n_q, model.traits.n_lam
    # the kept rows from the kernel's linearization at this state (∂R2/∂q̈ = c_s J_Φ; usually the
    # solver's own, cached), the few dropped rows from a kernel of their own
    Jk = sp.csr_matrix(model.linearize(t, state, params).R_z[n_q:n_q + n_lam, :n_q]).real / model.scale
    phi_d, Jd = dropped_values_and_rows(model, t, state.q, params)
    rows = np.maximum(np.linalg.norm(Jd, axis=1), 1e-300)
    # first a few fixed random combinations of the dropped rows (each leaves the span when any
    # row does), then, only if one is off, every row apart (to name them)
    W = model.dropped_equations().probe
    probe = (W / rows[:, None]).T @ Jd
    off = _span_distance(Jk, probe)
    if not np.all(off <= 0.01 * RUN_TOL):
        off = _span_distance(Jk, Jd)
    else:
        off = np.zeros(Jd.shape[0])
    kept = float(np.linalg.norm(np.real(model.constraint_residuals(t, state, params)[:, 0])))
    check_values(model, t, state.q, params, kept, phi=phi_d)
    bad = np.flatnonzero(off > RUN_TOL)
    if bad.size:
        names = ", ".join(f"{red[i][0]}.{red[i][1]}" for i in bad)
        raise ModelError(
            f"redundant joints changed rank at t = {t:.6g} s: the equation(s) {names}, dependent "
            "on the others at the initial pose (and so left out of the model), became independent "
            f"(relative distance {float(np.max(off[bad])):.3g} from the kept equations' span): the "
            "mechanism reached a configuration where its redundant joints are no longer redundant; "
            "the model without those equations does not describe it")
