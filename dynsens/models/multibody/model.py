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

The residual, its exact (analytic) linearization and the design partials are evaluated
by the vectorized kernel (:mod:`.kernel`, :mod:`.residual`); the term-by-term building
blocks define the same equations for the assembly, the outputs and the tests.  Kinematics
are cached by state, so residual, linearization, outputs and monitors at one state share
them; everything else the model keeps between calls is declared in its :class:`.RunCache`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from ...errors import ProblemCollector
from ..base import Linearization, Model, Output, StepState, Traits
from ..parameters import ParameterTable
from .bodies import BodyDef, BodyParams, Ctx, MBParams
from .drift import check_drift, describe_equation, diagnose_singular, norm2
from .forces import ForceElement, Gravity, PointForce, SpringDamper
from .hydraulics import HydraulicCylinder
from .joints import Equation, Joint, NormEq
from .kernel import KParams, Kin, Layout, kernel_params, stack_kernel_params
from .kernel_compiled import CompiledKin, KinCache, _use_compiled
from .residual import Evaluation, other_forces_q, time_inputs_steps
from .residual_compiled import evaluate
from .rotational import RotationalSpringDamper
from .rotations import from_axis_angle, rmatmul
from .run_cache import RunCache
from .sparse import SparseStructure, sparse_linearization, use_sparse

if TYPE_CHECKING:  # pragma: no cover
    from .assembly import InitialConditions
    from .projection import ProjectionSettings
    from .reaction_split import MinimumNormSplit
    from .redundancy import DroppedEquations

