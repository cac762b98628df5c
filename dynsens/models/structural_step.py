r"""The Newton iteration of a step of a spring network, compiled (no return to the interpreter).

:func:`dynsens.solver.newton_core.newton_iterations` is compiled for :class:`SpringStepData`, a
named tuple of a step's arrays.  It serves a structural model of point masses, springs
(:func:`.spring_law.spring_law`), viscous and Rayleigh damping and prescribed loads, whose
iteration matrix S = M + c_q K_t + c_q̇ D the Python path factors as a tridiagonal band (a chain,
after its reordering), in real arithmetic.  The step operations are overloaded here:

* the state is the scheme's corrector (:func:`dynsens.integrators.newmark.correct_arrays`);
* F_R = M q̈ + f_int(q) − f_ext(t) + D q̇ with the spring law's forces and tangents, summed in the
  order of the Python path's assembly and products, D q̇ by rows in column order as scipy's
  product of a canonical sparse D; f_ext(t) is the model's, evaluated once a step in Python;
* S is formed on the three diagonals ((c_q K_t + c_q̇ D) + M, the Python path's sums) and
  factored by :func:`dynsens.solver.tridiagonal.gttrf` (LAPACK's dgttrf, operation for
  operation) in the band plan's order, with the Python path's tests of regularity.

Its runs are bit for bit those of the Python iteration (tests/test_structural_step.py).  Only
sparse models are served: a dense model's D q̇ is summed by BLAS in an order a loop cannot
repeat, and the last bits it moved changed a Newton iteration count, and so gradients by 3e-11
(a chain of 100 masses, 2 000 steps).
"""
from __future__ import annotations

import sys
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import scipy.sparse as sp

from ..integrators.newmark import correct_arrays
from ..solver import newton_core as core
from ..solver import tridiagonal
from ..solver._jit import enabled, inline
from ..solver.banded import BandPlan, TridiagonalFactor
from ..solver.compiled_iteration import (NON_FINITE_ENTRIES, REGULAR, SMALL_PIVOT, ZERO_PIVOT,
                                         compiled_iteration, read_only, singular_reason, sources_stamp)
from ..solver.linalg import Counters, Factor, SingularMatrixError, all_finite, pivot_test
from . import spring_law as law
from .base import StepState
from .sparse_assembly import on_pattern

if TYPE_CHECKING:  # pragma: no cover
    from .structural import StructuralModel

Array = np.ndarray


class SpringStepData(NamedTuple):
    """What one step of a spring network reads: the step's arrays first, then those of the
    model and design (kept between steps).  Every array but the prediction is read-only."""

    q_pred: Array
    qd_pred: Array
    p_pred: Array            # (0,): no first-order states
    coeffs: Array            # (c_q, c_q̇, c_p)
    f_ext: Array             # (n,) loads at t
    mass: Array              # (n,) the diagonal mass
    spring_a: Array          # (n_s,) the springs' DOFs, n for ground
    spring_b: Array
    k1: Array
    k2: Array
    k3: Array
    k_pos: Array             # (4 n_s,) storage positions of the tangent's entries (aa, bb, ab, ba), −1: grounded
    d_ptr: Array             # D by rows (sorted columns)
    d_col: Array
    d_val: Array
    mass_band: Array         # (3n − 2,) M and D on the three diagonals
    damping_band: Array
    perm: Array              # (n,) the band order: its row k is row perm[k] of S
    s_row: Array             # S's stored entries in the Python path's order: row, column, storage
    s_col: Array
    s_pos: Array


def _is_step_data(ops: Any) -> bool:
    from numba import types
    return isinstance(ops, types.BaseNamedTuple) and ops.instance_class is SpringStepData


