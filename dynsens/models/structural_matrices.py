"""The matrices of a structural model (method.md §3): tangent stiffness, damping and mass,
assembled from element entries (dense, or sparse on patterns kept per call site), and the
linearization the Newton matrix and the sensitivity step are built from.  A mixin of
:class:`~dynsens.models.structural.StructuralModel`; its element arrays live there."""
from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from .base import Linearization, StepState
from .sparse_assembly import PatternAssembly, SparseLinearization, UnionCache


class StructuralMatrices:
    """Assembly of K_t, D, M and the model's :class:`Linearization` (mixin)."""

    # the model's element arrays and caches (set in StructuralModel.__init__)
    n: int
    dim: int
    traits: Any
    spring_names: list[str]
    damper_names: list[str]
    bar_names: list[str]
    spring_dofs: np.ndarray
    damper_dofs: np.ndarray
    bar_dofs: np.ndarray
    c: np.ndarray
    rayleigh: Any
    beams: Any
    frames: Any
    followers: Any
    nl_dampers: Any
    rotating_mass: bool
    frame_mass: bool
    _assembly_plans: dict[str, Any]
    _patterns: dict[str, Any]
    _sums: dict[str, Any]
    _unions: Any
    _diag_mass: tuple[Any, Any] | None
    _spring_state: Any
    _bar_state: Any
    _ext: Any

    def _mass_matrix(self, params: dict[str, Any], dtype: Any, q: np.ndarray | None = None) -> Any:
        """M(q): the diagonal (point, bar and lumped beam masses) plus the consistent beams'
        masses at state q (default: the undeformed structure, as Rayleigh damping uses it)."""
        diag = np.arange(self.n)
        qe = self._ext(np.zeros(self.n, dtype=dtype) if q is None else q)
        rows, cols, vals = [diag], [diag], [params["mass"]]
        if self.rotating_mass:
            Mb = self.beams.turning_mass(qe, params)["M"]
            idx = self.beams.idx[self.beams.is_consistent]
            rows.append(np.repeat(idx, 6, axis=1).ravel())
            cols.append(np.tile(idx, (1, 6)).ravel())
            vals.append(Mb.reshape(-1))
        if self.frame_mass:
            r, c, v = self.frames.consistent_entries(params)
            rows, cols, vals = rows + [r], cols + [c], vals + [v]
        return self._assemble("mass", rows, cols, vals, np.result_type(dtype, *vals))

    def _tangent(self, q: np.ndarray, params: dict[str, Any]) -> Any:
        """Tangent stiffness K_t = ∂f_int/∂q (dense or sparse)."""
        pv = params["pv"]
        rows, cols, vals = [], [], []
        if len(self.spring_names):
            _, kt = self._spring_state(q, params)
            assert kt is not None
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
        if len(self.beams):
            r, c, v = self.beams.tangent(self._ext(q), params)
            rows.append(r)
            cols.append(c)
            vals.append(v)
        if len(self.frames):
            r, c, v = self.frames.tangent(self._ext(q), params)
            rows, cols, vals = rows + [r], cols + [c], vals + [v]
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

    def linearize(self, t: float, s: StepState, params: dict[str, Any]) -> Linearization:
        # each block gathers its terms (follower loads, nonlinear dampers, a turning mass) and sums
        # them once (sparse models: on a pattern kept per block, see :meth:`_add`)
        Ks = [self._tangent(s.q, params)]
        if len(self.followers):
            rows, cols, vals = self.followers.tangent(t, self._ext(s.q), params["pv"])
            Ks.append(-self._assemble("follower", rows, cols, vals, np.result_type(s.q, params["pv"])))
        # the 3D frames' consistent mass is constant (small rotations): kept with the parameters
        Ms = [params["M0"] if self.frame_mass and not self.rotating_mass else self._diagonal_mass(params)]
        Ds = [params["D"]] if self.traits.has_damping else []
        if len(self.nl_dampers):
            rows, cols, vals = self.nl_dampers.tangent(self._ext(s.qd), params["pv"])
            Ds.append(self._assemble("nl_damping", rows, cols, vals, np.result_type(s.qd, params["pv"])))
        if self.rotating_mass:
            rows, cols, m_v, c_v, k_v = self.beams.inertia_jacobians(
                self._ext(s.q), self._ext(s.qd), self._ext(s.qdd), params)
            dtype = np.result_type(s.q, s.qd, s.qdd, params["pv"])
            Ms.append(self._assemble("inertia_M", [rows], [cols], [m_v], dtype))
            Ks.append(self._assemble("inertia_K", [rows], [cols], [k_v], dtype))
            Ds.append(self._assemble("inertia_C", [rows], [cols], [c_v], dtype))
        M, K = self._add("M", Ms), self._add("K", Ks)
        D = self._add("D", Ds) if Ds else None
        if not self.traits.sparse:
            return Linearization(R_z=M, R_q=K, R_qd=D)
        return SparseLinearization(R_z=M, R_q=K, R_qd=D, unions=self._unions)

    def _diagonal_mass(self, params: dict[str, Any]) -> Any:
        """diag(M) of the point, bar and lumped beam masses, made once per design (read-only)."""
        mass = params["mass"]
        kept = self._diag_mass          # read once: the pair stays consistent
        if kept is None or kept[0] is not mass:
            M = sp.diags(mass).tocsc() if self.traits.sparse else np.diag(mass)
            if not self.traits.sparse:
                M.flags.writeable = False
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
