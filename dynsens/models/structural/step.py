r"""The Newton iteration of a step of a spring network, compiled: which designs it serves, and
what becomes of its results.

It serves a structural model of point masses, springs (:func:`.spring_law.spring_law`), viscous
and Rayleigh damping and prescribed loads, whose iteration matrix S = M + c_q K_t + c_q̇ D the
Python path factors either as a tridiagonal band (a chain, after its reordering) or as a dense
matrix with LAPACK's getrf (a dense model below the band's break-even, any pattern), in real
arithmetic.  The iteration runs compiled over the step operations of :mod:`.step_kernels`; its
last factor becomes a :class:`~dynsens.solver.linalg.Factor` and its K_t the model's own
linearization, for the sensitivities.  The design partials of a sparse network evaluate the same
compiled F_R, for all their states and parameter sets in one call (:func:`batch_residuals`).

Its runs are bit for bit those of the Python iteration (tests/test_structural_step.py).  A dense
model's products (f_int, D q̇, the round-off test's |S| |z|) are numpy's BLAS calls, which a loop
cannot repeat (summed in a loop, the last bits moved a Newton iteration count of a 100-mass chain,
and its gradients by 3e-11): the step calls BLAS too, through numba, and a dense S is factored by
the LAPACK routines scipy's wrappers call (dgesv: dgetrf, then dgetrs).  Whether the step serves a
model is decided by its kinds (declared) and by how the Python path factors S (its pattern), never
by comparing numbers at run time; that numba's BLAS sums as numpy's does is an assumption of the
installation, checked by tests/test_structural_step.py (the compiled F_R against the model's at
random states, and whole runs bit for bit).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable

import numpy as np
import scipy.sparse as sp

from ...solver._jit import enabled
from ...solver.banded import BandPlan, TridiagonalFactor
from ...solver.compiled_iteration import REGULAR, CompiledStep, read_only
from ...solver.linalg import Counters, Factor, SingularMatrixError
from ..base import StepState
from ..sparse_assembly import on_pattern
from .step_kernels import SpringStepData, compiled_residuals, iteration, march

if TYPE_CHECKING:  # pragma: no cover
    from .model import StructuralModel

Array = np.ndarray


def serves(model: "StructuralModel") -> bool:
    """Whether the model is a spring network: masses, springs, viscous and Rayleigh damping and
    loads only (its only nonlinearity the springs'): every element set's kind declares that the
    compiled step serves it (:meth:`.elements.ElementKind.served_compiled`)."""
    return bool(len(model.spring_names)) and model.compiled_kinds and not (
        len(model.followers) or model.rotating_mass or model.frame_mass or model.traits.linear)


def _entries(A: sp.csc_matrix) -> tuple[Array, Array]:
    """(rows, columns) of the stored entries of a CSC matrix, in its order."""
    return A.indices, np.repeat(np.arange(A.shape[1]), np.diff(A.indptr))


class DenseStorage:
    """S stored whole, column by column (as LAPACK's getrf takes it): entry (i, j) at j n + i.
    The counterpart, for a dense LU, of a :class:`~dynsens.solver.banded.BandPlan`'s storage."""

    perm = None

    def __init__(self, n: int):
        self.n = n

    def storage_positions(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Where the entries (i, j) of S go in the column-major (n, n) array."""
        return np.asarray(j) * self.n + np.asarray(i)


class _Design:
    """The arrays of a model and design that every step reads (a run's: kept between steps).

    ``plan``: where S's entries are stored for its factorization, the tridiagonal band's
    :class:`~dynsens.solver.banded.BandPlan` (3n − 2 entries) or :class:`DenseStorage` (n²)."""

    def __init__(self, model: "StructuralModel", params: dict[str, Any], plan: "BandPlan | DenseStorage",
                 S: Any, K: Any):
        n = model.n
        self.plan, self.n = plan, n
        self.dense_lu = isinstance(plan, DenseStorage)
        self.size = size = n * n if self.dense_lu else 3 * n - 2      # S's storage
        a, b = model.spring_dofs[:, 0], model.spring_dofs[:, 1]
        rows, cols = np.concatenate([a, b, a, b]), np.concatenate([a, b, b, a])
        grounded = (rows >= n) | (cols >= n)
        k_pos = np.full(rows.size, -1, dtype=np.intp)
        k_pos[~grounded] = plan.storage_positions(rows[~grounded], cols[~grounded])
        D_model = params.get("D")
        D = _damping_rows(model, params)
        d_rows = np.repeat(np.arange(n), np.diff(D.indptr))
        diagonal = np.arange(n)
        mass_storage = np.zeros(size)
        mass_storage[plan.storage_positions(diagonal, diagonal)] = params["mass"]
        damping_storage = np.zeros(size)
        damping_storage[plan.storage_positions(d_rows, D.indices)] = D.data
        self.dense = not sp.issparse(S)
        none = np.zeros((0, 0))
        if self.dense:            # the products numpy forms, as arrays; S's entries: those stored
            within = np.ones((n, n), bool) if self.dense_lu else \
                np.abs(diagonal[:, None] - diagonal[None, :]) <= 1
            s_col, s_row = np.nonzero(within.T)
            G = model._spring_scatter.G
            D_dense = np.zeros((n, n)) if D_model is None else D_model
            t_row, t_col = s_row, s_col       # K_t: dense, written on the whole storage
        else:                     # the Python path's S: its stored entries, in CSC order
            s_row, s_col = _entries(S)
            G = D_dense = none
            t_row, t_col = _entries(K)        # K_t: on the pattern of the model's assembly
        s_pos = plan.storage_positions(s_row, s_col)
        self.tangent = K          # where K_t's entries are, in the model's matrix and here
        self.tangent_flat = t_row * n + t_col
        self.tangent_positions = plan.storage_positions(t_row, t_col)
        perm = np.arange(n) if plan.perm is None else plan.perm
        self.fields = tuple(read_only(x) for x in (
            params["mass"], a, b, params["k1"], params["k2"], params["k3"], k_pos, G, D_dense,
            D.indptr.astype(np.intp), D.indices.astype(np.intp), D.data, mass_storage, damping_storage,
            np.array([self.dense_lu]), perm, s_row.astype(np.intp), s_col.astype(np.intp), s_pos))

    def tangent_matrix(self, K: Array) -> Any:
        """K_t as the model assembles it (sparse on its pattern, or dense), from its entries in
        S's storage K: the same numbers."""
        if not self.dense:
            return on_pattern(self.tangent, K[self.tangent_positions])
        out = np.zeros(self.n * self.n)
        out[self.tangent_flat] = K[self.tangent_positions]
        return out.reshape(self.n, self.n)


def _damping_rows(model: "StructuralModel", params: dict[str, Any]) -> sp.csr_matrix:
    """The design's damping matrix by rows, columns sorted, duplicates summed (a copy)."""
    n = model.n
    D_model = params.get("D")
    D = sp.csr_matrix((n, n)) if D_model is None else sp.csr_matrix(D_model)
    D.sum_duplicates()
    D.sort_indices()
    return D


def residual_data(model: "StructuralModel", params: dict[str, Any]) -> SpringStepData:
    """The step data F_R reads of a sparse spring network's design ``params`` (real): its masses,
    springs and damping by rows; what only S's factorization reads is left empty."""
    D = _damping_rows(model, params)
    a, b = model.spring_dofs[:, 0], model.spring_dofs[:, 1]
    no_float, no_int, none = np.zeros(0), np.zeros(0, np.intp), np.zeros((0, 0))
    return SpringStepData(*(read_only(x) for x in (
        no_float, no_float, no_float, np.zeros(3), no_float, params["mass"], a, b, params["k1"], params["k2"],
        params["k3"], no_int, none, none, D.indptr.astype(np.intp), D.indices.astype(np.intp), D.data,
        no_float, no_float, np.array([False]), no_int, no_int, no_int, no_int)))


def batch_residuals(model: "StructuralModel", params_list: list[dict[str, Any]]
                    ) -> Callable[[list[StepState], Array], Array] | None:
    """For :meth:`.StructuralModel.residual_batch_steps`: ``residuals(states, f_ext)``, F_R (K, n, B)
    of the K states for the B designs of ``params_list`` with their loads f_ext (K, B, n),
    compiled (the step's F_R, bit for bit the model's); None where the compiled step does not
    serve them: not a sparse spring network (a dense model's batch multiplies by BLAS over all
    states at once, which sums otherwise than one product per state), complex designs, compiled
    code disabled.  The caller checks that the states are real."""
    if not (enabled() and serves(model) and model.traits.sparse
            and all(p["pv"].dtype == np.float64 for p in params_list)):
        return None
    datas = [residual_data(model, p) for p in params_list]
    width = max(d.d_val.size for d in datas)

    def padded(x: Array) -> Array:
        return np.pad(x, (0, width - x.size))
    sets = (np.stack([d.mass for d in datas]), *(np.stack([getattr(d, k) for d in datas]) for k in ("k1", "k2", "k3")),
            np.stack([d.d_ptr for d in datas]), np.stack([padded(d.d_col) for d in datas]),
            np.stack([padded(d.d_val) for d in datas]))

    def residuals(states: list[StepState], f_ext: Array) -> Array:
        q, qd, qdd = (np.stack([getattr(s, f) for s in states]) for f in ("q", "qd", "qdd"))
        return compiled_residuals(datas[0], sets, q, qd, qdd, f_ext).transpose(0, 2, 1)
    return residuals


def _storage(factor: Factor) -> "BandPlan | DenseStorage | None":
    """Where a compiled step stores S to factor it as the Python path did (``factor``): the band
    plan of a tridiagonal factor, the whole matrix for a dense real LU (getrf); None for any
    other factorization (a wider band, SuperLU, a diagonal S): the Python iteration then runs."""
    lu = getattr(factor, "_lu", None)
    if isinstance(lu, TridiagonalFactor):
        return lu.plan
    if factor.dense_real_lu is not None:
        return DenseStorage(factor.n)
    return None


def loads(model: "StructuralModel", t: float, params: dict[str, Any]) -> Array:
    """f_ext (n,) at time t (s), as a step's data holds it (read-only)."""
    return read_only(model.external_force(t, params), np.float64)


def step_factory(model: "StructuralModel", newton: bool, refactor: bool) -> Any:
    """For :meth:`.structural.StructuralModel.compiled_step`: the :class:`CompiledSpringStep` of a
    step, or None for a step it does not serve (complex data; a design whose S the Python path
    factors neither as tridiagonal nor by a dense LU: it iterates in Python); None for a model it does not serve
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
        plan = _storage(factor)
        if plan is None:
            return None
        d = _Design(model, params, plan, S, lin.R_q)
        kept[id(params)] = (params, d)
        return d

    def _step_data(t: float, pred: Any, params: dict[str, Any], coeffs: tuple[float, float, float],
                   d: _Design) -> SpringStepData:
        return SpringStepData(pred.q, pred.qd, read_only(pred.p, np.float64), np.array(coeffs),
                              loads(model, t, params), *d.fields)

    def make(t: float, pred: Any, params: dict[str, Any], coeffs: tuple[float, float, float]
             ) -> "CompiledSpringStep | None":
        if params["pv"].dtype != np.float64 or pred.q.dtype != np.float64 or pred.qd.dtype != np.float64:
            return None
        d = design(t, pred, params, coeffs)
        if d is None:
            return None
        return CompiledSpringStep(model, t, params, d, _step_data(t, pred, params, coeffs, d))
    return make


class CompiledSpringStep(CompiledStep):
    """One step of a spring network for :func:`.newton_core.newton_iterations`, compiled: the
    data of the step, and the conversion of what the iteration returns."""

    iteration = iteration
    march = march

    def __init__(self, model: "StructuralModel", t: float, params: dict[str, Any], design: _Design,
                 data: SpringStepData):
        super().__init__(data)
        self.model, self.t, self.params, self.design = model, t, params, design

    def loads(self, t: float) -> Array:
        return loads(self.model, t, self.params)

    def factor_buffers(self, steps: int) -> tuple[Array, ...]:
        # the iteration's last (K_t, q, q̇, q̈, S, LU, du2, pivots, regularity test), one row a step;
        # S's rows empty (not kept: its factor and K_t are what the sensitivities read)
        n, size = self.design.n, self.design.size
        return (np.empty((steps, size)), *(np.empty((steps, n)) for _ in range(3)), np.empty((steps, 0)),
                np.empty((steps, size)), np.empty((steps, max(n - 2, 0))), np.empty((steps, n), np.int32),
                np.empty((steps, 3)))

    def at_time(self, t: float) -> "CompiledSpringStep":
        return CompiledSpringStep(self.model, t, self.params, self.design, self.data)

    def linearization_and_factor(self, lf: tuple, counters: Counters, linearization: bool = True
                                 ) -> tuple[Any, Factor | None, None]:
        """(Linearization, Factor, S) of the iteration's last linearization (Factor None when S
        was not regular; the Linearization, the model's own at the state S was formed at, only
        with ``linearization``: the sensitivities need it, the primal steps do not; S None: the
        Python path's round-off test never reads a compiled step's)."""
        K, q, qd, qdd, S, lu, du2, piv, test = lf
        if not K.size:              # no linearization (a block's rows keep no S: K_t tells)
            return None, None, None
        d = self.design
        factor = None
        if test[0] == REGULAR:
            plan = d.plan
            if isinstance(plan, DenseStorage):      # getrf's LU by columns: its rows are LU's columns
                factor = Factor.from_compiled_lu(lu.reshape(d.n, d.n), piv, counters)
            else:
                factor = Factor.from_band(TridiagonalFactor.from_lu(plan, lu, du2, piv), counters)
        lin = None
        if linearization:
            # the model's linearization with the step's K_t: the same sums as its own assembly
            empty = np.zeros(0)
            lin = self.model.linearize(self.t, StepState(q, qd, qdd, empty, empty, empty), self.params,
                                       tangent=d.tangent_matrix(K))
        return lin, factor, None