Array = np.ndarray
Recipe = Callable[..., Any]  # recipe(params); "..." admits lambdas with bound defaults


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

    singular_hint = ("a mechanism at a singular (e.g. dead-centre) configuration, redundant "
                     "constraints, zero masses or unsupported (rigid-body) degrees of freedom: "
                     "change the geometry or the joint set")
    #: no compiled blocks of steps yet: a step's drivers and pump are evaluated in Python and its
    #: kinematics go to the model's cache step by step (BENCHMARKS.md, "Blocks of primal steps")
    compiled_blocks = False

    def __init__(self, table: ParameterTable, bodies: list[BodyDef], ground: BodyDef,
                 joints: list[Joint], forces: list[ForceElement], cylinders: list[HydraulicCylinder],
                 vec_recipes: list[tuple[str, Recipe]], scal_recipes: list[tuple[str, Recipe]],
                 assembly: Assembly, alpha: float = 0.0, beta: float = 0.0, scale: float = 1.0,
                 springs: list[Any] | None = None, sparse: bool | None = None):
        self.table = table
        self.bodies = bodies
        self.ground = ground
        self.body_index = {b.name: b.index for b in bodies}
        self.joints = joints
        self.forces = forces
        self.cylinders = cylinders
        self.springs = springs or []
        self.members: list[Any] = []               # flexible members (:mod:`.members`), set by the builder
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
        n_q = 7 * len(bodies)
        n_p = sum(c.n_pressures for c in cylinders)     # actuators' first-order states
        self.traits = Traits(n_q=n_q, n_lam=len(self.eqs), n_p=n_p)
        grav = [f for f in forces if isinstance(f, Gravity)]
        self.gravity = grav[0] if grav else None
        self.point_forces = [f for f in forces if isinstance(f, PointForce) and f.frame == "global"]
        axial: list[Any] = [f for f in forces if isinstance(f, SpringDamper)] + list(cylinders)
        self.rotational = [f for f in forces if isinstance(f, RotationalSpringDamper)]
        self.other_forces = [f for f in forces if not isinstance(f, (Gravity, SpringDamper, RotationalSpringDamper))
                             and f not in self.point_forces]
        self.layout = Layout(len(bodies), self.eqs, axial, [f.point for f in self.point_forces], self.rotational)
        # the storage of the linearization (:mod:`.sparse`): chosen by size unless the case says
        self.traits = Traits(n_q=n_q, n_lam=len(self.eqs), n_p=n_p,
                             sparse=use_sparse(self.traits.n_z, self.other_forces, sparse))
        self.cache = RunCache()
        self._kin = KinCache(self.layout)
        lay = self.layout
        self._cf0 = np.zeros((1, lay.n_cp, 3))
        self._cf0[..., 0] = 1.0
        self._shift0 = np.zeros((1, lay.n_eq, 3))
        self._shift0[0, lay.norm_eq, 0] = 1.0
        # rows of J_Φ, ∂R2/∂q, ∂R2/∂q̇ (o) as combinations of the product rows ∂x, ∂ẋ, ∂ẍ/∂q
        # (r) with weights linear in the coefficient levels (c, ċ, c̈) (i): eq_row_weights[o, r, i];
        # the normalisations' rows are 2p·(p, ṗ, p̈ weighted by norm_row_weights[o])
        a, b2 = alpha, beta ** 2
        self.eq_row_weights = np.array([
            [[1, 0, 0], [0, 0, 0], [0, 0, 0]],
            [[b2, 2 * a, 1], [2 * a, 2, 0], [1, 0, 0]],
            [[2 * a, 2, 0], [2, 0, 0], [0, 0, 0]]], float)
        self.norm_row_weights = np.array([[1, 0, 0], [b2, 2 * a, 1], [2 * a, 2, 0]], float)

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
        for member in self.members:                # member masses lumped on their nodes (:mod:`.members`)
            member.lump_mass(prm)
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
        """Sum of the body masses, members' included (mass unit)."""
        return sum(bp.mass for bp in params.bodies) + sum(mb.grounded_mass(params) for mb in self.members)

    # ------------------------------------------------------------------ residual
    def constraint_values(self, ctx: Ctx, eqs: list[Equation] | None = None
                          ) -> tuple[Array, Array, Array]:
        """Φ, Φ̇, Φ̈ (n_eq, k) of ``eqs`` (default: the model's) for the batch in ctx, term by term."""
        vals = [eq.evaluate(ctx) for eq in (self.eqs if eqs is None else eqs)]
        if not vals:
            z = np.zeros((0, ctx.k))
            return z, z, z
        return tuple(np.concatenate([v[i] for v in vals]) for i in range(3))  # type: ignore[return-value]

    def coefficients(self, t: float, kp: KParams) -> tuple[Array, Array]:
        """Time coefficients (c, ċ, c̈) of the constraint products (B, n_cp, 3) and the shifts
        (s, ṡ, s̈) of the equations (B, n_eq, 3) (1 for the normalisations) at time t (s);
        shared arrays (kept for the step's time): callers must not write into them."""
        lay = self.layout
        if not lay.coefs and not lay.shifts:
            return self._cf0, self._shift0
        # kept with kp for the last t: Newton evaluates all iterates of a step at one time
        hit = kp.cache.coefficients
        if hit is not None and hit[0] == t:
            return hit[1]
        # (no one writes into them; they stay writeable like the constant ones above, because numba
        # compiles a read-only array argument as another type: a second signature of every kernel)
        cf, shift = self.coefficients_steps(np.array([t]), kp)
        kp.cache.coefficients = (t, (cf, shift))
        return cf, shift

    def coefficients_steps(self, ts: Array, kp: KParams) -> tuple[Array, Array]:
        """:meth:`coefficients` at K times ts (s) for all B sets: (K·B, n_cp, 3) and
        (K·B, n_eq, 3), entry k·B + j for time k and set j; each function is evaluated once,
        for the times (K, 1) against the sets (B,)."""
        lay = self.layout
        if not lay.coefs and not lay.shifts:
            return self._cf0, self._shift0
        K, B = len(ts), kp.B
        # one time is a scalar (cheaper arithmetic than a (1, 1) array)
        T = float(ts[0]) if K == 1 else np.asarray(ts, float)[:, None]
        dt = np.result_type(kp.pv, float)
        cf = np.repeat(self._cf0, K * B, axis=0).astype(dt)
        shift = np.repeat(self._shift0, K * B, axis=0).astype(dt)
        for target, funcs in ((cf, lay.coefs), (shift, lay.shifts)):
            by_step = target.reshape((K, B) + target.shape[1:])     # a view: target is contiguous
            for i, fn in funcs:
                for lev, v in enumerate(fn(T, kp)):
                    by_step[:, :, i, lev] = v
        return cf, shift

    def constraint_levels(self, t: float, kin: Kin) -> tuple[Array, Array]:
        """(Φ, Φ̇, Φ̈) stacked (B, n_eq, 3) and the product coefficients (B, n_cp, 3) at time t (s)."""
        lay = self.layout
        cf, shift = self.coefficients(t, kin.kp)
        X = kin.X[:, :lay.n_cp]
        if cf is self._cf0:           # constant unit coefficients: the rows are the products
            rows = X
        else:
            c, cd, cdd = cf[..., 0], cf[..., 1], cf[..., 2]
            x, xd, xdd = X[..., 0], X[..., 1], X[..., 2]
            rows = np.stack([c * x, cd * x + c * xd, cdd * x + 2.0 * cd * xd + c * xdd], axis=-1)
        Phi = rmatmul(lay.S, rows) - shift
        Phi[:, lay.norm_rows] += kin.N
        return Phi, cf

    def kinematics(self, s: StepState, params: MBParams | KParams) -> Kin:
        """Kernel kinematics at s (leaves (n,) or (B, n)) for one or stacked parameter sets."""
        kp = params if isinstance(params, KParams) else kernel_params(self.layout, params)
        return self._kin.get(kp, s.q, s.qd, s.qdd)

    def keep_kinematics(self, s: StepState, params: MBParams, arrays: tuple) -> None:
        """Keep the compiled kernel's kinematics ``arrays`` of the state s (the compiled step's,
        at the state it converged to) for the checks and outputs that read them next."""
        self._kin.put(kernel_params(self.layout, params), s.q, s.qd, s.qdd, arrays)

    def _evaluation(self, t: float, s: StepState, params: MBParams | KParams) -> Evaluation:
        kin = self.kinematics(s, params)
        last = self.cache.evaluation
        if last is not None and last[1].kin is kin and last[1].t == t and \
                last[2][0] is s.lam and last[2][1] is s.p and last[2][2] is s.pd:
            return last[1]        # the same state objects (residual, then linearize)
        lam = s.lam if s.lam.ndim == 2 else s.lam[None]
        p = s.p if s.p.ndim == 2 else s.p[None]
        pd = s.pd if s.pd.ndim == 2 else s.pd[None]
        key = (id(kin), t, lam.tobytes(), p.tobytes(), pd.tobytes(), lam.dtype.char, p.dtype.char)
        if last is not None and last[0] == key and last[1].kin is kin:
            return last[1]
        ev = evaluate(self, kin, t, lam, p, pd)
        self.cache.evaluation = (key, ev, (s.lam, s.p, s.pd))
        return ev

    def residual(self, t: float, s: StepState, params: MBParams) -> Array:
        """F_R (n_z,) at time t (s) and state s."""
        return self._evaluation(t, s, params).residual()[0]

    def stack_parameters(self, params_list: list[MBParams]) -> KParams:
        """The kernel parameters of all sets stacked along a leading batch axis (cached on the list)."""
        if len(params_list) == 1:                # one set: its own kernel parameters (cached on it)
            return kernel_params(self.layout, params_list[0])
        # the entry keeps its list alive: a new list cannot take over its identity
        if self.cache.stacked is None or self.cache.stacked[0] is not params_list:
            self.cache.stacked = (params_list, stack_kernel_params(
                [kernel_params(self.layout, p) for p in params_list]))
        return self.cache.stacked[1]

    def residual_batch(self, t: float, s: StepState, params_list: list[MBParams]) -> Array:
        """F_R (n_z, B) at one state for B parameter sets, one vectorized evaluation."""
        return self._evaluation(t, s, self.stack_parameters(params_list)).residual().T

    def residual_batch_steps(self, ts: Array, states: list[StepState], params_list: list[MBParams]) -> Array:
        """F_R (K, n_z, B) at K states (times ts, s) for B parameter sets: one compiled call for
        all K·B entries (entry k·B + j: state k, set j; the sets are stacked once and repeat
        cyclically), with the time inputs of each step; closed-form other forces (torques) are added
        per step.  Models with other Python force elements (body-frame point forces) or without
        the compiled kernel evaluate state by state."""
        kp = self.stack_parameters(params_list)
        lay, K, B = self.layout, len(states), kp.B
        if not (self._kin.compiled and lay.compiled_laws) or \
                not all(f.closed_form for f in self.other_forces):
            return super().residual_batch_steps(ts, states, params_list)
        # (np.array of a list of equal arrays: np.stack's copies, without its per-array Python work)
        q, qd, qdd, lam, p, pd = (np.repeat(np.array(v), B, axis=0) for v in zip(*states))
        if not _use_compiled(kp, q, qd, qdd):
            return super().residual_batch_steps(ts, states, params_list)
        kin = CompiledKin(lay, kp, q, qd, qdd, self._kin.pool)
        dt = kin.dtype
        cf, shift = self.coefficients_steps(ts, kp)
        ext, f_ext, g = time_inputs_steps(self, kp, ts, dt)
        ev = evaluate(self, kin, ts[-1], lam, p, pd, inputs=(cf, shift, ext, f_ext, g))
        R = ev.residual().reshape(K, B, -1)
        if self.other_forces:                     # closed-form elements, at each step's time
            for k, t in enumerate(ts):
                R[k, :, :lay.n_q] -= other_forces_q(self, t, q[k * B:(k + 1) * B], qd[k * B:(k + 1) * B], kp.prms)
        return R.transpose(0, 2, 1)

    def linearize(self, t: float, s: StepState, params: MBParams) -> Linearization:
        """Exact ∂F_R/∂(z, q, q̇, p), analytic (:mod:`.residual`); CSC blocks on the model's kept
        pattern when ``traits.sparse`` (:mod:`.sparse`)."""
        ev = self._evaluation(t, s, params)
        last = self.cache.linearization
        if last is not None and last[0] is ev:      # the same evaluation (the redundancy check
            return last[1]                          # after a step reads the solver's own)
        lin = sparse_linearization(self, ev) if self.traits.sparse else ev.linearization()
        self.cache.linearization = (ev, lin)
        return lin

    def compiled_step(self, newton: bool, refactor: bool) -> Callable[..., Any] | None:
        """The compiled Newton iteration of :mod:`.compiled_step`, where it serves this model."""
        from .compiled_step import step_factory
        return step_factory(self, newton, refactor)

    def sparse_structure(self) -> SparseStructure:
        """The positions of the sparse linearization's entries (built on first use)."""
        if self.cache.sparse is None:
            self.cache.sparse = SparseStructure.of(self)
        return self.cache.sparse

    def dropped_equations(self) -> "DroppedEquations":
        """The kernel of the redundant equations left out of Φ (:mod:`.redundancy`; built on
        first use)."""
        if self.cache.dropped is None:
            from .redundancy import DroppedEquations
            self.cache.dropped = DroppedEquations.of(self)
        return self.cache.dropped

    def reaction_split(self) -> "MinimumNormSplit":
        """The minimum-norm split of the dependent joints' reactions (:mod:`.reaction_split`;
        built on first use)."""
        if self.cache.reaction_split is None:
            from .reaction_split import MinimumNormSplit
            self.cache.reaction_split = MinimumNormSplit(self)
        return self.cache.reaction_split

    # ------------------------------------------------------------------ diagnostics
    redundant: list[tuple[str, str, Equation]] = []   # (joint, label, equation) left out of Φ
    dependent_joints: list[str] = []      # joints with equations in a dependent set (:mod:`.reaction_split`)

    def check_state(self, t: float, s: StepState, params: MBParams) -> None:
        """Raise ModelError after a step when ‖Φ‖ exceeds the drift limit (:mod:`.drift`), when a
        joint equation left out as redundant became independent (:mod:`.redundancy`), or when a
        cylinder chamber volume is not positive."""
        if self.redundant:          # first: a change of rank also shows as drift, less specifically
            from .redundancy import check_dependency
            check_dependency(self, t, s, params)
        check_drift(self, t, s, params)
        if not (self.cylinders or self.rotational):
            return
        kin = self.kinematics(s, params)
        lay = self.layout
        for rot, px in zip(self.rotational, lay.rot_prod):      # the measured angle's range
            rot.check_angle(t, float(np.arctan2(np.real(kin.X[0, px + 1, 0]), np.real(kin.X[0, px, 0]))))
        for cyl in self.cylinders:
            i = lay.axial.index(cyl)
            c = kin.kp.ec[i][0]
            cyl.check(np.sqrt(kin.X[0, lay.n_cp + i, 0]) - c[2], params, t, c)

    def diagnose_singular(self, t: float, s: StepState, params: MBParams, rel_tol: float = 1e-9) -> str:
        """Name the joints whose equations became linearly dependent at (t, s) (a dead-centre
        or change-point configuration), from the rank of J_Φ; '' when J_Φ has full rank
        (:func:`.drift.diagnose_singular`)."""
        return diagnose_singular(self, t, s, params, rel_tol)

    drift_limit: float | None = None

    def constraint_residuals(self, t: float, s: StepState, params: MBParams) -> Array:
        """(Φ, Φ̇, Φ̈) (n_eq, 3) at (t, s), kept for the same state object: the drift guard after
        a step and the monitors recorded for it share one evaluation (also when they name the
        step's time differently, t_prev + h and the grid's time, where no constraint depends on
        time); :attr:`.RunCache.constraint_levels`."""
        last = self.cache.constraint_levels
        if last is not None and last[1] is s.q and last[2] is s.qd and last[3] is params and \
                (last[0] == t or not (self.layout.coefs or self.layout.shifts)):
            return last[4]
        Phi = self.constraint_levels(t, self.kinematics(s, params))[0][0]
        self.cache.constraint_levels = (t, s.q, s.qd, params, Phi)
        return Phi

    #: ``model.projection`` (None: off): each step's end state projected onto Φ = 0, Φ̇ = 0
    projection: "ProjectionSettings | None" = None

    def project(self, t: float, s: StepState, params: MBParams) -> tuple[StepState, Any]:
        """(q, q̇) of an accepted step projected onto the position and velocity constraints when
        ``model.projection`` is on (:mod:`.projection`); else s unchanged."""
        if self.projection is None:
            return s, None
        from .projection import project
        out, proj = project(self, self.projection, t, s, params)
        self.cache.solved = (t, proj.projected, s)          # for the monitors of this step
        return out, proj

    def monitors(self, t: float, s: StepState, params: MBParams) -> dict[str, float]:
        """‖Φ‖ and ‖Φ̇‖ (real parts) at one step (the drift guard is in :meth:`check_state`); with
        ``model.projection`` also those of the state Newton solved before the projection
        (``*_solved``: in mode output the state the integration continues from)."""
        Phi = self.constraint_residuals(t, s, params)
        out = {"constraint_position": norm2(np.real(Phi[:, 0])),
               "constraint_velocity": norm2(np.real(Phi[:, 1]))}
        if self.projection is not None:
            from .projection import solved_monitors
            last = self.cache.solved
            solved = last[2] if last is not None and last[0] == t and last[1].q is s.q else s
            out.update(solved_monitors(self, t, solved, s, params, Phi))
        return out

    def dof_labels(self) -> list[str]:
        """'body.x', 'body.y', 'body.z', 'body.e0' ... 'body.e3' per moving body."""
        return [f"{b.name}.{c}" for b in self.bodies for c in ("x", "y", "z", "e0", "e1", "e2", "e3")]

    #: YAML entries by name (set by the builder): joints, forces per body, the bodies' section
    entry_paths: dict[str, Any] = {}

    def describe_equation(self, k: int) -> str:
        """A body coordinate with its body's YAML entry and the forces naming it, or a
        constraint equation with its joint's YAML entry (:func:`.drift.describe_equation`)."""
        return describe_equation(self, k) or super().describe_equation(k)

    def multiplier_labels(self) -> list[str]:
        """Names of the constraint equations / multipliers, in λ order."""
        return list(self.eq_owner)

    # ------------------------------------------------------------------ initial state
    point_mass_attachments: list[tuple[str, str, str]] = []   # (body, vec key, what): see .pointmass

    def initial_state(self, params: MBParams) -> tuple[Array, Array, Array]:
        """Consistent (q0, q̇0, p0) by assembly; see :mod:`.assembly`."""
        from .assembly import initial_conditions
        if self.point_mass_attachments:
            from .pointmass import check_attachments
            check_attachments(self, params)
        res = initial_conditions(self, params)
        if self.redundant:          # the dropped equations hold at this design's assembly too
            from .redundancy import check_values
            check_values(self, self.assembly.t0, res.q0, params, 0.0)
        self.cache.initial = (params, res)
        return res.q0, res.qd0, res.p0

    def _initial_conditions(self, params: MBParams) -> "InitialConditions":
        """The assembly of :meth:`initial_state` when it was for the same parameter object."""
        if self.cache.initial is not None and self.cache.initial[0] is params:
            return self.cache.initial[1]
        from .assembly import initial_conditions
        return initial_conditions(self, params)

    def initial_guess(self, params: MBParams) -> tuple[Array, Array]:
        """(λ0, ṗ0) from the static solve of the assembly (good Newton start)."""
        res = self._initial_conditions(params)
        return res.lam0, res.pd0

    def initial_state_gradient(self, params0: MBParams, partials: Any
                               ) -> tuple[Array, Array, Array]:
        """∇q0, ∇q̇0, ∇p0 by implicit differentiation of the assembly (see :mod:`.assembly`)."""
        from .assembly import initial_gradient
        return initial_gradient(self, params0, partials, self._initial_conditions(params0))

    def output(self, spec: Any, path: str, problems: ProblemCollector) -> Output | None:
        """Resolve a quantity spec (see :mod:`.outputs`)."""
        from .outputs import resolve_output
        return resolve_output(self, spec, path, problems)