def _register() -> None:
    """The overloads of the step operations for SpringStepData (numba only)."""
    from numba.extending import overload

    correct = inline(correct_arrays)

    @overload(core.step_correct)
    def _correct(ops, z):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops, z):  # type: ignore[no-untyped-def]
            n = ops.mass.shape[0]
            c = ops.coeffs
            q, qd, p = correct(ops.q_pred, ops.qd_pred, ops.p_pred, c[0], c[1], c[2], z[:n], z[n:])
            return q, qd, z[:n], z[n:], p, z[n:]
        return impl

    @overload(core.step_residual)
    def _residual(ops, s):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops, s):  # type: ignore[no-untyped-def]
            q, qd, qdd = s[0], s[1], s[2]
            n = q.shape[0]
            a, b = ops.spring_a, ops.spring_b
            delta = np.empty(a.shape[0])
            for e in range(a.shape[0]):
                delta[e] = (q[a[e]] if a[e] < n else 0.0) - (q[b[e]] if b[e] < n else 0.0)
            f, kt = law.spring_law(delta, ops.k1, ops.k2, ops.k3)
            f_int = np.zeros(n)
            for e in range(a.shape[0]):
                if a[e] < n:
                    f_int[a[e]] += f[e]
                if b[e] < n:
                    f_int[b[e]] -= f[e]
            R = (ops.mass * qdd + f_int) - ops.f_ext
            for i in range(n):
                acc = 0.0
                for k in range(ops.d_ptr[i], ops.d_ptr[i + 1]):
                    acc += ops.d_val[k] * qd[ops.d_col[k]]
                R[i] += acc
            return R, kt
        return impl

    @overload(core.step_no_factor)
    def _no_factor(ops):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops):  # type: ignore[no-untyped-def]
            e = np.zeros(0)
            return e, e, e, e, e, e, e, np.zeros(0, np.int32), np.zeros(3)
        return impl

    @overload(core.step_factor_solve)
    def _factor_solve(ops, s, evaluation, rhs):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops, s, evaluation, rhs):  # type: ignore[no-untyped-def]
            kt = evaluation
            n = rhs.shape[0]
            n_s = kt.shape[0]
            K = np.zeros(3 * n - 2)
            for block in range(4):          # the assembly's order: (a, a), (b, b), (a, b), (b, a)
                sign = 1.0 if block < 2 else -1.0
                for e in range(n_s):
                    pos = ops.k_pos[block * n_s + e]
                    if pos >= 0:
                        K[pos] += sign * kt[e]
            c = ops.coeffs
            S = ops.mass_band + (c[0] * K + c[1] * ops.damping_band)
            lu = S.copy()
            du2 = np.zeros(max(n - 2, 0))
            piv = np.zeros(n, np.int32)
            x = np.zeros(n)
            test = np.zeros(3)              # (code, column of a zero pivot, pivot ratio)
            if not all_finite(S):
                test[0] = NON_FINITE_ENTRIES
            else:
                dl, d, du = lu[:n - 1], lu[n - 1:2 * n - 1], lu[2 * n - 1:]
                info = tridiagonal.gttrf(dl, d, du, du2, piv)
                if info > 0:
                    test[0], test[1] = ZERO_PIVOT, info
                else:
                    regular, ratio = pivot_test(d)
                    if not regular:
                        test[0], test[2] = SMALL_PIVOT, ratio
                    else:
                        for k in range(n):
                            x[k] = rhs[ops.perm[k]]
                        tridiagonal.gttrs(dl, d, du, du2, piv, x)
            step = np.empty(n)
            for k in range(n):
                step[ops.perm[k]] = x[k]
            q, qd, qdd = s[0], s[1], s[2]
            return test[0] == REGULAR, (K, q, qd, qdd.copy(), S, lu, du2, piv, test), step
        return impl

    @overload(core.step_at_roundoff)
    def _at_roundoff(ops, lf, R, z, rnorm):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops, lf, R, z, rnorm):  # type: ignore[no-untyped-def]
            S = lf[4]
            if S.size == 0:
                return False
            entries = S[ops.s_pos]          # S's stored entries, in the Python path's order
            if core.above_roundoff_bound(rnorm, entries, z):
                return False
            terms = np.zeros(R.shape[0])
            for k in range(entries.shape[0]):
                terms[ops.s_row[k]] += abs(entries[k]) * abs(z[ops.s_col[k]])
            return core.within_roundoff(R, terms)
        return impl

    @overload(core.step_block_norms)
    def _block_norms(ops, z, dz):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops, z, dz):  # type: ignore[no-untyped-def]
            zn, dzn = np.empty(1), np.empty(1)
            zn[0], dzn[0] = core.real_norm(z), core.real_norm(dz)
            return zn, dzn
        return impl


