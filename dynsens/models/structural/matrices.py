"""The matrices of a structural model (method.md §3): tangent stiffness, damping and mass,
assembled from element entries (dense, or sparse on patterns kept per call site), and the
linearization the Newton matrix and the sensitivity step are built from, and the residual rows
each design variable reaches (the pattern of the design partials).  A mixin of
:class:`~dynsens.models.structural.model.StructuralModel`; its element arrays live there."""
from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from ..base import Linearization, StepState
from ..sparse_assembly import PatternAssembly, SparseLinearization, UnionCache


class StructuralMatrices:
    """Assembly of K_t, D, M and the model's :class:`Linearization` (mixin)."""

    # the model's element sets and caches (set in StructuralModel.__init__)
    n: int
    dim: int
    traits: Any
    sets: list[Any]
    active: list[Any]
    providing: dict[str, list[Any]]
    rayleigh: Any
    followers: Any
    rotating_mass: bool
    frame_mass: bool
    loads: list[Any]
    init_q: Any
    init_qd: Any
    table: Any
    _assembly_plans: dict[str, Any]
    _patterns: dict[str, Any]
    _sums: dict[str, Any]
    _unions: Any
    _diag_mass: tuple[Any, Any] | None
    _pattern_kept: tuple[int, np.ndarray] | None
    _design_rows: tuple[np.ndarray, ...] | None
    _ext: Any
    corotated_damping: Any

    def _mass_matrix(self, params: dict[str, Any], dtype: Any, q: np.ndarray | None = None) -> Any:
        """M(q): the diagonal (point, bar and lumped beam masses) plus the consistent beams'
        masses at state q (default: the undeformed structure, as Rayleigh damping uses it)."""
        diag = np.arange(self.n)
        qe = self._ext(np.zeros(self.n, dtype=dtype) if q is None else q)
        rows, cols, vals = [diag], [diag], [params["mass"]]
        for k in self.sets:
            for r, c, v in k.mass_entries(qe, params):
                rows, cols, vals = rows + [r], cols + [c], vals + [v]
        return self._assemble("mass", rows, cols, vals, np.result_type(dtype, *vals))

    def _tangent(self, q: np.ndarray, params: dict[str, Any], corotated: bool = True) -> Any:
        """Tangent stiffness K_t = ∂f_int/∂q (dense or sparse); without ``corotated`` that of the
        springs and linear beams only (the part of Rayleigh's β K that does not turn)."""
        triplets = [t for k in self.providing["tangent"] for t in k.tangent(q, params, corotated)]
        rows, cols, vals = [t[0] for t in triplets], [t[1] for t in triplets], [t[2] for t in triplets]
        return self._assemble("tangent" if corotated else "tangent_linear", rows, cols, vals,
                              np.result_type(q, params["pv"]))

    def _damping(self, params: dict[str, Any], dtype: Any) -> Any:
        rows, cols, vals = [], [], []
        for k in self.sets:
            for r, c, v in k.damping_entries(params):
                rows.append(r)
                cols.append(c)
                vals.append(v)
        D = self._assemble("damping", rows, cols, vals, np.result_type(dtype, params["pv"]))
        if self.rayleigh is not None:
            pv = params["pv"]
            alpha, beta = pv[self.rayleigh[0]], pv[self.rayleigh[1]]
            Mdiag = params["mass"]
            M = params["M0"] if "M0" in params else sp.diags(Mdiag) if self.traits.sparse else np.diag(Mdiag)
            D = D + alpha * M + beta * params["K0"]
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
            # None: every entry is kept (no grounded ones), and the values need no selection
            plan = self._assembly_plans[site] = (None if keep.all() else keep, r[keep], c[keep],
                                                 r[keep] * n + c[keep])
        kept: np.ndarray | None = plan[0]
        r, c, flat = plan[1:]
        # the arrays' own ravel: np.ravel's dispatch costs more than the copy at these sizes
        v = np.concatenate([x.ravel() if isinstance(x, np.ndarray) else np.ravel(x) for x in vals])
        if kept is not None:
            v = v[kept]
        if self.traits.sparse:
            if site not in self._patterns:
                self._patterns[site] = PatternAssembly(n, r, c)
            return self._patterns[site].matrix(v, dtype)
        # bincount sums repeated positions (as np.add.at) at a fraction of its cost
        K = np.bincount(flat, v.real, n * n)
        if np.iscomplexobj(v) or np.dtype(dtype).kind == "c":
            K = K + 1j * np.bincount(flat, v.imag, n * n)
        return K.reshape(n, n)

    def linearize(self, t: float, s: StepState, params: dict[str, Any], tangent: Any = None) -> Linearization:
        """The model's :class:`Linearization` at s; ``tangent``: K_t at s where the caller has it
        (a compiled step forms it with the same sums)."""
        # each block gathers its terms (follower loads, nonlinear dampers, a turning mass) and sums
        # them once (sparse models: on a pattern kept per block, see :meth:`_add`)
        Ks = [self._tangent(s.q, params) if tangent is None else tangent]
        if len(self.followers):
            rows, cols, vals = self.followers.tangent(t, self._ext(s.q), params["pv"])
            Ks.append(-self._assemble("follower", rows, cols, vals, np.result_type(s.q, params["pv"])))
        # the 3D frames' consistent mass is constant (small rotations): kept with the parameters
        Ms = [params["M0"] if self.frame_mass and not self.rotating_mass else self._diagonal_mass(params)]
        Ds = [params["D"]] if self.traits.has_damping else []
        triplets = [t for k in self.providing["damping_tangent"] for t in k.damping_tangent(s.qd, params)]
        if triplets:
            rows, cols, vals = (list(x) for x in zip(*triplets))
            Ds.append(self._assemble("nl_damping", rows, cols, vals, np.result_type(s.qd, params["pv"])))
        if self.rotating_mass:
            self._turning_mass_terms(s, params, Ms, Ks, Ds)
        if self.corotated_damping.active(params):
            dtype = np.result_type(s.q, s.qd, params["pv"])
            for j, (rows, cols, k_v, c_v) in enumerate(
                    self.corotated_damping.jacobians(self._ext(s.q), self._ext(s.qd), params)):
                Ks.append(self._assemble(f"corot_damping_K{j}", [rows], [cols], [k_v], dtype))
                Ds.append(self._assemble(f"corot_damping_C{j}", [rows], [cols], [c_v], dtype))
        M, K = self._add("M", Ms), self._add("K", Ks)
        D = self._add("D", Ds) if Ds else None
        if not self.traits.sparse:
            return Linearization(R_z=M, R_q=K, R_qd=D, dense_pattern=self._dense_pattern())
        return SparseLinearization(R_z=M, R_q=K, R_qd=D, unions=self._unions)

    def _turning_mass_terms(self, s: StepState, params: dict[str, Any], Ms: list, Ks: list, Ds: list) -> None:
        """Append the Jacobians of the turning masses' inertia forces to the blocks' terms."""
        qe, qde, qdde = self._ext(s.q), self._ext(s.qd), self._ext(s.qdd)
        dtype = np.result_type(s.q, s.qd, s.qdd, params["pv"])
        for j, k in enumerate(self.sets):
            jac = k.inertia_jacobians(qe, qde, qdde, params)
            if jac is None:
                continue
            rows, cols, m_v, c_v, k_v = jac
            site = "inertia" if j == 0 else f"inertia{j}"
            Ms.append(self._assemble(f"{site}_M", [rows], [cols], [m_v], dtype))
            Ks.append(self._assemble(f"{site}_K", [rows], [cols], [k_v], dtype))
            Ds.append(self._assemble(f"{site}_C", [rows], [cols], [c_v], dtype))

    def _dense_pattern(self) -> np.ndarray:
        """Flat (row-major) positions where the dense M, K and D can be nonzero: the diagonal
        (lumped masses) and the positions of every assembly site (element tangents, damping,
        consistent masses; Rayleigh damping and the sums of :meth:`_add` stay within them).
        The same array until a site is added."""
        kept = self._pattern_kept
        if kept is None or kept[0] != len(self._assembly_plans):
            n = self.n
            flat = [np.arange(n) * (n + 1)] + [plan[3] for plan in self._assembly_plans.values()]
            kept = self._pattern_kept = (len(self._assembly_plans), np.unique(np.concatenate(flat)))
        return kept[1]

    def _diagonal_mass(self, params: dict[str, Any]) -> Any:
        """diag(M) of the point, bar and lumped beam masses, made once per design (read-only)."""
        mass = params["mass"]
        kept = self._diag_mass          # read once: the pair stays consistent
        if kept is None or kept[0] is not mass:
            M = sp.diags(mass).tocsc() if self.traits.sparse else np.diag(mass)
            entries: Any = M.data if self.traits.sparse else M
            entries.flags.writeable = False
            kept = self._diag_mass = (mass, M)
        return kept[1]

    def _add(self, site: str, terms: list[Any]) -> Any:
        """terms[0] + terms[1] + … in this order; sparse models sum on the union pattern kept
        for ``site``, entries that cancel staying as explicit zeros, so that the iteration matrix
        keeps one pattern for the whole run (its factorization plan is made once)."""
        if len(terms) == 1:
            return terms[0]
        if not self.traits.sparse:
            total = terms[0]
            for term in terms[1:]:
                total = total + term
            return total
        return self._sums.setdefault(site, UnionCache()).add(terms)

    def design_pattern(self) -> list[np.ndarray]:
        """Rows of the residual each design variable reaches through the elements whose
        parameters depend on it (masses, springs, dampers, bars with their lumped masses
        and coordinates, loads with their time functions); Rayleigh coefficients reach all.
        Made once per model (its structure is fixed; a run of m = 1 000 variables spent ~10 µs a
        step on it); the arrays are read-only."""
        if self._design_rows is None:
            rows = self._design_rows_of_variables()
            for r in rows:
                r.flags.writeable = False
            self._design_rows = tuple(rows)
        return list(self._design_rows)

    def _design_rows_of_variables(self) -> list[np.ndarray]:
        """:meth:`design_pattern`, made afresh."""
        n = self.n
        rows_of_param: dict[int, set[int]] = {}

        def touch(params: Any, dofs: Any) -> None:
            dof_set = {int(d) for d in np.ravel(dofs) if d < n}
            for p in np.ravel(params):
                rows_of_param.setdefault(int(p), set()).update(dof_set)

        for k in self.sets:
            for params, dofs in k.design_touch():
                touch(params, dofs)
        for params, dofs in self.followers.design_touch():
            touch(params, dofs)
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
