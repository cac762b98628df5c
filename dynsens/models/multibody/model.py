r"""The rigid-multibody model (``model.type: multibody``): index-1 DAE residual.

Unknowns per step ``z = [q̈; λ; ṗ]`` (method.md §1), residual blocks

    row 1 (n_q):   M(q) q̈ + J_Φᵀ λ − Q_ext(q, q̇, p, t, x) − Q_v(q, q̇)
    row 2 (n_λ):   c_s (Φ̈ + 2α Φ̇ + β² Φ)     with Φ̈ = J_Φ q̈ − F_c   (Baumgarte)
    row 3 (n_p):   ṗ − h(q, q̇, p, t, x)

* q: 7 coordinates per moving body (COM position, Euler parameters; :mod:`.bodies`),
  mass matrix diag(m I, 4 GᵀJ'G) and quadratic-velocity term 8 G(ṗ)ᵀJ'G(ṗ)p.
* Φ: the joint equations (:mod:`.joints`) followed by one Euler-parameter
  normalisation per body, in that order; λ has the same order.
* α, β (1/s) are the Baumgarte parameters (``stabilization``; default 0, i.e. the
  plain index-1 form) and c_s (``constraint_scale``, default 1) scales row 2.  Both are
  part of the residual, so the sensitivities are consistent with them.

``linearize`` returns the exact partial derivatives, computed in one batched call of
the (complex-safe) residual: by complex step (step 1e-30) when state and parameters are
real, by central differences when they are complex (a complex-step-of-the-whole-run
verification, where only Newton uses the matrix).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ...errors import ProblemCollector
from ..base import Linearization, Model, Output, ParameterTable, StepState, Traits
from .bodies import BodyDef, BodyParams, Ctx, MBParams, inertial_forces
from .forces import ForceElement
from .hydraulics import HydraulicCylinder
from .joints import DotBlock, Equation, Joint, NormEq
from .rotations import from_axis_angle

Array = np.ndarray
Recipe = Callable[[MBParams], Any]


@dataclass
class Assembly:
    """Assembly settings: extra equations used only to find q0, the time, tolerance."""

    equations: list[Equation] = field(default_factory=list)
    labels: list[str] = field(default_factory=list)
    t0: float = 0.0
    tol: float = 1e-12
    max_iterations: int = 50


class MultibodyModel(Model):
    """Rigid bodies with Euler parameters, joints, forces and hydraulic cylinders."""

    def __init__(self, table: ParameterTable, bodies: list[BodyDef], ground: BodyDef,
                 joints: list[Joint], forces: list[ForceElement], cylinders: list[HydraulicCylinder],
                 vec_recipes: list[tuple[str, Recipe]], scal_recipes: list[tuple[str, Recipe]],
                 assembly: Assembly, alpha: float = 0.0, beta: float = 0.0, scale: float = 1.0,
                 springs: list[Any] | None = None):
        self.table = table
        self.bodies = bodies
        self.ground = ground
        self.body_index = {b.name: b.index for b in bodies}
        self.joints = joints
        self.forces = forces
        self.cylinders = cylinders
        self.springs = springs or []
        self.vec_recipes = vec_recipes
        self.scal_recipes = scal_recipes
        self.assembly = assembly
        self.alpha, self.beta, self.scale = alpha, beta, scale
        self.eqs: list[Equation] = []
        self.eq_owner: list[str] = []
        for jt in joints:
            jt.rows = tuple(range(len(self.eqs), len(self.eqs) + len(jt.eqs)))
            self.eqs += jt.eqs
            self.eq_owner += [f"{jt.name}.{lab}" for lab in jt.labels]
        for b in bodies:
            self.eqs.append(NormEq(b.index))
            self.eq_owner.append(f"{b.name}.normalization")
        plain = [i for i, eq in enumerate(self.eqs) if DotBlock.accepts(eq)]
        self._block_rows = np.array(plain, dtype=int)
        self._block = DotBlock([self.eqs[i] for i in plain]) if plain else None   # type: ignore[misc]
        self._other_rows = [i for i in range(len(self.eqs)) if i not in set(plain)]
        n_q = 7 * len(bodies)
        n_p = 2 * len(cylinders)
        self.traits = Traits(n_q=n_q, n_lam=len(self.eqs), n_p=n_p)
        self._ic_cache: tuple[Any, Any] | None = None

    # ------------------------------------------------------------------ parameters
    def parameters(self, x: Array) -> MBParams:
        """Evaluate all entries and derived body-fixed vectors for design x (complex-safe)."""
        pv = self.table.evaluate(np.asarray(x))
        bps = []
        for b in self.bodies:
            bps.append(self._body_params(b, pv))
        prm = MBParams(pv, bps, {}, {}, np.asarray(x))
        for key, fn in self.vec_recipes:
            prm.vec[key] = np.asarray(fn(prm)).reshape(3, 1)
        for key, fn in self.scal_recipes:          # may use the vectors (free lengths)
            prm.scal[key] = fn(prm)
        return prm

    @staticmethod
    def _body_params(b: BodyDef, pv: Array) -> BodyParams:
        I = [pv[i] for i in b.inertia]
        J = np.array([[I[0], I[3], I[4]], [I[3], I[1], I[5]], [I[4], I[5], I[2]]])
        o = b.orientation
        if o[0] == "axis":
            p0 = from_axis_angle(np.array([pv[i] for i in o[1]]), pv[o[2]])
        elif o[0] == "ep":
            e = np.array([pv[i] for i in o[1]])
            p0 = e / np.sqrt(np.sum(e * e))
        else:
            p0 = np.array([1.0, 0.0, 0.0, 0.0], dtype=pv.dtype)
        return BodyParams(pv[b.mass], J, np.array([pv[i] for i in b.position]), p0,
                          np.array([pv[i] for i in b.velocity]),
                          np.array([pv[i] for i in b.angular_velocity]))

    def structural_mass(self, params: MBParams) -> Any:
        """Sum of the body masses (mass unit)."""
        return sum(bp.mass for bp in params.bodies)

    # ------------------------------------------------------------------ residual
    def constraint_values(self, ctx: Ctx, eqs: list[Equation] | None = None
                          ) -> tuple[Array, Array, Array]:
        """Φ, Φ̇, Φ̈ (n_eq, k) for the batch in ctx (default: the model's Φ, block-evaluated)."""
        if eqs is None and self._block is not None:
            dt = np.result_type(ctx.q, ctx.qd, ctx.qdd, ctx.params.pv, float)
            out = [np.empty((len(self.eqs), ctx.k), dt) for _ in range(3)]
            for o, v in zip(out, self._block.evaluate(ctx)):
                o[self._block_rows] = v
            for i in self._other_rows:
                for o, v in zip(out, self.eqs[i].evaluate(ctx)):
                    o[i] = v[0]
            return out[0], out[1], out[2]
        vals = [eq.evaluate(ctx) for eq in (self.eqs if eqs is None else eqs)]
        if not vals:
            z = np.zeros((0, ctx.k))
            return z, z, z
        return tuple(np.concatenate([v[i] for v in vals]) for i in range(3))  # type: ignore[return-value]

    def generalized_forces(self, ctx: Ctx, p: Array) -> Array:
        """Q_ext (n_q, k): applied forces and cylinder forces."""
        dt = np.result_type(ctx.q, ctx.qd, ctx.params.pv, p, float)
        Q = np.zeros((self.traits.n_q, ctx.k), dt)
        for el in self.forces:
            el.add(ctx, Q)
        for cyl in self.cylinders:
            cyl.add(ctx, p, Q)
        return Q

    def residual_columns(self, t: float, q: Array, qd: Array, qdd: Array, lam: Array, p: Array,
                       pd: Array, params: MBParams) -> Array:
        """F_R (n_z, k) for a batch of states (each argument (n, k) or (n, 1))."""
        k = max(a.shape[1] for a in (q, qd, qdd, lam, p, pd))
        dt = np.result_type(q, qd, qdd, lam, p, pd, params.pv, float)
        q, qd, qdd = (np.broadcast_to(a, (a.shape[0], k)) for a in (q, qd, qdd))
        ctx = Ctx(q, qd, qdd, params, t)
        R1 = np.zeros((self.traits.n_q, k), dt)
        inertial_forces(ctx, len(self.bodies), R1)
        lam = np.broadcast_to(lam, (lam.shape[0], k))
        if self._block is not None:
            self._block.push(ctx, lam[self._block_rows])
        for i in self._other_rows:
            self.eqs[i].push(ctx, lam[i:i + 1])
        ctx.flush(R1)
        R1 = R1 - self.generalized_forces(ctx, p)
        phi, phid, phidd = self.constraint_values(ctx)
        R2 = self.scale * (phidd + 2.0 * self.alpha * phid + self.beta ** 2 * phi)
        R3 = np.zeros((self.traits.n_p, k), dt) + pd
        for cyl in self.cylinders:
            h1, h2 = cyl.rates(ctx, p)
            j = cyl.p_index
            R3[j:j + 1] -= h1
            R3[j + 1:j + 2] -= h2
        return np.concatenate([R1, R2 * np.ones((1, k)), R3])

    def residual(self, t: float, s: StepState, params: MBParams) -> Array:
        """F_R (n_z,) at time t (s) and state s."""
        return self.residual_columns(t, *(v[:, None] for v in s), params)[:, 0]

    def linearize(self, t: float, s: StepState, params: MBParams) -> Linearization:
        """Exact ∂F_R/∂(z, q, q̇, p) (complex step; central differences for complex states)."""
        tr = self.traits
        n_q, n_lam, n_p, n_z = tr.n_q, tr.n_lam, tr.n_p, tr.n_z
        sizes = (n_q, n_q, n_q, n_lam, n_p, n_p)        # q, qd, qdd, lam, p, pd
        # columns: z = (qdd, lam, pd), then q, qd, p
        order = [2, 3, 5, 0, 1, 4]
        k = sum(sizes[i] for i in order)
        offs: dict[int, int] = {}
        c = 0
        for i in order:
            offs[i] = c
            c += sizes[i]
        base = list(s)
        real = not any(np.iscomplexobj(v) for v in base) and not np.iscomplexobj(params.pv)

        def batch(step: complex | Array) -> list[Array]:
            out = []
            for i, v in enumerate(base):
                E = np.zeros((sizes[i], k), dtype=complex if real else float)
                idx = np.arange(sizes[i])
                E[idx, offs[i] + idx] = step if np.isscalar(step) else step[i]
                out.append(v[:, None] + E)
            return out

        if real:
            h = 1e-30
            D = np.imag(self.residual_columns(t, *batch(1j * h), params)) / h
        else:
            steps = [1e-7 * (1.0 + np.abs(np.real(v))) for v in base]
            Rp = self.residual_columns(t, *batch(steps), params)
            Rm = self.residual_columns(t, *batch([-x for x in steps]), params)
            hcol = np.concatenate([steps[i] for i in order])
            D = (Rp - Rm) / (2.0 * hcol[None, :])
        R_z = D[:, :n_z]
        R_q = D[:, n_z:n_z + n_q]
        R_qd = D[:, n_z + n_q:n_z + 2 * n_q]
        R_p = D[:, n_z + 2 * n_q:] if n_p else None
        return Linearization(R_z, R_q, R_qd, R_p)

    # ------------------------------------------------------------------ diagnostics
    def check_state(self, t: float, s: StepState, params: MBParams) -> None:
        """Raise ModelError when a cylinder chamber volume is not positive."""
        if not self.cylinders:
            return
        ctx = Ctx(s.q[:, None], s.qd[:, None], s.qdd[:, None], params, t)
        for cyl in self.cylinders:
            cyl.check(ctx, t)

    def monitors(self, t: float, s: StepState, params: MBParams) -> dict[str, float]:
        """‖Φ‖ and ‖Φ̇‖ (real parts) at one step."""
        ctx = Ctx(s.q[:, None], s.qd[:, None], s.qdd[:, None], params, t)
        phi, phid, _ = self.constraint_values(ctx)
        return {"constraint_position": float(np.linalg.norm(np.real(phi))),
                "constraint_velocity": float(np.linalg.norm(np.real(phid)))}

    def dof_labels(self) -> list[str]:
        """'body.x', 'body.y', 'body.z', 'body.e0' ... 'body.e3' per moving body."""
        return [f"{b.name}.{c}" for b in self.bodies for c in ("x", "y", "z", "e0", "e1", "e2", "e3")]

    def multiplier_labels(self) -> list[str]:
        """Names of the constraint equations / multipliers, in λ order."""
        return list(self.eq_owner)

    # ------------------------------------------------------------------ initial state
    def initial_state(self, params: MBParams) -> tuple[Array, Array, Array]:
        """Consistent (q0, q̇0, p0) by assembly; see :mod:`.assembly`."""
        from .assembly import initial_conditions
        res = initial_conditions(self, params)
        self._ic_cache = (params, res)
        return res.q0, res.qd0, res.p0

    def initial_guess(self, params: MBParams) -> tuple[Array, Array]:
        """(λ0, ṗ0) from the static solve of the assembly (good Newton start)."""
        if self._ic_cache is not None and self._ic_cache[0] is params:
            res = self._ic_cache[1]
        else:
            from .assembly import initial_conditions
            res = initial_conditions(self, params)
        return res.lam0, res.pd0

    def initial_state_gradient(self, params0: MBParams, partials: Any
                               ) -> tuple[Array, Array, Array]:
        """∇q0, ∇q̇0, ∇p0 by implicit differentiation of the assembly (see :mod:`.assembly`)."""
        from .assembly import initial_gradient
        return initial_gradient(self, params0, partials)

    def output(self, spec: Any, path: str, problems: ProblemCollector) -> Output | None:
        """Resolve a quantity spec (see :mod:`.outputs`)."""
        from .outputs import resolve_output
        return resolve_output(self, spec, path, problems)