def _stamp() -> str:
    """The cache key of the compiled iteration: the sources it inlines (the overloads here, the
    spring law, the tridiagonal LU)."""
    return sources_stamp((law, tridiagonal, sys.modules[__name__]))


_ITERATE: Any = None


def _iterate() -> Any:
    """The compiled iteration (the overloads registered first)."""
    global _ITERATE
    if _ITERATE is None:
        _register()
        _ITERATE = compiled_iteration(_stamp())
    return _ITERATE


def serves(model: "StructuralModel") -> bool:
    """Whether the model is a sparse spring network: masses, springs, viscous and Rayleigh
    damping and loads only (its only nonlinearity the springs'), on the sparse path."""
    return bool(len(model.spring_names)) and model.traits.sparse and not (
        len(model.bar_names) or len(model.beams) or len(model.frames) or len(model.nl_dampers)
        or len(model.followers) or model.rotating_mass or model.frame_mass or model.traits.linear)


def _entries(A: sp.csc_matrix) -> tuple[Array, Array]:
    """(rows, columns) of the stored entries of a CSC matrix, in its order."""
    return A.indices, np.repeat(np.arange(A.shape[1]), np.diff(A.indptr))


class _Design:
    """The arrays of a model and design that every step reads (a run's: kept between steps)."""

    def __init__(self, model: "StructuralModel", params: dict[str, Any], plan: BandPlan, S: Any, K: Any):
        n = model.n
        self.plan = plan
        a, b = model.spring_dofs[:, 0], model.spring_dofs[:, 1]
        rows, cols = np.concatenate([a, b, a, b]), np.concatenate([a, b, b, a])
        grounded = (rows >= n) | (cols >= n)
        k_pos = np.full(rows.size, -1, dtype=np.intp)
        k_pos[~grounded] = plan.storage_positions(rows[~grounded], cols[~grounded])
        D = params.get("D")
        D = sp.csr_matrix((n, n)) if D is None else sp.csr_matrix(D)    # (a copy: sorted here)
        D.sum_duplicates()
        D.sort_indices()
        d_rows = np.repeat(np.arange(n), np.diff(D.indptr))
        diagonal = np.arange(n)
        mass_band = np.zeros(3 * n - 2)
        mass_band[plan.storage_positions(diagonal, diagonal)] = params["mass"]
        damping_band = np.zeros(3 * n - 2)
        damping_band[plan.storage_positions(d_rows, D.indices)] = D.data
        s_row, s_col = _entries(S)        # the Python path's S: its stored entries, in CSC order
        self.tangent = K                  # the tangent's pattern, and where its entries are here
        self.tangent_positions = plan.storage_positions(*_entries(K))
        perm = np.arange(n) if plan.perm is None else plan.perm
        self.fields = tuple(read_only(x) for x in (
            params["mass"], a, b, params["k1"], params["k2"], params["k3"], k_pos, D.indptr.astype(np.intp),
            D.indices.astype(np.intp), D.data, mass_band, damping_band, perm, s_row.astype(np.intp),
            s_col.astype(np.intp), plan.storage_positions(s_row, s_col)))


