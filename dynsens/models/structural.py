r"""Structural dynamics models: point masses, springs, dampers and truss bars.

Residual (method.md §1) with z = q̈:

.. math:: F_R = M\ddot q + D\dot q + f_{int}(q) - f_{ext}(t) = 0

* ``M`` is diagonal (point masses and lumped bar masses, ρAL/2 per node and direction);
* springs between two DOFs (or a DOF and ground) carry f = k₁δ + k₂δ² + k₃δ³ with
  δ = u_a − u_b (cubic hardening for k₃ > 0, softening for k₃ < 0);
* viscous dampers f = c δ̇, and Rayleigh damping D_R = α M + β K₀ (K₀: the stiffness at q = 0);
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

from ..errors import ProblemCollector
from ..case_keys import allowed
from ._keys import check_keys, did_you_mean
from .base import Linearization, Model, Output, ParameterTable, StepState, Traits
from .registry import register
from .sparse_assembly import PatternAssembly, SparseLinearization, UnionCache
from .timefunctions import TimeFunction, build_time_function

GROUND = "ground"
AXES = ("x", "y", "z")
SPARSE_THRESHOLD = 200  # DOFs above which the sparse (splu) path is chosen


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


class StructuralModel(Model):
    """Assembled structural model; built from a case by :func:`build_structural`."""

    def __init__(self, *, dof_names: list[str], table: ParameterTable, mass_terms: list[tuple[int, int]],
                 springs: _Group, dampers: _Group, bars: _Group, dim: int, node_coords: dict[str, list[int]],
                 bar_nodes: list[tuple[str, str]], loads: list[tuple[int, int, TimeFunction]],
                 initial: tuple[list[tuple[int, int]], list[tuple[int, int]]],
                 rayleigh: tuple[int, int] | None, sparse: bool | None, spring_nonlinear: bool):
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
        self.bar_dofs, bar_par = bars.freeze(2 * dim)
        self.bar_names = bars.names
        self.bar_A, self.bar_E, self.bar_rho = (bar_par.get(k, np.zeros(0, int)) for k in ("A", "E", "rho"))
        # undeformed bar vectors from nodal coordinates (parameter indices, may be design-dependent)
        self.bar_X = np.array([[node_coords[b] + [] for b in pair] for pair in bar_nodes], dtype=int) \
            .reshape(-1, 2, dim) if bar_nodes else np.zeros((0, 2, dim), int)
        self.loads = loads
        self.init_q, self.init_qd = initial
        self.rayleigh = rayleigh
        nonlinear = bool(len(self.bar_names)) or spring_nonlinear
        has_damping = bool(len(self.damper_names)) or rayleigh is not None
        use_sparse = (n > SPARSE_THRESHOLD) if sparse is None else sparse
        self.traits = Traits(n_q=n, linear=not nonlinear, constant_matrices=not nonlinear,
                             has_damping=has_damping, sparse=use_sparse)
        # element forces -> nodal forces as one matrix product (works with a leading batch axis)
        self._spring_scatter = self._scatter(self.spring_dofs, np.array([1.0, -1.0]), per_element=True)
        self._spring_elongation = self._spring_scatter.T  # (n, n_s): δ = q @ it
        self._bar_scatter = self._scatter(self.bar_dofs, np.ones(2 * dim), per_element=False)
        self._stacked: tuple[list[dict[str, Any]], dict[str, Any]] | None = None
        self._elongation_of: dict[tuple[int, ...], Any] = {}     # columns of selected springs
        self._assembly_plans: dict[str, tuple[Any, ...]] = {}   # per _assemble site: kept indices
        self._patterns: dict[str, PatternAssembly] = {}          # sparse models: per site
        self._unions = UnionCache()                              # sparse iteration matrices
        self._mass_matrix: tuple[np.ndarray, Any] | None = None  # (mass vector, its sparse M)

    def _scatter(self, dofs: np.ndarray, signs: np.ndarray, per_element: bool) -> Any:
        """Scatter matrix Gᵀ so that nodal forces = element values @ Gᵀ.

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
        return G.T.tocsr() if self.traits.sparse else G.toarray().T

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
        out["mass"] = mass[:self.n]
        if len(self.spring_names):
            out.update(k1=pv[self.k1], k2=pv[self.k2], k3=pv[self.k3])
        if self.rayleigh is not None:
            out["K0"] = self._tangent(np.zeros(self.n, dtype=pv.dtype), out)
        if self.traits.has_damping:
            # viscous and Rayleigh damping depend on the design only: assemble once per design
            out["D"] = self._damping(out, pv.dtype)
        return out

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

    def _spring_state(self, q: np.ndarray, params: dict[str, Any], springs: np.ndarray | None = None
                      ) -> tuple[np.ndarray, np.ndarray]:
        """Spring forces f (..., n_s) and tangents df/dδ of all springs or of the indices
        ``springs``; params may carry a leading batch axis."""
        if springs is None:
            elongation = self._spring_elongation
        else:
            key = tuple(springs.tolist())
            if key not in self._elongation_of:
                self._elongation_of[key] = self._spring_elongation[:, springs]
            elongation = self._elongation_of[key]
        delta = _times(q, elongation)                # δ = u_a − u_b for every spring

        def pick(key: str) -> np.ndarray:
            return params[key] if springs is None else params[key][..., springs]
        k1 = pick("k1")
        f = k1 * delta
        kt = k1 + 0 * delta
        if self.traits.linear:
            return f, kt
        k2, k3 = pick("k2"), pick("k3")
        f = f + k2 * delta ** 2 + k3 * delta ** 3
        kt = kt + 2 * k2 * delta + 3 * k3 * delta ** 2
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

    def _tangent(self, q: np.ndarray, params: dict[str, Any]) -> Any:
        """Tangent stiffness K_t = ∂f_int/∂q (dense or sparse)."""
        pv = params["pv"]
        rows, cols, vals = [], [], []
        if len(self.spring_names):
            _, kt = self._spring_state(q, params)
            a, b = self.spring_dofs[:, 0], self.spring_dofs[:, 1]
            rows += [a, b, a, b]
            cols += [a, b, b, a]
            vals += [kt, kt, -kt, -kt]
        if len(self.bar_names):
            bs = self._bar_state(q, params)
            d, N, L0, EA = bs["d"], bs["N"], params["L0"], params["EA"]
            k_node = (EA / L0 ** 3)[:, None, None] * d[:, :, None] * d[:, None, :] \
                + (N / L0)[:, None, None] * np.eye(self.dim)
            ke = np.block([[k_node, -k_node], [-k_node, k_node]])
            idx = self.bar_dofs
            rows.append(np.repeat(idx, 2 * self.dim, axis=1).ravel())
            cols.append(np.tile(idx, (1, 2 * self.dim)).ravel())
            vals.append(ke.reshape(len(idx), -1).ravel())
        return self._assemble("tangent", rows, cols, vals, np.result_type(q, pv))

    def _damping(self, params: dict[str, Any], dtype: Any) -> Any:
        rows, cols, vals = [], [], []
        if len(self.damper_names):
            c = params["pv"][self.c]
            a, b = self.damper_dofs[:, 0], self.damper_dofs[:, 1]
            rows += [a, b, a, b]
            cols += [a, b, b, a]
            vals += [c, c, -c, -c]
        D = self._assemble("damping", rows, cols, vals, np.result_type(dtype, params["pv"]))
        if self.rayleigh is not None:
            pv = params["pv"]
            alpha, beta = pv[self.rayleigh[0]], pv[self.rayleigh[1]]
            Mdiag = params["mass"]
            D = D + alpha * (sp.diags(Mdiag) if self.traits.sparse else np.diag(Mdiag)) + beta * params["K0"]
        return D

    def _assemble(self, site: str, rows: list, cols: list, vals: list, dtype: Any) -> Any:
        """Sum the element entries vals at (rows, cols) into an (n, n) matrix; index n is the
        slot of fixed DOFs and ground, dropped.  The indices of a call ``site`` are the same
        every call (element DOFs), so their filtered flat positions are kept per site."""
        n = self.n
        if not rows:
            return sp.csc_matrix((n, n), dtype=dtype) if self.traits.sparse else np.zeros((n, n), dtype)
        plan = self._assembly_plans.get(site)
        if plan is None:
            r = np.concatenate([np.ravel(x) for x in rows])
            c = np.concatenate([np.ravel(x) for x in cols])
            keep = (r < n) & (c < n)
            plan = self._assembly_plans[site] = (keep, r[keep], c[keep], r[keep] * n + c[keep])
        keep, r, c, flat = plan
        v = np.concatenate([np.ravel(x) for x in vals])[keep]
        if self.traits.sparse:
            if site not in self._patterns:
                self._patterns[site] = PatternAssembly(n, r, c)
            return self._patterns[site].matrix(v, dtype)
        # bincount sums repeated positions (as np.add.at) at a fraction of its cost
        K = np.bincount(flat, v.real, n * n)
        if np.iscomplexobj(v) or np.dtype(dtype).kind == "c":
            K = K + 1j * np.bincount(flat, v.imag, n * n)
        return K.reshape(n, n)

    def external_force(self, t: float, params: dict[str, Any]) -> np.ndarray:
        """f_ext(t) (..., n) in force units; params may be stacked along a leading batch axis."""
        pv = params["pv"]
        f = np.zeros(pv.shape[:-1] + (self.n + 1,), dtype=pv.dtype)
        for dof, amp, fn in self.loads:
            f[..., dof] += pv[..., amp] * fn.value(t, pv)
        return f[..., :self.n]

    # ------------------------------------------------------------------ residual contract
    def residual(self, t: float, s: StepState, params: dict[str, Any]) -> np.ndarray:
        f_int = self._internal_force(s.q, params)
        R = params["mass"] * s.qdd + f_int - self.external_force(t, params)
        if self.traits.has_damping:
            R = R + params["D"] @ s.qd
        return R

    def _internal_force(self, q: np.ndarray, params: dict[str, Any]) -> np.ndarray:
        """f_int(q) (..., n) in force units; params may be stacked along a leading batch axis."""
        pv = params["pv"]
        f = np.zeros(pv.shape[:-1] + (self.n,), dtype=np.result_type(q, pv))
        if len(self.spring_names):
            fs, _ = self._spring_state(q, params)
            f = f + _times(fs, self._spring_scatter)
        if len(self.bar_names):
            bs = self._bar_state(q, params)
            fe = (bs["N"] / params["L0"])[..., None] * bs["d"]
            flat = np.concatenate([-fe, fe], axis=-1).reshape(fe.shape[:-2] + (-1,))
            f = f + _times(flat, self._bar_scatter)
        return f

    def stack_parameters(self, params_list: list[dict[str, Any]]) -> dict[str, Any] | None:
        """Parameter arrays stacked along a leading batch axis, without the damping matrix: the
        outputs, which are evaluated in batches of many sets, do not need it (n² numbers per
        set), and :meth:`residual_batch_steps` stacks it for its own few sets."""
        keys = [k for k in ("pv", "mass", "D0", "L0", "EA", "E", "k1", "k2", "k3") if k in params_list[0]]
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
        R = st["mass"] * qdd + self._internal_force(q, st)
        R = R - np.stack([self.external_force(t, st) for t in ts])
        if self.traits.has_damping and self.traits.sparse:
            # one sparse product per parameter set, over the K states: (K, B, n)
            R = R + np.stack([(D @ qd[:, 0, :].T).T for D in st["D"]], axis=1)
        elif self.traits.has_damping:
            R = R + (st["D"] @ qd[..., None])[..., 0]
        return R.transpose(0, 2, 1)

    def design_pattern(self) -> list[np.ndarray]:
        """Rows of the residual each design variable reaches through the elements whose
        parameters depend on it (masses, springs, dampers, bars with their lumped masses
        and coordinates, loads with their time functions); Rayleigh coefficients reach all."""
        n = self.n
        rows_of_param: dict[int, set[int]] = {}

        def touch(params: Any, dofs: Any) -> None:
            dof_set = {int(d) for d in np.ravel(dofs) if d < n}
            for p in np.ravel(params):
                rows_of_param.setdefault(int(p), set()).update(dof_set)

        for d, p in zip(self.mass_dof, self.mass_idx):
            touch(p, d)
        for e, dofs in enumerate(self.spring_dofs):
            touch([k[e] for k in (self.k1, self.k2, self.k3) if len(k)], dofs)
        for e, dofs in enumerate(self.damper_dofs):
            touch(self.c[e], dofs)
        for e, dofs in enumerate(self.bar_dofs):
            touch([self.bar_A[e], self.bar_E[e], self.bar_rho[e], *np.ravel(self.bar_X[e])], dofs)
        for dof, amp, fn in self.loads:
            touch([amp, *fn.idx], dof)
        if self.rayleigh is not None:
            # αM + βK0: every row of the mass and stiffness; the other parameters of M and K0
            # already reach their own rows
            touch(list(self.rayleigh), np.arange(n))
        # initial conditions do not enter F_R; any other entry not listed above (a future
        # element's) is taken to reach every row, so the colouring stays correct, only coarser
        initial = {int(i) for _, i in list(self.init_q) + list(self.init_qd)}
        every = set(range(n))

        def rows_of(p: int) -> set[int]:
            return rows_of_param.get(p, set() if p in initial else every)
        return [np.array(sorted(set().union(*(rows_of(p) for p in params))), int)
                for params in self.table.design_dependents()]

    def linearize(self, t: float, s: StepState, params: dict[str, Any]) -> Linearization:
        K = self._tangent(s.q, params)
        D = params["D"] if self.traits.has_damping else None
        if not self.traits.sparse:
            return Linearization(R_z=np.diag(params["mass"]), R_q=K, R_qd=D)
        mass = params["mass"]
        if self._mass_matrix is None or self._mass_matrix[0] is not mass:   # once per design
            self._mass_matrix = (mass, sp.diags(mass).tocsc())
        return SparseLinearization(R_z=self._mass_matrix[1], R_q=K, R_qd=D, unions=self._unions)

    def structural_mass(self, params: dict[str, Any]) -> Any:
        """Sum of point masses and bar masses ρAL (mass unit of the case)."""
        total = np.sum(params["pv"][self.mass_idx]) if len(self.mass_idx) else 0.0
        if len(self.bar_names):
            total = total + np.sum(params["bar_mass"])
        return total

    def dof_labels(self) -> list[str]:
        return list(self.dof_names)

    # ------------------------------------------------------------------ outputs
    def output(self, spec: Any, path: str, problems: ProblemCollector) -> Output | None:
        """Quantities: ``{dof: NAME|[NAMES], kind: displacement|velocity|acceleration}`` or
        ``{element: NAME|[NAMES]|all, kind: force|stress|strain}``."""
        if not check_keys(spec, path, allowed("structural.quantity"), problems):
            return None
        kind = spec.get("kind", "displacement" if "dof" in spec else "force")
        if "dof" in spec:
            names = spec["dof"] if isinstance(spec["dof"], list) else [spec["dof"]]
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
            return Output(lambda t, s, prm, _f=fld, _i=ia: getattr(s, _f)[_i],
                          tuple(f"{n}.{kind}" for n in names), unit, linear=True)
        if "element" not in spec:
            problems.add(path, "expected 'dof' or 'element'")
            return None
        names = spec["element"]
        all_names = self.spring_names + self.damper_names + self.bar_names
        if names == "all":
            names = list(self.bar_names) if self.bar_names else list(self.spring_names)
        names = names if isinstance(names, list) else [names]
        kinds = ("force", "stress", "strain")
        if kind not in kinds:
            problems.add(f"{path}.kind",
                         f"unknown kind {kind!r}{did_you_mean(kind, kinds)} (known: {', '.join(kinds)})")
            return None
        bars, springs = [], []
        for nm in names:
            if nm in self.bar_names:
                bars.append(self.bar_names.index(nm))
            elif nm in self.spring_names and kind == "force":
                springs.append(self.spring_names.index(nm))
            elif nm in self.spring_names:
                problems.add(f"{path}.kind", f"springs report only 'force', not {kind!r}")
            else:
                problems.add(f"{path}.element", f"unknown element {nm!r}{did_you_mean(nm, all_names)}")
        if len(bars) + len(springs) != len(names):
            return None
        if springs and bars:
            problems.add(f"{path}.element", "mix springs and bars in separate quantities")
            return None
        if springs:
            si = np.array(springs)
            return Output(lambda t, s, prm, _i=si: self._spring_state(s.q, prm, _i)[0],
                          tuple(f"{n}.force" for n in names), "", batched=True, autonomous=True)
        bi = np.array(bars)

        def bar_out(t: float, s: StepState, prm: dict[str, Any], _i: np.ndarray = bi, _k: str = kind) -> np.ndarray:
            bs = self._bar_state(s.q, prm)
            if _k == "strain":
                return bs["strain"][..., _i]
            if _k == "force":
                return bs["N"][..., _i]
            return (prm["E"] * bs["strain"])[..., _i]

        return Output(bar_out, tuple(f"{n}.{kind}" for n in names), "-" if kind == "strain" else "",
                      batched=True, autonomous=True)


