r"""Natural frequencies and linear buckling of a structural model, with design sensitivities.

Both come from the model's own linearization (M = ∂F_R/∂q̈, K = ∂F_R/∂q; method.md §3) at a
state at rest: the initial state, or the state a run reaches at a given time.

**Modes.**  K φ = ω² M φ (``scipy.linalg.eigh``, M positive definite), φ normalized to
φᵀMφ = 1, frequencies f = ω/2π.  For a simple eigenvalue λ = ω²

    dλ/dx_j = φᵀ (dK/dx_j − λ dM/dx_j) φ,

with dK/dx_j and dM/dx_j the *total* derivatives of the matrices: by complex step of the design
and, at a state a run reached, of that state along its sensitivity dq/dx_j (Im K(x + ih e_j,
q + ih dq/dx_j)/h, exact to round-off).  A repeated eigenvalue (relative gap below
``REPEATED_GAP``) has no gradient: its eigenvectors are any basis of the eigenspace, and the
eigenvalues split differently along each direction.  There the derivative along x_j is reported
as the eigenvalues of the cluster's matrix Φᵀ(dK/dx_j − λ dM/dx_j)Φ (sorted), a directional
derivative, and the result says which modes are repeated.

**Linear buckling.**  With the static displacement of the reference load, u₀ = K₀⁻¹ f,
the geometric stiffness K_G = d K(q₀ + ε u₀)/dε at ε = 0 (complex step in ε; its design
derivatives are central differences of relative step ``FD_STEP``) and load factors λ with
(K₀ + λ K_G) φ = 0, solved as −K_G φ = ν K₀ φ (K₀ positive definite), λ = 1/ν for the positive
ν.  With φᵀK₀φ = 1,  dν/dx_j = φᵀ(−dK_G/dx_j − ν dK₀/dx_j)φ  and  dλ = −dν/ν².  The load is the
external force at ``load_time`` (default: the instant of the window where it is largest).
K_G comes from the elements' geometric nonlinearity: co-rotational beams, geometrically
nonlinear bars; a linear model has none, and no load factor.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Callable, Protocol, Sequence

import numpy as np
import scipy.linalg as sla

from ..errors import DynsensError
from ..models.base import StepState, as_dense

REPEATED_GAP = 1e-8      # eigenvalues closer than this (relative) are treated as repeated
CS_STEP = 1e-30          # complex step of the design (relative to |x_j|, or its scale)
FD_STEP = 1e-5           # relative step of the central differences of K_G in the design


class Subject(Protocol):
    """What the analyses read of a case (a :class:`~dynsens.case.load.Case` is one; a response
    inside a run passes its model, plan and scales)."""

    model: Any
    source: str
    plan: Any

    @property
    def x0(self) -> np.ndarray: ...

    @property
    def scale(self) -> np.ndarray: ...


class AnalysisError(DynsensError, ValueError):
    """A modal or buckling analysis the model cannot serve (not structural, singular mass, ...)."""


@dataclass
class Modes:
    """Lowest natural modes.

    frequencies : (k,) Hz; eigenvalues : (k,) ω² in (rad/s)²; shapes : (n, k), φᵀMφ = 1;
    gradient : (k, m) d frequency/dx (Hz per design unit), None without sensitivities;
    repeated : (k,) bool, True where a mode belongs to a repeated eigenvalue (its gradient row
    is directional, see the module docstring); time : the state's time (s).
    """

    frequencies: np.ndarray
    eigenvalues: np.ndarray
    shapes: np.ndarray
    gradient: np.ndarray | None
    repeated: np.ndarray
    dof_labels: list[str]
    time: float
    eigenvalue_gradient: np.ndarray | None = None


@dataclass
class Buckling:
    """Lowest positive linear buckling load factors of the reference load.

    factors : (k,) load factors λ (the load at buckling is λ·f); shapes : (n, k), φᵀK₀φ = 1;
    gradient : (k, m) dλ/dx, None without sensitivities; load_time : the reference load's time (s).
    """

    factors: np.ndarray
    shapes: np.ndarray
    gradient: np.ndarray | None
    dof_labels: list[str]
    load_time: float
    repeated: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))


def _structural(case: Subject) -> Any:
    from ..models.structural.model import StructuralModel
    if not isinstance(case.model, StructuralModel):
        raise AnalysisError(f"{case.source}: modes and buckling need a structural model (model.type: structural); "
                            "a mechanism's modes would need its constraints eliminated, which dynsens does not do")
    return case.model


def _rest(q: np.ndarray) -> StepState:
    z = np.zeros_like(q)
    e = np.zeros(0, dtype=q.dtype)
    return StepState(q, z, z, e, e, e)


def _matrices(model: Any, t: float, q: np.ndarray, params: Any) -> tuple[np.ndarray, np.ndarray]:
    """(K, M) at rest at q, dense."""
    lin = model.linearize(t, _rest(q), params)
    K = as_dense(lin.R_q) if lin.R_q is not None else np.zeros(lin.R_z.shape, dtype=q.dtype)
    return np.array(K), np.array(as_dense(lin.R_z))


def _state_at(case: Subject, x: np.ndarray, time: float | None, sensitivities: bool
              ) -> tuple[float, np.ndarray, np.ndarray | None]:
    """(t, q, dq/dx or None) of the initial state, or of the stored step nearest ``time``."""
    model = case.model
    if time is None:
        q0 = model.initial_state(model.parameters(x))[0]
        return case.plan.t0, np.real(q0), None        # dq0/dx: through the complex design
    from ..case.load import Case
    from ..simulation import run_case
    if not isinstance(case, Case):
        raise AnalysisError("the modes at a time of a run need the case itself")
    if not case.plan.t0 <= time <= case.plan.t_end:
        raise AnalysisError(f"--time {time:g} s lies outside the case's window [{case.plan.t0:g}, "
                            f"{case.plan.t_end:g}] s")
    c = replace(case, plan=replace(case.plan, sensitivity_history=sensitivities, method="direct"))
    res = run_case(c, x, sensitivities=sensitivities, history=("q",))
    k = int(np.argmin(np.abs(res.time - time)))
    hist = res.sensitivity_history.get("q") if sensitivities and res.sensitivity_history else None
    dq = None if hist is None else hist[k]
    return float(res.time[k]), np.real(res.history["q"][k]), dq


def _design_derivatives(case: Subject, x: np.ndarray, t: float, q: np.ndarray, dq: np.ndarray | None,
                        matrices: Any, central: bool = False) -> list[tuple[np.ndarray, ...]]:
    """Per design variable j, the total derivatives of ``matrices(params, t, q)``: by complex step,
    or (``central``) by central differences of relative step ``FD_STEP``."""
    model = case.model
    size = np.where(x != 0, np.abs(x), case.scale)    # the steps are relative to these
    out = []
    for j in range(x.size):
        if central:
            h = FD_STEP * size[j]
            sides = []
            for sign in (1.0, -1.0):
                xs = x.copy()
                xs[j] += sign * h
                params = model.parameters(xs)
                qs = model.initial_state(params)[0] if dq is None else q + sign * h * dq[:, j]
                sides.append(matrices(params, t, np.real(qs)))
            out.append(tuple((a - b) / (2 * h) for a, b in zip(*sides)))
            continue
        h = CS_STEP * size[j]
        xc = x.astype(complex)
        xc[j] += 1j * h
        params = model.parameters(xc)
        qc = model.initial_state(params)[0].astype(complex) if dq is None else q + 1j * h * dq[:, j]
        out.append(tuple(np.imag(a) / h for a in matrices(params, t, qc)))
    return out


def _clusters(values: np.ndarray) -> list[list[int]]:
    groups: list[list[int]] = []
    for i, v in enumerate(values):
        if groups and abs(v - values[groups[-1][-1]]) <= REPEATED_GAP * max(abs(v), 1e-300):
            groups[-1].append(i)
        else:
            groups.append([i])
    return groups


def _eigen_derivatives(values: np.ndarray, shapes: np.ndarray,
                       terms: Sequence[Callable[[Any], Any]]) -> tuple[np.ndarray, np.ndarray]:
    """d(value)/dx_j = φᵀ A_j(value) φ per design variable j, (k, m); for a cluster of repeated
    values the sorted eigenvalues of Φᵀ A_j Φ (directional).  Also (k,) True where repeated."""
    k, m = values.size, len(terms)
    grad = np.zeros((k, m))
    repeated = np.zeros(k, bool)
    for group in _clusters(values):
        Phi = shapes[:, group]
        for j, A in enumerate(terms):
            B = Phi.T @ A(values[group[0]]) @ Phi
            grad[group, j] = np.sort(np.linalg.eigvalsh(0.5 * (B + B.T))) if len(group) > 1 else B[0, 0]
        repeated[group] = len(group) > 1
    return grad, repeated


def modes(case: Subject, x: Any = None, *, count: int = 6, time: float | None = None,
          sensitivities: bool = True) -> Modes:
    """The ``count`` lowest natural modes of ``case`` at design ``x`` (default x0).

    ``time``: linearize at the state a run reaches at the stored step nearest this time (s)
    instead of the initial state (velocities and accelerations set to zero).
    """
    model = _structural(case)
    x = case.x0 if x is None else np.asarray(x, dtype=float)
    t, q, dq = _state_at(case, x, time, sensitivities)
    K, M = _matrices(model, t, q, model.parameters(x))
    n = K.shape[0]
    count = min(int(count), n)
    if count < 1:
        raise AnalysisError(f"expected count >= 1, found {count}")
    try:
        lam, phi = sla.eigh(0.5 * (K + K.T), 0.5 * (M + M.T), subset_by_index=[0, count - 1])
    except np.linalg.LinAlgError:
        raise AnalysisError(f"{case.source}: the mass matrix is not positive definite (a DOF without mass, or "
                            "a rotation of lumped beams without rotary inertia): give every free DOF a mass") from None
    if np.any(lam < -1e-9 * max(abs(lam).max(), 1.0)):
        raise AnalysisError(f"{case.source}: the stiffness is not positive semi-definite at t = {t:g} s "
                            f"(lowest ω² = {lam[0]:.4g}): the structure is unstable there")
    lam = np.maximum(lam, 0.0)
    freq = np.sqrt(lam) / (2 * np.pi)
    grad = lam_grad = None
    repeated = np.zeros(count, bool)
    if sensitivities and x.size:
        derivs = _design_derivatives(case, x, t, q, dq, lambda p, tt, qq: _matrices(model, tt, qq, p))
        terms = [(lambda v, dK=dK, dM=dM: dK - v * dM) for dK, dM in derivs]
        lam_grad, repeated = _eigen_derivatives(lam, phi, terms)
        with np.errstate(divide="ignore", invalid="ignore"):
            grad = np.where(freq[:, None] > 0, lam_grad / (8 * np.pi ** 2 * freq[:, None]), np.nan)
    return Modes(freq, lam, phi, grad, repeated, model.dof_labels(), t, lam_grad)


def _load(model: Any, t: float, q0: np.ndarray, params: Any) -> np.ndarray:
    """The external force at rest at q₀, follower loads included: f_int(q₀) − F_R(t, q₀ at rest)."""
    return np.asarray(model._internal_force(q0, params)) - np.asarray(model.residual(t, _rest(q0), params))


def _reference_load(case: Subject, model: Any, q0: np.ndarray, params: Any, load_time: float | None
                    ) -> tuple[float, np.ndarray]:
    """(t, f): the external force at ``load_time``, or at the grid instant where it is largest."""
    if load_time is not None:
        return float(load_time), _load(model, float(load_time), q0, params)
    plan = case.plan
    grid = np.linspace(plan.t0, plan.t_end, plan.n_steps + 1)
    norms = [np.linalg.norm(np.real(_load(model, float(t), q0, params))) for t in grid]
    k = int(np.argmax(norms))
    return float(grid[k]), _load(model, float(grid[k]), q0, params)


def _buckling_matrices(model: Any, t: float, q0: np.ndarray, f: np.ndarray, params: Any
                       ) -> tuple[np.ndarray, np.ndarray]:
    """(K₀, K_G) for the load f at q₀ (real design): K_G by complex step in ε."""
    K0 = _matrices(model, t, q0, params)[0]
    u0 = np.linalg.solve(K0, f)
    h = 1e-30 * max(1.0, float(np.abs(q0).max(initial=0.0))) / max(float(np.abs(u0).max()), 1e-300)
    KG = np.imag(_matrices(model, t, q0 + 1j * h * u0, params)[0]) / h
    return K0, KG


def buckling(case: Subject, x: Any = None, *, count: int = 3, load_time: float | None = None,
             sensitivities: bool = True) -> Buckling:
    """The ``count`` lowest positive linear buckling load factors of the case's load.

    ``load_time``: the time (s) whose external force is the reference load (default: the grid
    instant of the window where it is largest).
    """
    model = _structural(case)
    x = case.x0 if x is None else np.asarray(x, dtype=float)
    params = model.parameters(x)
    q0 = np.real(model.initial_state(params)[0])
    t, f = _reference_load(case, model, q0, params, load_time)
    if not np.any(f):
        raise AnalysisError(f"{case.source}: there is no external force at t = {t:g} s to buckle under")
    K0, KG = _buckling_matrices(model, t, q0, np.real(f), params)
    K0s = 0.5 * (K0 + K0.T)
    try:
        nu, phi = sla.eigh(-0.5 * (KG + KG.T), K0s)
    except np.linalg.LinAlgError:
        raise AnalysisError(f"{case.source}: the stiffness is not positive definite at the initial state: "
                            "the structure is a mechanism or unsupported") from None
    positive = np.where(nu > 1e-12 * max(abs(nu).max(), 1e-300))[0][::-1]
    if not positive.size:
        raise AnalysisError(f"{case.source}: no buckling under this load (no geometric stiffness softens it: "
                            "geometrically nonlinear bars or co-rotational beams carry one)")
    sel = positive[:count]
    nu, phi = nu[sel], phi[:, sel]
    factors = 1.0 / nu
    grad = None
    repeated = np.zeros(sel.size, bool)
    if sensitivities and x.size:
        def matrices(p: Any, tt: float, qq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return _buckling_matrices(model, tt, qq, np.real(_load(model, tt, qq, p)), p)
        # K_G is itself a complex step (in ε): its design derivative is a central difference
        derivs = _design_derivatives(case, x, t, q0, None, matrices, central=True)
        terms = [(lambda v, dK0=dK0, dKG=dKG: -dKG - v * dK0) for dK0, dKG in derivs]
        nu_grad, repeated = _eigen_derivatives(nu, phi, terms)
        grad = -nu_grad / nu[:, None] ** 2
    return Buckling(factors, phi, grad, model.dof_labels(), t, repeated)