def step_factory(model: "StructuralModel", newton: bool, refactor: bool) -> Any:
    """For :meth:`.structural.StructuralModel.compiled_step`: the :class:`CompiledSpringStep` of a
    step, or None for a step it does not serve (complex data; a design whose S the Python path
    does not factor as tridiagonal: it iterates in Python); None for a model it does not serve
    (not a spring network, see :func:`serves`)."""
    if not (newton and refactor and enabled() and serves(model)):
        return None
    kept: dict[int, tuple[Any, Any]] = {}       # per parameter set: its _Design (None: not served)
    empty = np.zeros(0)

    def design(t: float, pred: Any, params: dict[str, Any], coeffs: tuple[float, float, float]) -> Any:
        hit = kept.get(id(params))
        if hit is not None and hit[0] is params:
            return hit[1]
        kept.clear()        # one design at a time (a run's)
        kept[id(params)] = (params, None)
        # how the Python path factors S: served only where it takes the tridiagonal band
        lin = model.linearize(t, StepState(pred.q, pred.qd, np.zeros(model.n), empty, empty, empty), params)
        S = lin.iteration_matrix(*coeffs, n_q=model.n)
        try:
            factor = Factor(S, Counters(), within=lin.dense_pattern)
        except SingularMatrixError:
            return None
        lu = getattr(factor, "_lu", None)
        if isinstance(lu, TridiagonalFactor):
            kept[id(params)] = (params, _Design(model, params, lu.plan, S, lin.R_q))
        return kept[id(params)][1]

    def make(t: float, pred: Any, params: dict[str, Any], coeffs: tuple[float, float, float]
             ) -> "CompiledSpringStep | None":
        if params["pv"].dtype != np.float64 or pred.q.dtype != np.float64 or pred.qd.dtype != np.float64:
            return None
        d = design(t, pred, params, coeffs)
        if d is None:
            return None
        f_ext = read_only(model.external_force(t, params), np.float64)
        data = SpringStepData(pred.q, pred.qd, read_only(pred.p, np.float64), np.array(coeffs), f_ext, *d.fields)
        return CompiledSpringStep(model, t, params, d, data)
    return make


class CompiledSpringStep:
    """One step of a spring network for :func:`.newton_core.newton_iterations`, compiled: the
    data of the step, and the conversion of what the iteration returns."""

    def __init__(self, model: "StructuralModel", t: float, params: dict[str, Any], design: _Design,
                 data: SpringStepData):
        self.model, self.t, self.params, self.design, self.data = model, t, params, design, data

    def iterate(self, *args: Any) -> tuple:
        """:func:`.newton_core.newton_iterations` with this step's data (same arguments after ops)."""
        return _iterate()(self.data, *args)

    @staticmethod
    def state(s: tuple) -> StepState:
        """The StepState of the iteration's state tuple."""
        return StepState(*s)

    def linearization_and_factor(self, lf: tuple, counters: Counters, linearization: bool = True
                                 ) -> tuple[Any, Factor | None, None]:
        """(Linearization, Factor, S) of the iteration's last linearization (Factor None when S
        was not regular; the Linearization, the model's own at the state S was formed at, only
        with ``linearization``: the sensitivities need it, the primal steps do not; S None: the
        Python path's round-off test never reads a compiled step's)."""
        K, q, qd, qdd, S, lu, du2, piv, test = lf
        if not S.size:
            return None, None, None
        d = self.design
        factor = None
        if test[0] == REGULAR:
            factor = Factor.from_band(TridiagonalFactor.from_lu(d.plan, lu, du2, piv), counters)
        lin = None
        if linearization:
            # the model's linearization with the step's K_t: the same sums as its own assembly
            empty = np.zeros(0)
            lin = self.model.linearize(self.t, StepState(q, qd, qdd, empty, empty, empty), self.params,
                                       tangent=on_pattern(d.tangent, K[d.tangent_positions]))
        return lin, factor, None

    @staticmethod
    def singular_reason(lf: tuple) -> str:
        """Why S was not regular, in the words of :class:`~dynsens.solver.linalg.Factor`."""
        return singular_reason(lf[-1])