def _times(x: np.ndarray, M: Any) -> np.ndarray:
    """x @ M for x (..., a) and M (a, b) dense or sparse (scipy's sparse products take at most
    two dimensions: the leading axes are folded into one)."""
    if x.ndim <= 2 or not sp.issparse(M):
        return x @ M
    return (x.reshape(-1, x.shape[-1]) @ M).reshape(x.shape[:-1] + (M.shape[1],))


# ---------------------------------------------------------------------- builder
_MODEL_KEYS = allowed("model.structural")


@register("structural")
def build_structural(spec: dict, path: str, table: ParameterTable,
                     problems: ProblemCollector) -> StructuralModel | None:
    """Build a :class:`StructuralModel` from the case's ``model`` mapping."""
    n_before = len(problems.problems)
    check_keys(spec, path, _MODEL_KEYS, problems)
    dim = spec.get("dim", 2)
    if dim not in (2, 3):
        problems.add(f"{path}.dim", f"must be 2 or 3, found {dim!r}")
        dim = 2
    dof_names: list[str] = []
    fixed: set[str] = set()
    scalar = spec.get("dofs", [])
    if not isinstance(scalar, list) or not all(isinstance(d, str) for d in scalar):
        problems.add(f"{path}.dofs", f"expected a list of DOF names, found {scalar!r}")
        scalar = []
    dof_names += scalar
    node_coords: dict[str, list[int]] = {}
    nodes = spec.get("nodes", {}) or {}
    if not isinstance(nodes, dict):
        problems.add(f"{path}.nodes", "expected a mapping node name -> {coords, fixed}")
        nodes = {}
    for name, nd in nodes.items():
        npath = f"{path}.nodes.{name}"
        if not check_keys(nd, npath, allowed("structural.node"), problems, required=("coords",)):
            continue
        node_coords[name] = table.add_many(nd.get("coords", [0] * dim), f"{npath}.coords", problems, length=dim)
        fx = nd.get("fixed", [])
        if fx is True or fx == "all":
            fx = list(AXES[:dim])
        if not isinstance(fx, list) or any(a not in AXES[:dim] for a in fx):
            problems.add(f"{npath}.fixed", f"expected a list of axes from {list(AXES[:dim])} or 'all', found {fx!r}")
            fx = []
        for a in AXES[:dim]:
            (fixed.add if a in fx else dof_names.append)(f"{name}.{a}")
    if len(set(dof_names)) != len(dof_names):
        problems.add(f"{path}.dofs", "DOF names must be unique")
    n = len(dof_names)
    index = {d: i for i, d in enumerate(dof_names)}

    def dof(name: Any, p: str) -> int:
        if name == GROUND or name in fixed:
            return n
        if name not in index:
            problems.add(p, f"unknown dof {name!r}{did_you_mean(name, list(index) + [GROUND])}")
            return n
        return index[name]

    def node_dofs(name: Any, p: str) -> list[int]:
        if name not in node_coords:
            problems.add(p, f"unknown node {name!r}{did_you_mean(name, node_coords)}")
            return [n] * dim
        return [dof(f"{name}.{a}", p) for a in AXES[:dim]]

    mass_terms: list[tuple[int, int]] = []
    springs, dampers, bars = _Group(), _Group(), _Group()
    bar_nodes: list[tuple[str, str]] = []
    names_seen: set[str] = set()
    spring_nonlinear = False
    zero_index = -1
    elements = spec.get("elements", [])
    if not isinstance(elements, list):
        problems.add(f"{path}.elements", "expected a list")
        elements = []
    kinds = ("mass", "spring", "damper", "bar")
    for k, el in enumerate(elements):
        ep = f"{path}.elements[{k}]"
        if not isinstance(el, dict):
            problems.add(ep, f"expected a mapping, found {el!r}")
            continue
        kind = el.get("type")
        name = str(el.get("name", f"{kind}{k}"))
        if name in names_seen:
            problems.add(f"{ep}.name", f"duplicate element name {name!r}")
        names_seen.add(name)
        if kind == "mass":
            check_keys(el, ep, allowed("structural.mass"), problems, required=("mass",))
            pi = table.add(el.get("mass"), f"{ep}.mass", problems, positive=True)
            targets = [dof(el["dof"], f"{ep}.dof")] if "dof" in el else \
                node_dofs(el.get("node"), f"{ep}.node") if "node" in el else []
            if not targets:
                problems.add(ep, "a mass needs 'dof' or 'node'")
            mass_terms += [(d, pi) for d in targets]
        elif kind in ("spring", "damper"):
            keys = allowed(f"structural.{kind}")
            check_keys(el, ep, keys, problems, required=("dofs", "k" if kind == "spring" else "c"))
            pair = el.get("dofs", [])
            if not isinstance(pair, list) or len(pair) not in (1, 2):
                problems.add(f"{ep}.dofs", f"expected [dof] or [dof_a, dof_b|ground], found {pair!r}")
                continue
            ids = [dof(d, f"{ep}.dofs") for d in pair] + ([n] if len(pair) == 1 else [])
            if kind == "spring":
                higher = {}
                for key in ("k2", "k3"):
                    if key in el:
                        spring_nonlinear = True
                        higher[key] = table.add(el[key], f"{ep}.{key}", problems)
                    else:
                        if zero_index < 0:
                            zero_index = table.add(0.0, "", problems)
                        higher[key] = zero_index
                springs.add(name, ids, k1=table.add(el.get("k"), f"{ep}.k", problems), **higher)
            else:
                dampers.add(name, ids, c=table.add(el.get("c"), f"{ep}.c", problems, nonnegative=True))
        elif kind == "bar":
            check_keys(el, ep, allowed("structural.bar"), problems,
                       required=("nodes", "area", "E"))
            pair = el.get("nodes", [])
            if not isinstance(pair, list) or len(pair) != 2:
                problems.add(f"{ep}.nodes", f"expected [node_a, node_b], found {pair!r}")
                continue
            ids = node_dofs(pair[0], f"{ep}.nodes") + node_dofs(pair[1], f"{ep}.nodes")
            bars.add(name, ids, A=table.add(el.get("area"), f"{ep}.area", problems, positive=True),
                     E=table.add(el.get("E"), f"{ep}.E", problems, positive=True),
                     rho=table.add(el.get("density", 0.0), f"{ep}.density", problems, nonnegative=True))
            bar_nodes.append((pair[0], pair[1]))
        else:
            problems.add(f"{ep}.type", f"unknown element type {kind!r}{did_you_mean(kind, kinds)} "
                                       f"(known: {', '.join(kinds)})")
    loads = []
    for k, ld in enumerate(spec.get("loads", []) or []):
        lp = f"{path}.loads[{k}]"
        if not check_keys(ld, lp, allowed("structural.load"), problems, required=("value",)):
            continue
        if "dof" in ld:
            target = dof(ld["dof"], f"{lp}.dof")
        elif "node" in ld:
            direction = ld.get("direction")
            if direction not in AXES[:dim]:
                problems.add(f"{lp}.direction", f"expected one of {list(AXES[:dim])}, found {direction!r}")
                continue
            target = node_dofs(ld["node"], f"{lp}.node")[AXES.index(direction)]
        else:
            problems.add(lp, "a load needs 'dof' or 'node' + 'direction'")
            continue
        amp = table.add(ld.get("value"), f"{lp}.value", problems)
        fn = build_time_function(ld.get("function"), f"{lp}.function", table, problems)
        if fn is not None:
            loads.append((target, amp, fn))
    init = spec.get("initial", {}) or {}
    init_lists: tuple[list[tuple[int, int]], list[tuple[int, int]]] = ([], [])
    if check_keys(init, f"{path}.initial", allowed("structural.initial"), problems):
        for j, key in enumerate(("displacement", "velocity")):
            entries = init.get(key, {}) or {}
            if not isinstance(entries, dict):
                problems.add(f"{path}.initial.{key}", "expected a mapping dof -> value")
                continue
            for d, v in entries.items():
                ip = f"{path}.initial.{key}.{d}"
                di = dof(d, ip)
                init_lists[j].append((di, table.add(v, ip, problems)))
    rayleigh = None
    damping = spec.get("damping")
    if damping is not None and check_keys(damping, f"{path}.damping", allowed("structural.damping"), problems):
        ry = damping.get("rayleigh")
        if check_keys(ry, f"{path}.damping.rayleigh", allowed("structural.rayleigh"), problems):
            rayleigh = (table.add(ry.get("alpha", 0.0), f"{path}.damping.rayleigh.alpha", problems, nonnegative=True),
                        table.add(ry.get("beta", 0.0), f"{path}.damping.rayleigh.beta", problems, nonnegative=True))
    la = spec.get("linear_algebra", "auto")
    if la not in ("auto", "dense", "sparse"):
        problems.add(f"{path}.linear_algebra", f"expected auto, dense or sparse, found {la!r}")
    if n == 0:
        problems.add(path, "the model has no free degrees of freedom")
    massed = {d for d, _ in mass_terms} | ({d for row in bars.dofs for d in row} if bars.names else set())
    for i, d in enumerate(dof_names):
        if i not in massed:
            problems.add(f"{path}.elements", f"dof {d!r} has no mass (add a mass or a bar density)")
    try:
        model = StructuralModel(dof_names=dof_names, table=table, mass_terms=mass_terms, springs=springs,
                                dampers=dampers, bars=bars, dim=dim, node_coords=node_coords,
                                bar_nodes=bar_nodes, loads=loads, initial=init_lists, rayleigh=rayleigh,
                                sparse=None if la == "auto" else la == "sparse",
                                spring_nonlinear=spring_nonlinear)
    except (ValueError, IndexError, TypeError):
        if len(problems.problems) > n_before:
            return None  # the problems already listed explain why it cannot be assembled
        raise
    # with problems listed, the model is still returned so that the responses can be checked
    # against its DOFs and elements; the loader raises before anything runs
    return model
