r"""Structural dynamics models: element sets of registered kinds on scalar DOFs and nodes.

Residual (method.md §1) with z = q̈:

.. math:: F_R = M\ddot q + D\dot q + f_{int}(q) - f_{ext}(t) = 0

* the element kinds (:mod:`.elements`: point masses, springs, dampers, truss bars, cables, plane
  and space beams) contribute M's diagonal (lumped masses) and consistent masses, D's viscous
  entries and nonlinear damping forces, f_int and its tangent; the model loops over its element
  sets, one per kind, in the kinds' fixed order (the order of every sum);
* Rayleigh damping α M + β K₀ (K₀: the stiffness at q = 0) whose stiffness part acts, for bars
  and co-rotational beams, on the elements' deformation rates in their turning frames
  (:mod:`.corotated_damping`); loads value · function(t), and follower loads (:mod:`.follower`).

The model also resolves output quantities (DOF histories; element quantities by the element's
kind) and answers the run-time diagnostics (the elements and loads acting on a DOF, the size
of q its data imply).  Elements of one kind are stored as arrays and evaluated together.  Fixed DOFs (supports,
``ground``) map to an extra slot that always holds zero.  All code is complex-safe.
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np
import scipy.sparse as sp

from ...case_keys import allowed
from ...errors import ProblemCollector
from .._keys import check_keys, did_you_mean
from ..base import Linearization, Model, Output, OutputPattern, StepState, Traits
from .parameter_set import ParameterSet
from ..parameters import ParameterTable
from .beams import BeamSet
from .beams3d import Beam3DSet
from .corotated_damping import CorotatedDamping
from .dampers import NonlinearDampers
from .elements import ElementKind, ModelContext
from .follower import FollowerLoads
from ..sparse_assembly import PatternAssembly, RightProduct, UnionCache
from .matrices import StructuralMatrices
from ..timefunctions import TimeFunction

GROUND = "ground"
AXES = ("x", "y", "z")
# DOFs above which ``linear_algebra: auto`` chooses the sparse path: the measured break-even on
# the Duffing chain (dense and sparse equal at 100 DOFs, sparse 8 % ahead at 120 and 27 % at
# 200) and about the same on the tower frame (144 DOFs: equal; BENCHMARKS.md)
SPARSE_THRESHOLD = 100
_EMPTY_BEAMS, _EMPTY_FRAMES = BeamSet(), Beam3DSet()      # the beams of the other dimension: none
_EMPTY_BEAMS.freeze()
_EMPTY_FRAMES.freeze()


class StructuralModel(StructuralMatrices, Model):
    """Assembled structural model; built from a case by :func:`build_structural`.  It knows no
    element kind by name: it loops over its element sets (:mod:`.elements`), in their order.
    Its matrices and their assembly are :class:`.matrices.StructuralMatrices`."""

    #: (YAML entry, DOFs it acts on) of every element and load, set by the builder
    equation_sources: list[tuple[str, list[int]]] = []
    #: a spring network's compiled steps run in blocks (:mod:`.step_kernels`)
    compiled_blocks = True

    def __init__(self, *, dof_names: list[str], table: ParameterTable, sets: list[ElementKind], dim: int,
                 node_coords: dict[str, list[int]], loads: list[tuple[int, int, TimeFunction]],
                 initial: tuple[list[tuple[int, int]], list[tuple[int, int]]],
                 rayleigh: tuple[int, int] | None, sparse: bool | None,
                 followers: FollowerLoads | None = None, rayleigh_corotated: bool = True):
        self.dof_names = dof_names
        self.table = table
        n = len(dof_names)
        self.n = n
        self.dim = dim
        self.node_names = list(node_coords)
        self.node_coords = node_coords     # name -> parameter indices of its coordinates (drawing)
        self.sets = sorted(sets, key=lambda k: k.order)
        self.loads = loads
        self.init_q, self.init_qd = initial
        self.rayleigh = rayleigh
        self.followers = followers if followers is not None else FollowerLoads()
        nonlinear = any(k.nonlinear() for k in self.sets) or bool(len(self.followers))
        # consistent-mass plane beams: a mass M(q) that turns with them (inertia forces per element);
        # consistent space frames (small rotations): a constant M
        self.rotating_mass = any(k.mass_turns() for k in self.sets)
        self.frame_mass = any(k.constant_mass() for k in self.sets)
        has_damping = rayleigh is not None or any(k.damped() for k in self.sets)
        use_sparse = (n > SPARSE_THRESHOLD) if sparse is None else sparse
        self.traits = Traits(n_q=n, linear=not nonlinear, constant_matrices=not nonlinear,
                             has_damping=has_damping, sparse=use_sparse)
        context = ModelContext(n, dim, self._scatter, not nonlinear)
        for k in self.sets:
            k.freeze(context)
        # the sets with elements; per contribution, those whose kind provides it: the per-iteration
        # loops visit only these (an empty set, or the protocol's default, adds nothing)
        self.active = [k for k in self.sets if len(k)]
        self.providing = {name: [k for k in self.active if getattr(type(k), name) is not getattr(ElementKind, name)]
                          for name in ("internal_force", "damping_force", "inertia_force", "tangent",
                                       "damping_tangent", "range_problem")}
        self.compiled_kinds = all(k.served_compiled() for k in self.sets)   # declared by the kinds
        # Rayleigh's β K on the deformation rates of the elements that turn (K₀ keeps the others)
        kinds = [d for d in (k.damped_kind() for k in self.sets) if d is not None]
        self.corotated_damping = CorotatedDamping(kinds if rayleigh is not None and rayleigh_corotated else [],
                                                  rayleigh[1] if rayleigh is not None else -1, n)
        # the partials' parameter sets: (the list, its stacked arrays, the compiled residuals or None)
        self._stacked: tuple[list[dict[str, Any]], dict[str, Any], Any] | None = None
        # per parameter set (the run's, the partials' stacked one): (params, t, f_ext, settled)
        self._last_loads: dict[int, tuple[Any, float, np.ndarray, float]] = {}
        self._assembly_plans: dict[str, tuple[Any, ...]] = {}   # per _assemble site: kept indices
        self._patterns: dict[str, PatternAssembly] = {}          # sparse models: per _assemble site
        self._sums: dict[str, UnionCache] = {}                   # sparse models: per _add site
        self._unions = UnionCache()                              # sparse iteration matrices
        self._diag_mass: tuple[np.ndarray, Any] | None = None    # (mass vector, its sparse diag(M))
        self._pattern_kept: tuple[int, np.ndarray] | None = None  # dense models: see _dense_pattern
        self._design_rows: tuple[np.ndarray, ...] | None = None  # design_pattern, made once

    # ------------------------------------------------------------------ the element sets by kind
    def elements_of(self, type_name: str) -> Any:
        """The element set of ``type_name`` in this model, or None."""
        return next((k for k in self.sets if k.type == type_name), None)

    @property
    def springs(self) -> Any:
        """The springs' set (:class:`.elements.springs.Springs`)."""
        return self.elements_of("spring")

    @property
    def spring_names(self) -> list[str]:
        return self.springs.names

    @property
    def spring_dofs(self) -> np.ndarray:
        return self.springs.dof_idx

    @property
    def _spring_scatter(self) -> RightProduct:
        return self.springs.scatter

    @property
    def damper_names(self) -> list[str]:
        """Names of the linear viscous dampers."""
        return self.elements_of("damper").linear_names

    @property
    def nl_dampers(self) -> NonlinearDampers:
        return self.elements_of("damper").nl

    @property
    def bar_names(self) -> list[str]:
        return self.elements_of("bar").names

    @property
    def bar_I(self) -> np.ndarray:
        """Parameter indices of the bars' second moments of area (−1: not given)."""
        return self.elements_of("bar").I

    @property
    def bar_X(self) -> np.ndarray:
        """Parameter indices of the bars' end coordinates (n_e, 2, dim)."""
        return self.elements_of("bar").X

    @property
    def beams(self) -> BeamSet:
        """The plane beams (empty in a 3D model)."""
        kind = self.elements_of("beam")
        return kind.set if self.dim == 2 and kind is not None else _EMPTY_BEAMS

    @property
    def frames(self) -> Beam3DSet:
        """The space-frame beams (empty in a plane model)."""
        kind = self.elements_of("beam")
        return kind.set if self.dim == 3 and kind is not None else _EMPTY_FRAMES

    def _scatter(self, dofs: np.ndarray, signs: np.ndarray, per_element: bool) -> RightProduct:
        """The product with the scatter matrix Gᵀ: nodal forces = element values @ Gᵀ.

        With ``per_element`` one value per element acts on its k DOFs with ``signs`` (springs);
        otherwise every element supplies k values, one per DOF (bars).  Fixed DOFs are dropped.
        """
        n_e, k = dofs.shape
        rows = dofs.ravel()
        cols = np.repeat(np.arange(n_e), k) if per_element else np.arange(n_e * k)
        vals = np.tile(signs, n_e)
        keep = rows < self.n
        G = sp.csr_matrix((vals[keep], (rows[keep], cols[keep])),
                          shape=(self.n, n_e if per_element else n_e * k))
        return RightProduct(G.T.tocsr() if self.traits.sparse else G.toarray().T)

    # ------------------------------------------------------------------ parameters
    def parameters(self, x: np.ndarray) -> dict[str, Any]:
        """Evaluated parameter vector and derived element data for design x."""
        pv = self.table.evaluate(np.asarray(x))
        out = ParameterSet(pv=pv)
        mass = np.zeros(self.n + 1, dtype=pv.dtype)
        for k in self.sets:
            k.parameters(pv, out, mass)
        out["mass"] = mass[:self.n]
        # the matrices are assembled when first read: the sets of perturbed designs that only
        # serve outputs, the mass or the initial state never assemble them (ParameterSet)
        if self.rotating_mass or self.frame_mass:
            out.defer("M0", lambda prm: self._mass_matrix(prm, pv.dtype))
        if self.rayleigh is not None:
            # the co-rotated elements' β K acts on their deformation rates instead (residual)
            out.defer("K0", lambda prm: self._tangent(np.zeros(self.n, dtype=pv.dtype), prm,
                                                      corotated=not self.corotated_damping))
        if self.traits.has_damping:
            # viscous and Rayleigh damping depend on the design only: assemble once per design
            out.defer("D", lambda prm: self._damping_of_design(prm, pv.dtype))
        return out

    def _damping_of_design(self, params: dict[str, Any], dtype: Any) -> Any:
        """The design's damping matrix D (viscous and Rayleigh), read-only when sparse."""
        D = self._damping(params, dtype)
        if sp.issparse(D):
            D.data.flags.writeable = False      # constant for the run: kept scaled per step size
        return D

    def _inertia(self, params: dict[str, Any], s: Any) -> np.ndarray:
        """Inertia forces (..., n): M q̈ of the diagonal masses plus the consistent beams'
        M(q)q̈ + velocity terms; params and state leaves may carry leading batch axes."""
        f = params["mass"] * s.qdd
        if self.rotating_mass or self.frame_mass:
            qe, qde, qdde = self._ext(s.q), self._ext(s.qd), self._ext(s.qdd)
            for k in self.providing["inertia_force"]:
                fk = k.inertia_force(qe, qde, qdde, params)
                if fk is not None:
                    f = f + fk
        return f

    def initial_state(self, params: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        pv = params["pv"]
        q0 = np.zeros(self.n, dtype=pv.dtype)
        qd0 = np.zeros(self.n, dtype=pv.dtype)
        for d, i in self.init_q:
            q0[d] = pv[i]
        for d, i in self.init_qd:
            qd0[d] = pv[i]
        return q0, qd0, np.zeros(0, dtype=pv.dtype)

    def initial_state_gradient(self, params0: dict[str, Any], partials: Any
                               ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """∇q0, ∇q̇0, ∇p0 (n, m) each: zero when no initial condition is given (the state starts
        at rest whatever the design: no perturbed parameter set is evaluated for it); None
        otherwise (numerically, :func:`dynsens.derivatives.partials.initial_state_gradient`)."""
        if self.init_q or self.init_qd:
            return None
        m = partials.m
        return np.zeros((self.n, m)), np.zeros((self.n, m)), np.zeros((0, m))

    # ------------------------------------------------------------------ element kernels
    def _ext(self, v: np.ndarray) -> np.ndarray:
        """v with a trailing zero entry: the slot of fixed DOFs and ground."""
        return np.concatenate([v, np.zeros(v.shape[:-1] + (1,), dtype=v.dtype)], axis=-1)

    def external_force(self, t: float, params: dict[str, Any]) -> np.ndarray:
        """f_ext(t) (..., n) in force units; params may be stacked along a leading batch axis.
        The loads of the last time of each parameter set are kept (read-only), and reused at
        another time where both times are past the time functions' last change
        (:meth:`.TimeFunction.settled_from`): the same numbers, not evaluated again each step."""
        last = self._last_loads.get(id(params))
        if last is not None and last[0] is params and (last[1] == t or min(t, last[1]) > last[3]):
            return last[2]
        pv = params["pv"]
        f = np.zeros(pv.shape[:-1] + (self.n + 1,), dtype=pv.dtype)
        for dof, amp, fn in self.loads:
            f[..., dof] += pv[..., amp] * fn.value(t, pv)
        f = f[..., :self.n]
        f.flags.writeable = False
        if last is None and len(self._last_loads) >= 4:     # (a run's sets: its own and the partials')
            self._last_loads.clear()
        settled = last[3] if last is not None and last[0] is params else \
            max((fn.settled_from(pv) for _, _, fn in self.loads), default=-np.inf)
        self._last_loads[id(params)] = (params, t, f, settled)
        return f

    # ------------------------------------------------------------------ residual contract
    def residual(self, t: float, s: StepState, params: dict[str, Any]) -> np.ndarray:
        f_int = self._internal_force(s.q, params)
        R = self._inertia(params, s) + f_int - self.external_force(t, params)
        if len(self.followers):
            R = R - self.followers.force(t, self._ext(s.q), params["pv"])[..., :self.n]
        if self.traits.has_damping:
            R = R + params["D"] @ s.qd
            fv = self._velocity_forces(s.qd, params)
            if fv is not None:
                R = R + fv
            R = R + self._corotated_damping_force(s.q, s.qd, params)
        return R

    def _corotated_damping_force(self, q: np.ndarray, qd: np.ndarray, params: dict[str, Any]) -> Any:
        """Nodal forces (..., n) of β K on the elements' deformation rates (0 where there is none)."""
        if not self.corotated_damping.active(params):
            return 0.0
        return self.corotated_damping.force(self._ext(q), self._ext(qd), params)

    def _velocity_forces(self, qd: np.ndarray, params: dict[str, Any]) -> Any:
        """Nodal forces (..., n) of the nonlinear dampers, summed in the sets' order; None without any."""
        f = None
        for k in self.providing["damping_force"]:
            fk = k.damping_force(qd, params)
            if fk is not None:
                f = fk if f is None else f + fk
        return f

    def _internal_force(self, q: np.ndarray, params: dict[str, Any]) -> np.ndarray:
        """f_int(q) (..., n) in force units; params may be stacked along a leading batch axis."""
        pv = params["pv"]
        f = np.zeros(pv.shape[:-1] + (self.n,), dtype=np.result_type(q, pv))
        first = True
        for k in self.providing["internal_force"]:
            fk = k.internal_force(q, params)
            if fk is None:
                continue
            # the first term as it is, where its shape and dtype are the sum's (0 + x is x)
            f = fk if first and fk.shape == f.shape and fk.dtype == f.dtype else f + fk
            first = False
        return f

    def stack_parameters(self, params_list: list[dict[str, Any]]) -> dict[str, Any] | None:
        """Parameter arrays stacked along a leading batch axis, without the damping matrix: the
        outputs, which are evaluated in batches of many sets, do not need it (n² numbers per
        set), and :meth:`residual_batch_steps` stacks it for its own few sets."""
        keys = [k for k in ("pv", "mass") + sum((kind.stack_keys for kind in self.sets), ())
                if k in params_list[0]]
        return {k: np.stack([p[k] for p in params_list]) for k in keys}

    def residual_batch(self, t: float, s: StepState, params_list: list[dict[str, Any]]) -> np.ndarray:
        """F_R for several parameter sets at one state, vectorized: (n, B)."""
        return self.residual_batch_steps(np.array([t]), [s], params_list)[0]

    def residual_batch_steps(self, ts: np.ndarray, states: list[StepState],
                             params_list: list[dict[str, Any]]) -> np.ndarray:
        """F_R at K states (times ts, s) for several parameter sets, vectorized over both:
        (K, n, B).  Sparse models multiply the damping matrix of each set with all K states."""
        if self._stacked is None or self._stacked[0] is not params_list:   # keeps the list alive
            st = self.stack_parameters(params_list)
            assert st is not None  # structural models always stack
            if self.traits.has_damping:
                Ds = [p["D"] for p in params_list]
                st["D"] = Ds if self.traits.sparse else np.stack(Ds)
            from .step import batch_residuals
            self._stacked = (params_list, st, batch_residuals(self, params_list))
        st, compiled = self._stacked[1], self._stacked[2]
        if compiled is not None and all(s.q.dtype == np.float64 and s.qd.dtype == np.float64
                                        and s.qdd.dtype == np.float64 for s in states):
            # a sparse spring network: the compiled step's F_R of each state and set, with the loads
            # formed here as below (the same numbers as the arrays below, in one compiled call)
            return compiled(states, np.stack([self.external_force(t, st) for t in ts]))
        # states (K, 1, n) against parameter sets (B, ...): residuals (K, B, n)
        q, qd, qdd = (np.stack([getattr(s, f) for s in states])[:, None, :] for f in ("q", "qd", "qdd"))
        empty = np.zeros(q.shape[:-1] + (0,))
        R = self._inertia(st, StepState(q, qd, qdd, empty, empty, empty)) + self._internal_force(q, st)
        R = R - np.stack([self.external_force(t, st) for t in ts])
        if len(self.followers):
            R = R - np.stack([self.followers.force(t, self._ext(q[i]), st["pv"])[..., :self.n]
                              for i, t in enumerate(ts)])
        fv = self._velocity_forces(qd, st) if self.traits.has_damping else None
        fv = 0.0 if fv is None else fv
        if self.traits.has_damping and self.traits.sparse:
            # one sparse product per parameter set, over the K states: (K, B, n)
            R = R + np.stack([(D @ qd[:, 0, :].T).T for D in st["D"]], axis=1) + fv
        elif self.traits.has_damping:
            R = R + (st["D"] @ qd[..., None])[..., 0] + fv
        if self.traits.has_damping:
            R = R + self._corotated_damping_force(q, qd, st)
        return R.transpose(0, 2, 1)

    def structural_mass(self, params: dict[str, Any]) -> Any:
        """Sum of point masses, bar and beam masses ρAL (mass unit of the case), in the sets' order."""
        total: Any = None
        for k in self.sets:
            m = k.structural_mass(params)
            if m is not None:
                total = m if total is None else total + m
        return 0.0 if total is None else total

    def compiled_step(self, newton: bool, refactor: bool) -> Any:
        """The compiled Newton iteration of :mod:`.step`, where it serves this model."""
        from .step import step_factory
        return step_factory(self, newton, refactor)

    def check_state(self, t: float, s: StepState, params: dict[str, Any]) -> None:
        """Raise ModelError when an element leaves its range (e.g. :meth:`Beam3DSet.range_problem`)."""
        qe = None
        for k in self.providing["range_problem"]:
            qe = self._ext(s.q) if qe is None else qe
            why = k.range_problem(qe, params)
            if why:
                from ...errors import ModelError
                raise ModelError(f"t = {np.real(t):.6g} s: {why}")

    def dof_labels(self) -> list[str]:
        return list(self.dof_names)

    # ------------------------------------------------------------------ outputs
    def output(self, spec: Any, path: str, problems: ProblemCollector) -> Output | None:
        """Quantities: ``{dof: NAME|[NAMES], kind: displacement|velocity|acceleration}``,
        ``{node: NAME, kind: ...}`` (the node's free translation DOFs x, y (z)) or
        ``{element: NAME|[NAMES]|all, kind: ...}``: what each element kind reports (bars force,
        stress, strain and buckling, the ratio −N/P_E of the compressive axial force to the Euler
        load π²EI/(KL)², positive in compression, > 1 means buckled; beams force and stress;
        springs and dampers force)."""
        if not check_keys(spec, path, allowed("structural.quantity"), problems):
            return None
        kind = spec.get("kind", "displacement" if "dof" in spec or "node" in spec else "force")
        if sum(k in spec for k in ("dof", "node", "element")) > 1:
            problems.add(path, "give one of 'dof', 'node' or 'element'")
            return None
        if "node" in spec:
            free = self._node_dofs(spec["node"], path, problems)
            if free is None:
                return None
            spec = {"dof": free, "kind": kind}
        if "dof" in spec:
            return self._dof_output(spec["dof"], kind, path, problems)
        if "element" not in spec:
            problems.add(path, "expected 'dof' or 'element'")
            return None
        return self._element_output(spec["element"], kind, path, problems)

    def _node_dofs(self, node: Any, path: str, problems: ProblemCollector) -> list[str] | None:
        """The free translation DOFs of a node, or None with a problem listed."""
        if not isinstance(node, str) or node not in self.node_names:
            problems.add(f"{path}.node", f"unknown node {node!r}{did_you_mean(str(node), self.node_names)}")
            return None
        free = [f"{node}.{a}" for a in "xyz"[:self.dim] if f"{node}.{a}" in self.dof_names]
        if not free:
            problems.add(f"{path}.node", f"every translation of node {node!r} is fixed")
            return None
        return free

    def _dof_output(self, dofs: Any, kind: str, path: str, problems: ProblemCollector) -> Output | None:
        """Displacements, velocities or accelerations of named DOFs."""
        names = dofs if isinstance(dofs, list) else [dofs]
        if not names:
            problems.add(f"{path}.dof", "expected a dof name or a non-empty list of dof names, found []")
            return None
        field_of = {"displacement": "q", "velocity": "qd", "acceleration": "qdd"}
        if kind not in field_of:
            problems.add(f"{path}.kind", f"unknown kind {kind!r} for a dof{did_you_mean(kind, field_of)} "
                                         f"(known: {', '.join(field_of)})")
            return None
        idx = []
        for nm in names:
            if nm not in self.dof_names:
                problems.add(f"{path}.dof", f"unknown or fixed dof {nm!r}{did_you_mean(nm, self.dof_names)}")
            else:
                idx.append(self.dof_names.index(nm))
        if len(idx) != len(names):
            return None
        ia = np.array(idx)
        fld = field_of[kind]
        unit = ""  # the case's own unit system; a response may name it with 'unit'
        offset = {"q": 0, "qd": self.n, "qdd": 2 * self.n}[fld]
        return Output(lambda t, s, prm, _f=fld, _i=ia: getattr(s, _f)[_i],
                      tuple(f"{n}.{kind}" for n in names), unit, linear=True,
                      pattern=self._output_pattern([([], [i]) for i in ia], offset))

    def _element_output(self, names: Any, kind: str, path: str, problems: ProblemCollector) -> Output | None:
        """Quantities of named elements (``all``: the members, bars and beams; else the springs),
        grouped by their sets, in the sets' order."""
        if names == "all":
            members = [nm for k in self.sets if k.member for nm in k.names]
            names = members if members else [nm for k in self.sets if k.type == "spring" for nm in k.names]
        names = names if isinstance(names, list) else [names]
        owner = {nm: k for k in self.sets for nm in k.names}
        known = list(dict.fromkeys(knd for k in self.sets for knd in k.output_kinds))
        if kind not in known:
            problems.add(f"{path}.kind",
                         f"unknown kind {kind!r}{did_you_mean(kind, known)} (known: {', '.join(known)})")
            return None
        picked = self._pick(names, owner, kind, path, problems)
        if picked is None:
            return None
        if len({self.sets[j].member for j in picked}) > 1:
            problems.add(f"{path}.element", "mix springs and bars or beams in separate quantities")
            return None
        parts = [self.sets[j].output(np.array(idx), kind, path, problems) for j, idx in sorted(picked.items())]
        if any(p is None for p in parts):
            return None
        unit = "-" if kind in ("strain", "buckling") else ""
        reads = [self.sets[j].output_reads(np.array(idx), kind) for j, idx in sorted(picked.items())]
        pattern = None if any(r is None for r in reads) else \
            self._output_pattern([row for r in reads if r is not None for row in r])
        if len(parts) == 1:
            return Output(parts[0][0], parts[0][1], unit, batched=True, autonomous=True, pattern=pattern)

        def joined(t: float, s: StepState, prm: dict[str, Any]) -> np.ndarray:
            return np.concatenate([fn(t, s, prm) for fn, _ in parts], axis=-1)
        return Output(joined, sum((lab for _, lab in parts), ()), unit, batched=True, autonomous=True,
                      pattern=pattern)

    def _output_pattern(self, rows: list[tuple[Any, Any]], offset: int = 0) -> Callable[[], OutputPattern]:
        """The pattern of an output whose row i reads rows[i] = (parameter indices, DOFs): its
        free DOFs (at ``offset`` in the flat state: 0 for q) and the design variables whose
        expressions set those parameters (formed when called: the design is known by then)."""
        def pattern() -> OutputPattern:
            design_of: dict[int, list[int]] = {}
            for j, entries in enumerate(self.table.design_dependents()):
                for i in entries:
                    design_of.setdefault(i, []).append(j)
            state: list[tuple[int, int]] = []
            design: list[tuple[int, int]] = []
            for row, (params, dofs) in enumerate(rows):
                state += [(row, offset + int(d)) for d in np.ravel(dofs) if d < self.n]
                design += [(row, j) for j in sorted({j for i in np.ravel(params) if i >= 0
                                                     for j in design_of.get(int(i), ())})]
            s_rows, s_cols = np.array(state, int).reshape(-1, 2).T
            d_rows, d_cols = np.array(design, int).reshape(-1, 2).T
            return OutputPattern(s_rows, s_cols, d_rows, d_cols)
        return pattern

    def _pick(self, names: list[Any], owner: dict[str, Any], kind: str, path: str,
              problems: ProblemCollector) -> dict[int, list[int]] | None:
        """Element indices per set position of the named elements that report ``kind``; None
        with one problem per unknown name and per kind of element that does not report it."""
        picked: dict[int, list[int]] = {}        # set position -> element indices
        refused: dict[str, list[str]] = {}       # one problem per kind of element, naming them all
        for nm in names:
            k = owner.get(nm)
            if k is None:
                problems.add(f"{path}.element", f"unknown element {nm!r}{did_you_mean(nm, list(owner))}")
            elif kind in k.output_kinds:
                picked.setdefault(self.sets.index(k), []).append(k.names.index(nm))
            else:
                refused.setdefault(k.refusal(kind), []).append(nm)
        for what, which in refused.items():
            problems.add(f"{path}.kind", f"{what}, not {kind!r}: {', '.join(which[:5])}"
                                         f"{f' and {len(which) - 5} more' if len(which) > 5 else ''}")
        return picked if sum(len(v) for v in picked.values()) == len(names) else None

    # ------------------------------------------------------------------ run-time diagnostics
    def describe_equation(self, k: int) -> str:
        """DOF k and the elements and loads acting on it, by YAML path and name."""
        if not 0 <= k < self.n:
            return Model.describe_equation(self, k)  # type: ignore[arg-type]
        acting = [entry for entry, dofs in self.equation_sources if k in dofs]
        return f"DOF '{self.dof_names[k]}'" + (f" (acted on by {', '.join(acting)})" if acting else "")

    def displacement_scale(self, params: dict[str, Any], lin: Linearization | None) -> float:
        """The larger of the bar nodes' coordinates and the static deflections |f_amp|/K_dd of the
        loads' amplitudes on their DOFs (K: the tangent stiffness at t0)."""
        pv = np.real(params["pv"])
        bar_X = self.bar_X
        scale = float(np.max(np.abs(pv[bar_X]))) if np.size(bar_X) else 0.0
        if lin is None or lin.R_q is None or not self.loads:
            return scale
        diag = np.real(lin.R_q.diagonal())
        for dof, amp, _ in self.loads:
            if dof < self.n and diag[dof] > 0:
                scale = max(scale, abs(float(pv[amp])) / float(diag[dof]))
        return scale
