r"""Structural dynamics models: point masses, springs, dampers and truss bars.

Residual (method.md §1) with z = q̈:

.. math:: F_R = M\ddot q + D\dot q + f_{int}(q) - f_{ext}(t) = 0

* ``M`` is diagonal (point masses and lumped bar masses, ρAL/2 per node and direction);
* springs between two DOFs (or a DOF and ground) carry f = k₁δ + k₂δ² + k₃δ³ with
  δ = u_a − u_b (cubic hardening for k₃ > 0, softening for k₃ < 0);
* viscous dampers f = c δ̇, and Rayleigh damping α M + β K₀ (K₀: the stiffness at q = 0) whose
  stiffness part acts, for bars and co-rotational beams, on the elements' deformation rates in
  their turning frames (:mod:`.corotated_damping`);
* bars (2D or 3D truss elements) are geometrically nonlinear: total Lagrangian with the
  Green–Lagrange strain ε = (ℓ² − L²)/(2L²), axial force N = E A ε, nodal forces
  ± N d/L (d the current bar vector); the tangent is (EA/L³) d dᵀ + (N/L) I per node pair.

Elements of one kind are stored as arrays and evaluated together.  Fixed DOFs (supports,
``ground``) map to an extra slot that always holds zero.  All code is complex-safe.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from .base import Model, StepState, Traits
from .parameters import ParameterTable
from .beams import BeamSet
from .beams3d import Beam3DSet
from .corotated_damping import CorotatedDamping, DampedKind
from .dampers import NonlinearDampers
from .follower import FollowerLoads
from .sparse_assembly import PatternAssembly, RightProduct, UnionCache
from .spring_law import spring_law
from .structural_diagnostics import StructuralDiagnostics
from .structural_matrices import StructuralMatrices
from .structural_outputs import StructuralOutputs
from .timefunctions import TimeFunction

GROUND = "ground"
AXES = ("x", "y", "z")
# DOFs above which ``linear_algebra: auto`` chooses the sparse path: the measured break-even on
# the Duffing chain (dense and sparse equal at 100 DOFs, sparse 8 % ahead at 120 and 27 % at
# 200) and about the same on the tower frame (144 DOFs: equal; BENCHMARKS.md)
SPARSE_THRESHOLD = 100


@dataclass
class _Group:
    """Elements of one kind: connectivity (n_e, k) into the extended DOF vector and parameters."""

    names: list[str] = field(default_factory=list)
    dofs: list[list[int]] = field(default_factory=list)
    params: dict[str, list[int]] = field(default_factory=dict)

    def add(self, name: str, dofs: list[int], **params: int) -> None:
        self.names.append(name)
        self.dofs.append(dofs)
        for k, v in params.items():
            self.params.setdefault(k, []).append(v)

    def freeze(self, width: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        idx = np.array(self.dofs, dtype=int).reshape(-1, width)
        return idx, {k: np.array(v, dtype=int) for k, v in self.params.items()}


class StructuralModel(StructuralMatrices, StructuralOutputs, StructuralDiagnostics, Model):
    """Assembled structural model; built from a case by :func:`build_structural`."""

    def __init__(self, *, dof_names: list[str], table: ParameterTable, mass_terms: list[tuple[int, int]],
                 springs: _Group, dampers: _Group, bars: _Group, dim: int, node_coords: dict[str, list[int]],
                 bar_nodes: list[tuple[str, str]], loads: list[tuple[int, int, TimeFunction]],
                 initial: tuple[list[tuple[int, int]], list[tuple[int, int]]],
                 rayleigh: tuple[int, int] | None, sparse: bool | None, spring_nonlinear: bool,
                 beams: BeamSet | None = None, nl_dampers: NonlinearDampers | None = None,
                 followers: FollowerLoads | None = None, frames: Beam3DSet | None = None,
                 rayleigh_corotated: bool = True):
        self.dof_names = dof_names
        self.table = table
        n = len(dof_names)
        self.n = n
        self.mass_dof = np.array([d for d, _ in mass_terms], dtype=int)
        self.mass_idx = np.array([p for _, p in mass_terms], dtype=int)
        self.spring_dofs, sp_par = springs.freeze(2)
        self.spring_names = springs.names
        self.k1, self.k2, self.k3 = (sp_par.get(k, np.zeros(0, int)) for k in ("k1", "k2", "k3"))
        self.damper_dofs, dp_par = dampers.freeze(2)
        self.damper_names = dampers.names
        self.c = dp_par.get("c", np.zeros(0, int))
        self.dim = dim
        self.node_names = list(node_coords)
        self.node_coords = node_coords     # name -> parameter indices of its coordinates (drawing)
        self.bar_dofs, bar_par = bars.freeze(2 * dim)
        self.bar_names = bars.names
        self.bar_A, self.bar_E, self.bar_rho = (bar_par.get(k, np.zeros(0, int)) for k in ("A", "E", "rho"))
        # second moment of area and effective-length factor (buckling); -1: not given
        self.bar_I, self.bar_K = (bar_par.get(k, np.zeros(0, int)) for k in ("I", "K"))
        # undeformed bar vectors from nodal coordinates (parameter indices, may be design-dependent)
        self.bar_X = np.array([[node_coords[b] + [] for b in pair] for pair in bar_nodes], dtype=int) \
            .reshape(-1, 2, dim) if bar_nodes else np.zeros((0, 2, dim), int)
        self.loads = loads
        self.init_q, self.init_qd = initial
        self.rayleigh = rayleigh
        self.beams = beams if beams is not None else BeamSet()
        self.beams.freeze()
        # consistent-mass beams: a mass M(q) that turns with them (inertia forces per element)
        self.rotating_mass = bool(self.beams.is_consistent.any())
        # space-frame beams (dim 3, small rotations): constant K and, when consistent, constant M
        self.frames = frames if frames is not None else Beam3DSet()
        self.frames.freeze()
        self.frame_mass = bool(self.frames.is_consistent.any())
        self.nl_dampers = nl_dampers if nl_dampers is not None else NonlinearDampers()
        self.nl_dampers.freeze()
        self.followers = followers if followers is not None else FollowerLoads()
        nonlinear = bool(len(self.bar_names)) or spring_nonlinear or bool(len(self.beams)) \
            or bool(len(self.nl_dampers)) or bool(len(self.followers)) or bool(self.frames.is_corot.any())
        has_damping = bool(len(self.damper_names)) or rayleigh is not None or bool(len(self.nl_dampers)) \
            or self.rotating_mass       # (the turning mass's inertia forces depend on q̇)
        use_sparse = (n > SPARSE_THRESHOLD) if sparse is None else sparse
        self.traits = Traits(n_q=n, linear=not nonlinear, constant_matrices=not nonlinear,
                             has_damping=has_damping, sparse=use_sparse)
        # element forces -> nodal forces as one matrix product (works with a leading batch axis)
        self._spring_scatter = self._scatter(self.spring_dofs, np.array([1.0, -1.0]), per_element=True)
        self._spring_elongation = self._spring_scatter.transposed()  # (n, n_s): δ = q @ it
        self._bar_scatter = self._scatter(self.bar_dofs, np.ones(2 * dim), per_element=False)
        self._beam_scatter = self._scatter(self.beams.idx, np.ones(6), per_element=False)
        self._inertia_scatter = self._scatter(self.beams.idx[self.beams.is_consistent], np.ones(6), per_element=False)
        self._frame_scatter = self._scatter(self.frames.idx, np.ones(12), per_element=False)
        self._frame_inertia_scatter = self._scatter(self.frames.idx[self.frames.is_consistent], np.ones(12),
                                                    per_element=False)
        self._nl_damper_scatter = self._scatter(self.nl_dampers.idx, np.array([1.0, -1.0]), per_element=True)
        # Rayleigh's β K on the deformation rates of the elements that turn (K₀ keeps the others)
        corot_frames = self.frames.idx[self.frames.is_corot]
        kinds = [DampedKind(self.bar_dofs, self._bar_scatter, self._bar_deformations),
                 DampedKind(self.beams.idx, self._beam_scatter, self.beams.deformations),
                 DampedKind(corot_frames, self._scatter(corot_frames, np.ones(12), per_element=False),
                            self.frames.deformations)]
        self.corotated_damping = CorotatedDamping(kinds if rayleigh is not None and rayleigh_corotated else [],
                                                  rayleigh[1] if rayleigh is not None else -1, n)
        self._stacked: tuple[list[dict[str, Any]], dict[str, Any]] | None = None
        self._elongation_of: dict[tuple[int, ...], Any] = {}     # columns of selected springs
        # the spring state of the last residual: Newton linearizes at the state it has just
        # evaluated, and the tangent needs the same products (kept with q and params themselves)
        self._last_springs: tuple[Any, Any, np.ndarray, np.ndarray] | None = None
        self._last_loads: tuple[float, Any, np.ndarray] | None = None       # (t, params, f_ext)
        self._assembly_plans: dict[str, tuple[Any, ...]] = {}   # per _assemble site: kept indices
        self._patterns: dict[str, PatternAssembly] = {}          # sparse models: per _assemble site
        self._sums: dict[str, UnionCache] = {}                   # sparse models: per _add site
        self._unions = UnionCache()                              # sparse iteration matrices
        self._diag_mass: tuple[np.ndarray, Any] | None = None    # (mass vector, its sparse diag(M))
        self._pattern_kept: tuple[int, np.ndarray] | None = None  # dense models: see _dense_pattern

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
        out: dict[str, Any] = {"pv": pv}
        mass = np.zeros(self.n + 1, dtype=pv.dtype)
        np.add.at(mass, self.mass_dof, pv[self.mass_idx])
        if len(self.bar_names):
            X = pv[self.bar_X]                       # (n_e, 2, dim)
            D0 = X[:, 1] - X[:, 0]
            L0 = np.sqrt(np.sum(D0 * D0, axis=1))
            A, E, rho = pv[self.bar_A], pv[self.bar_E], pv[self.bar_rho]
            half = 0.5 * rho * A * L0
            lumped = np.repeat(half[:, None], 2 * self.dim, axis=1)
            np.add.at(mass, self.bar_dofs, lumped)
            out.update(D0=D0, L0=L0, EA=E * A, E=E, A=A, bar_mass=2 * half)
            # Euler load π²EI/(KL)² (force unit); infinite for a bar without 'inertia' (the
            # buckling output refuses such bars)
            KL = pv[self.bar_K] * L0
            has = self.bar_I >= 0
            inertia = np.where(has, pv[np.maximum(self.bar_I, 0)], 1.0)
            out["P_euler"] = np.where(has, np.pi ** 2 * E * inertia / (KL * KL), np.inf)
        if len(self.beams):
            self.beams.parameters(pv, out)
            idx, vals = self.beams.lumped_mass(out)
            np.add.at(mass, idx, vals)
        if len(self.frames):
            self.frames.parameters(pv, out)
            idx, vals = self.frames.lumped_mass(out)
            np.add.at(mass, idx, vals)
        out["mass"] = mass[:self.n]
        if self.rotating_mass or self.frame_mass:
            out["M0"] = self._mass_matrix(out, pv.dtype)
        if len(self.spring_names):
            out.update(k1=pv[self.k1], k2=pv[self.k2], k3=pv[self.k3])
        if self.rayleigh is not None:
            # the co-rotated elements' β K acts on their deformation rates instead (residual)
            out["K0"] = self._tangent(np.zeros(self.n, dtype=pv.dtype), out, corotated=not self.corotated_damping)
        if self.traits.has_damping:
            # viscous and Rayleigh damping depend on the design only: assemble once per design
            out["D"] = D = self._damping(out, pv.dtype)
            if sp.issparse(D):
                D.data.flags.writeable = False      # constant for the run: kept scaled per step size
        return out

    def _inertia(self, params: dict[str, Any], s: Any) -> np.ndarray:
        """Inertia forces (..., n): M q̈ of the diagonal masses plus the consistent beams'
        M(q)q̈ + velocity terms; params and state leaves may carry leading batch axes."""
        f = params["mass"] * s.qdd
        if self.rotating_mass:
            fe = self.beams.inertia(self._ext(s.q), self._ext(s.qd), self._ext(s.qdd), params)
            f = f + self._inertia_scatter(fe.reshape(fe.shape[:-2] + (-1,)))
        if self.frame_mass:
            fe = self.frames.inertia(self._ext(s.qdd), params)
            f = f + self._frame_inertia_scatter(fe.reshape(fe.shape[:-2] + (-1,)))
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

    # ------------------------------------------------------------------ element kernels
    def _ext(self, v: np.ndarray) -> np.ndarray:
        """v with a trailing zero entry: the slot of fixed DOFs and ground."""
        return np.concatenate([v, np.zeros(v.shape[:-1] + (1,), dtype=v.dtype)], axis=-1)

    def _spring_state(self, q: np.ndarray, params: dict[str, Any], springs: np.ndarray | None = None,
                      tangent: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Spring forces f (..., n_s) and, with ``tangent``, the tangents df/dδ (else None) of all
        springs or of the indices ``springs``; params may carry a leading batch axis."""
        keep = springs is None and tangent
        if keep:
            last = self._last_springs
            if last is not None and last[0] is q and last[1] is params:
                return last[2], last[3]
        if springs is None:
            elongation = self._spring_elongation
        else:
            key = tuple(springs.tolist())
            if key not in self._elongation_of:
                self._elongation_of[key] = self._spring_elongation.columns(springs)
            elongation = self._elongation_of[key]
        delta = elongation(q)                        # δ = u_a − u_b for every spring

        def pick(key: str) -> np.ndarray:
            return params[key] if springs is None else params[key][..., springs]
        k1 = pick("k1")
        if self.traits.linear:
            return k1 * delta, (k1 + 0 * delta if tangent else None)
        f, kt = spring_law(delta, k1, pick("k2"), pick("k3"))
        if not tangent:
            return f, None
        if keep:
            f.flags.writeable = kt.flags.writeable = False     # kept: never changed in place
            self._last_springs = (q, params, f, kt)
        return f, kt

    def _bar_state(self, q: np.ndarray, params: dict[str, Any]) -> dict[str, np.ndarray]:
        """Bar vectors d (..., n_e, dim), Green–Lagrange strains and axial forces (..., n_e)."""
        qe = self._ext(q)
        U = qe[..., self.bar_dofs].reshape(qe.shape[:-1] + (-1, 2, self.dim))
        du = U[..., 1, :] - U[..., 0, :]
        D0 = params["D0"]
        d = D0 + du
        L0 = params["L0"]
        # (ℓ² − L²) written as 2 D0·Δu + Δu·Δu: no cancellation for small displacements
        strain = (2.0 * np.sum(D0 * du, axis=-1) + np.sum(du * du, axis=-1)) / (2 * L0 * L0)
        N = params["EA"] * strain
        return {"d": d, "strain": strain, "N": N}

    def external_force(self, t: float, params: dict[str, Any]) -> np.ndarray:
        """f_ext(t) (..., n) in force units; params may be stacked along a leading batch axis.
        The loads of the last (t, params) are kept (read-only): every Newton iteration of a
        step evaluates them at the same time."""
        last = self._last_loads
        if last is not None and last[0] == t and last[1] is params:
            return last[2]
        pv = params["pv"]
        f = np.zeros(pv.shape[:-1] + (self.n + 1,), dtype=pv.dtype)
        for dof, amp, fn in self.loads:
            f[..., dof] += pv[..., amp] * fn.value(t, pv)
        f = f[..., :self.n]
        f.flags.writeable = False
        self._last_loads = (t, params, f)
        return f

    # ------------------------------------------------------------------ residual contract
    def residual(self, t: float, s: StepState, params: dict[str, Any]) -> np.ndarray:
        f_int = self._internal_force(s.q, params)
        R = self._inertia(params, s) + f_int - self.external_force(t, params)
        if len(self.followers):
            R = R - self.followers.force(t, self._ext(s.q), params["pv"])[..., :self.n]
        if self.traits.has_damping:
            R = R + params["D"] @ s.qd
            if len(self.nl_dampers):
                R = R + self._nl_damper_force(s.qd, params)
            R = R + self._corotated_damping_force(s.q, s.qd, params)
        return R

    def _corotated_damping_force(self, q: np.ndarray, qd: np.ndarray, params: dict[str, Any]) -> Any:
        """Nodal forces (..., n) of β K on the elements' deformation rates (0 where there is none)."""
        if not self.corotated_damping.active(params):
            return 0.0
        return self.corotated_damping.force(self._ext(q), self._ext(qd), params)

    def _bar_deformations(self, qe: np.ndarray, params: dict[str, Any], hessian: bool = False
                          ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """(B, H, D) of the bars' Green–Lagrange strains ε at qe (..., n+1): B = ∂ε/∂u =
        [−d, d]/L² (..., n_e, 1, 2·dim), H = [[I, −I], [−I, I]]/L² and D = EA·L (the energy
        ½ EA L ε²), for :mod:`.corotated_damping`."""
        bs = self._bar_state(qe[..., :self.n], params)
        L2 = (params["L0"] ** 2)[..., None]
        B = (np.concatenate([-bs["d"], bs["d"]], axis=-1) / L2)[..., None, :]
        H = None
        if hessian:
            eye = np.eye(self.dim)
            H = np.block([[eye, -eye], [-eye, eye]])[None, None] / L2[..., None, None]
        return B, H, (params["EA"] * params["L0"])[..., None, None]

    def _nl_damper_force(self, qd: np.ndarray, params: dict[str, Any]) -> Any:
        """Nodal forces (..., n) of the nonlinear viscous dampers (0 without any)."""
        if not len(self.nl_dampers):
            return 0.0
        F, _ = self.nl_dampers.force(self.nl_dampers.velocity(self._ext(qd)), params["pv"])
        return self._nl_damper_scatter(F)

    def _internal_force(self, q: np.ndarray, params: dict[str, Any]) -> np.ndarray:
        """f_int(q) (..., n) in force units; params may be stacked along a leading batch axis."""
        pv = params["pv"]
        f = np.zeros(pv.shape[:-1] + (self.n,), dtype=np.result_type(q, pv))
        if len(self.spring_names):
            # a single state: the tangent at it is asked for next (Newton), batches need none
            fs, _ = self._spring_state(q, params, tangent=q.ndim == 1)
            fs = self._spring_scatter(fs)
            # the first term as it is, where its shape and dtype are the sum's (0 + x is x)
            f = fs if fs.shape == f.shape and fs.dtype == f.dtype else f + fs
        if len(self.bar_names):
            bs = self._bar_state(q, params)
            fe = (bs["N"] / params["L0"])[..., None] * bs["d"]
            flat = np.concatenate([-fe, fe], axis=-1).reshape(fe.shape[:-2] + (-1,))
            f = f + self._bar_scatter(flat)
        if len(self.beams):
            fb = self.beams.forces(self._ext(q), params)
            f = f + self._beam_scatter(fb.reshape(fb.shape[:-2] + (-1,)))
        if len(self.frames):
            fb = self.frames.forces(self._ext(q), params)
            f = f + self._frame_scatter(fb.reshape(fb.shape[:-2] + (-1,)))
        return f

    def stack_parameters(self, params_list: list[dict[str, Any]]) -> dict[str, Any] | None:
        """Parameter arrays stacked along a leading batch axis, without the damping matrix: the
        outputs, which are evaluated in batches of many sets, do not need it (n² numbers per
        set), and :meth:`residual_batch_steps` stacks it for its own few sets."""
        keys = [k for k in ("pv", "mass", "D0", "L0", "EA", "E", "k1", "k2", "k3", "P_euler")
                + BeamSet.STACK_KEYS + Beam3DSet.STACK_KEYS if k in params_list[0]]
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
            self._stacked = (params_list, st)
        st = self._stacked[1]
        # states (K, 1, n) against parameter sets (B, ...): residuals (K, B, n)
        q, qd, qdd = (np.stack([getattr(s, f) for s in states])[:, None, :] for f in ("q", "qd", "qdd"))
        empty = np.zeros(q.shape[:-1] + (0,))
        R = self._inertia(st, StepState(q, qd, qdd, empty, empty, empty)) + self._internal_force(q, st)
        R = R - np.stack([self.external_force(t, st) for t in ts])
        if len(self.followers):
            R = R - np.stack([self.followers.force(t, self._ext(q[i]), st["pv"])[..., :self.n]
                              for i, t in enumerate(ts)])
        if self.traits.has_damping and self.traits.sparse:
            # one sparse product per parameter set, over the K states: (K, B, n)
            R = R + np.stack([(D @ qd[:, 0, :].T).T for D in st["D"]], axis=1) + self._nl_damper_force(qd, st)
        elif self.traits.has_damping:
            R = R + (st["D"] @ qd[..., None])[..., 0] + self._nl_damper_force(qd, st)
        if self.traits.has_damping:
            R = R + self._corotated_damping_force(q, qd, st)
        return R.transpose(0, 2, 1)

    def structural_mass(self, params: dict[str, Any]) -> Any:
        """Sum of point masses, bar and beam masses ρAL (mass unit of the case); a mass on a
        node counts once, not once per direction."""
        total = np.sum(params["pv"][np.unique(self.mass_idx)]) if len(self.mass_idx) else 0.0
        if len(self.bar_names):
            total = total + np.sum(params["bar_mass"])
        if len(self.beams):
            total = total + np.sum(params["beam_mass"])
        if len(self.frames):
            total = total + np.sum(params["frame_mass"])
        return total

    def compiled_step(self, newton: bool, refactor: bool) -> Any:
        """The compiled Newton iteration of :mod:`.structural_step`, where it serves this model."""
        from .structural_step import step_factory
        return step_factory(self, newton, refactor)

    def check_state(self, t: float, s: StepState, params: dict[str, Any]) -> None:
        """Raise ModelError when a co-rotational 3D beam leaves its range (:meth:`Beam3DSet.range_problem`)."""
        why = self.frames.range_problem(self._ext(s.q), params) if len(self.frames) else None
        if why:
            from ..errors import ModelError
            raise ModelError(f"t = {np.real(t):.6g} s: {why}")

    def dof_labels(self) -> list[str]:
        return list(self.dof_names)
