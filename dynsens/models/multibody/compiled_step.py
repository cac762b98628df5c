r"""The Newton iteration of a step of a compiled mechanism, without returning to the interpreter.

:func:`dynsens.solver.newton_core.newton_iterations` is compiled for :class:`StepData`, a
named tuple of a step's arrays: the prediction and coefficients of the scheme's corrector, the
compiled kernel's layout and parameters (:mod:`.compiled`) and the time inputs of the step.
The step operations are overloaded here for it:

* the state is the scheme's corrector (:func:`dynsens.integrators.newmark.correct_arrays`);
* F_R is :func:`.compiled.kinematics` and :func:`.compiled.forces_and_residual`, and its
  linearization and S are :mod:`.compiled_linearization`'s: the functions the Python path calls;
* S is factored and solved by LAPACK gesv (getrf, then getrs: the calls, and so the numbers, of
  the Python path's :class:`~dynsens.solver.linalg.Factor`), with the same tests of regularity
  (:func:`~dynsens.solver.compiled_iteration.dense_solver`, shared with the spring networks').

It serves a mechanism whose every force element has a compiled law (spring-dampers, cylinders,
rotational spring-dampers; no Python force elements),
in real arithmetic, with a dense iteration matrix; other runs take the same iteration in Python.
numba caches it on disk: the types of its arguments, not the model, select the overloads.
"""
from __future__ import annotations

import sys
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from ...integrators.newmark import correct_arrays
from ...solver import newton_core as core
from ...solver.banded import DENSE_BAND_MIN_N
from ...solver.compiled_iteration import CompiledStep as CompiledStepBase
from ...solver.compiled_iteration import (REGULAR, LazyIteration, dense_solver, is_step_data, read_only,
                                         sources_stamp, step_kept)
from ...solver.linalg import Counters, Factor
from . import compiled as cc
from . import compiled_linearization as clin
from .residual import time_inputs
from .residual_compiled import CompiledLinearization

if TYPE_CHECKING:  # pragma: no cover
    from .model import MultibodyModel

Array = np.ndarray

class StepData(NamedTuple):
    """What one step of a compiled mechanism reads (see :mod:`.compiled`): the step's own
    arrays first, then those of the model and design (kept between steps).  Every array but the
    prediction is read-only, so that all mechanisms share one compiled signature."""

    q_pred: Array
    qd_pred: Array
    p_pred: Array
    coeffs: Array            # (c_q, c_q̇, c_p)
    cf: Array                # time coefficients and shifts of the constraints
    shift: Array
    ext: Array               # element inputs and applied point forces at t
    f_ext: Array
    sizes: Array             # (n_q, n_λ, n_p, n_cp)
    blocks: Array            # (start, stop) of the present blocks of z, (k, 2)
    pb: Array
    is_point: Array
    Ts4: Array
    side_ptr: Array
    side_prim: Array
    side_coef: Array
    cAB: Array
    norm_body: Array
    norm_eq: Array
    prod_eq: Array
    ax_kind: Array
    ax_pidx: Array
    ax_c: Array
    mass: Array
    J: Array
    gravity: Array
    weights: Array           # (scale, α, β) of the constraint rows
    eq_row_weights: Array
    norm_row_weights: Array
    ax_prod: Array
    p_owner: Array
    TG: Array
    rot_prod: Array
    rot_c: Array


def _is_step_data(ops: Any) -> bool:
    return is_step_data(ops, StepData)


def _register() -> None:
    """The overloads of the step operations for StepData (numba only)."""
    from numba.extending import overload

    dense_factor_solve = dense_solver()
    correct = cc.inline(correct_arrays)

    @overload(core.step_correct)
    def _correct(ops, z):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops, z):  # type: ignore[no-untyped-def]
            n_q, n_lam = ops.sizes[0], ops.sizes[1]
            c = ops.coeffs
            q, qd, p = correct(ops.q_pred, ops.qd_pred, ops.p_pred, c[0], c[1], c[2], z[:n_q],
                               z[n_q + n_lam:])
            return q, qd, z[:n_q], z[n_q:n_q + n_lam], p, z[n_q + n_lam:]
        return impl

    def kinematics(ops, s):  # type: ignore[no-untyped-def]
        q, qd, qdd = s[0], s[1], s[2]
        return cc.kinematics(q.reshape(1, -1), qd.reshape(1, -1), np.ascontiguousarray(qdd).reshape(1, -1),
                             ops.pb, ops.is_point, ops.Ts4, ops.side_ptr, ops.side_prim, ops.side_coef, ops.cAB,
                             ops.norm_body)
    kinematics = cc.inline(kinematics)

    @overload(step_kept)
    def _kept(ops, s):  # type: ignore[no-untyped-def]
        if _is_step_data(ops):          # of the converged state: the drift guard's, the outputs'
            return lambda ops, s: kinematics(ops, s)

    @overload(core.step_residual)
    def _residual(ops, s):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops, s):  # type: ignore[no-untyped-def]
            q, qd, qdd, lam, p, pd = s
            Lp, Lr, C, PV, ABV, X, N = kinematics(ops, s)
            w = ops.weights
            R, Phi, W, F, AX, Pp, H, HL, HLd, Hp, RT = cc.forces_and_residual(
                Lp, Lr, C, ABV, X, N, ops.pb, ops.is_point, ops.side_ptr, ops.side_prim, ops.side_coef,
                ops.prod_eq, ops.cf, ops.shift, ops.norm_eq, ops.norm_body, ops.ax_kind, ops.ax_pidx,
                ops.ax_c, ops.ext, ops.f_ext, ops.mass, ops.J, ops.gravity, np.ascontiguousarray(lam).reshape(1, -1),
                np.ascontiguousarray(p).reshape(1, -1), np.ascontiguousarray(pd).reshape(1, -1), w[0], w[1],
                w[2], ops.TG, ops.rot_prod, ops.rot_c)
            return R[0], (Lp, C, ABV, W, F, AX, Pp, HL, HLd, Hp, RT)
        return impl

    @overload(core.step_no_factor)
    def _no_factor(ops):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops):  # type: ignore[no-untyped-def]
            e2 = np.zeros((0, 0))
            return e2, e2, e2, e2, e2, e2, np.zeros(0, np.int32), np.zeros(0), np.zeros(3)
        return impl

    @overload(core.step_factor_solve)
    def _factor_solve(ops, s, evaluation, rhs):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops, s, evaluation, rhs):  # type: ignore[no-untyped-def]
            lam = s[3]
            Lp, C, ABV, W, F, AX, Pp, HL, HLd, Hp, RT = evaluation
            n_q, n_cp = ops.sizes[0], ops.sizes[3]
            G = clin.product_rows(C[0], ABV[0], ops.pb, ops.is_point, ops.side_ptr, ops.side_prim,
                                  ops.side_coef, n_q)
            R_z, R_q, R_qd, R_p = clin.linearization(
                Lp[0], C[0], ABV[0], G, ops.pb, ops.is_point, ops.Ts4[0], ops.side_ptr, ops.side_prim,
                ops.side_coef, n_cp, ops.prod_eq, ops.cf[0], ops.eq_row_weights, ops.norm_row_weights,
                ops.norm_eq, ops.norm_body, ops.weights[0], W[0], F[0], np.ascontiguousarray(lam), ops.mass[0],
                ops.J[0], ops.TG, ops.ax_prod, AX[0], Pp[0], ops.p_owner, HL[0], HLd[0], Hp[0], ops.rot_prod,
                RT[0])
            c = ops.coeffs
            S = clin.iteration_matrix(R_z, R_q, R_qd, R_p, c[0], c[1], c[2])
            n = S.shape[0]
            lu = S.T.copy()                  # S in column-major order: LAPACK's
            piv = np.zeros(n, np.int32)
            x = rhs.copy()
            test = dense_factor_solve(lu, piv, x)
            return test[0] == REGULAR, (R_z, R_q, R_qd, R_p, S, lu, piv, x, test), x
        return impl

    @overload(core.step_at_roundoff)
    def _at_roundoff(ops, lf, R, z, rnorm):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops, lf, R, z, rnorm):  # type: ignore[no-untyped-def]
            S = lf[4]
            return S.size > 0 and core.dense_at_roundoff(S, R, z, rnorm)
        return impl

    @overload(core.step_block_norms)
    def _block_norms(ops, z, dz):  # type: ignore[no-untyped-def]
        if not _is_step_data(ops):
            return None

        def impl(ops, z, dz):  # type: ignore[no-untyped-def]
            k = ops.blocks.shape[0]
            zn, dzn = np.empty(k), np.empty(k)
            for i in range(k):
                a, b = ops.blocks[i, 0], ops.blocks[i, 1]
                zn[i], dzn[i] = core.real_norm(z[a:b]), core.real_norm(dz[a:b])
            return zn, dzn
        return impl


def _sources_stamp() -> str:
    """The cache key of the compiled iteration: the sources it inlines (the overloads here, the
    kernels and force laws)."""
    from . import forces, hydraulics, rotational
    return sources_stamp((cc, clin, forces, hydraulics, rotational, sys.modules[__name__]))


# the compiled iteration (the overloads registered first)
_iterate = LazyIteration(_register, _sources_stamp)


def step_factory(model: "MultibodyModel", newton: bool, refactor: bool) -> Any:
    """For :meth:`.model.MultibodyModel.compiled_step`: the :class:`CompiledStep` of a step, or
    None for a step it does not serve (complex data); None for a model it does not serve: not
    the compiled kernel with a compiled law for every force element, no constraints (then S
    may be diagonal), a sparse S or one that the Python path would factor as a band."""
    tr = model.traits
    if not (newton and refactor and cc.enabled() and model.layout.compiled_laws and not model.other_forces
            and not tr.sparse and tr.n_lam > 0 and tr.n_z < DENSE_BAND_MIN_N):
        return None
    from .kernel import kernel_params
    from .kernel_compiled import compiled_params
    lay = model.layout
    sizes = (tr.n_q, tr.n_lam, tr.n_p)
    starts = np.cumsum((0,) + sizes)
    blocks = np.array([(starts[k], starts[k + 1]) for k in range(3) if sizes[k]], dtype=np.intp)
    kept: dict[int, tuple[Any, tuple[Array, ...]]] = {}      # per parameter set: its kept fields

    def design_fields(params: Any, kp: Any, g: Array) -> tuple[Array, ...]:
        hit = kept.get(id(params))
        if hit is not None and hit[0] is params:
            return hit[1]
        cl, ck = lay.compiled_arrays(), compiled_params(kp, np.float64)
        fields = tuple(read_only(a) for a in (
            np.array([tr.n_q, tr.n_lam, tr.n_p, lay.n_cp]), blocks, cl.pb, cl.is_point, ck.Ts4, cl.side_ptr,
            cl.side_prim, cl.side_coef, ck.cAB, cl.norm_body, cl.norm_eq, cl.prod_eq, cl.ax_kind, cl.ax_pidx,
            ck.ax_c, ck.mass, ck.J, g, np.array([model.scale, model.alpha, model.beta], float),
            model.eq_row_weights, model.norm_row_weights, cl.ax_prod, cl.p_owner, cc.TG, cl.rot_prod, ck.rot_c))
        kept.clear()        # one design at a time (a run's)
        kept[id(params)] = (params, fields)
        return fields

    views: list[tuple[Array | None, Array | None]] = [(None, None)] * 4    # (source, read-only view)

    def read_only_kept(k: int, a: Array) -> Array:
        # cf, shift, ext and f_ext are mostly the same arrays from step to step (constant in time)
        source, view = views[k]
        if source is not a:
            views[k] = source, view = a, read_only(a, np.float64)
        return view  # type: ignore[return-value]

    f64 = np.dtype(np.float64)

    def make(t: float, pred: Any, params: Any, coeffs: tuple[float, float, float]) -> CompiledStep | None:
        kp = kernel_params(lay, params)
        if not (kp.pv.dtype == pred.q.dtype == pred.qd.dtype == pred.p.dtype == f64):
            return None
        cf, shift = model.coefficients(t, kp)
        ext, f_ext, g = time_inputs(model, kp, t, np.float64)      # (g: the same at every t)
        step = (pred.q, pred.qd, pred.p, np.array(coeffs), read_only_kept(0, cf), read_only_kept(1, shift),
                read_only_kept(3, ext), read_only_kept(2, f_ext))
        return CompiledStep(model, StepData._make(step + design_fields(params, kp, g)), params)
    return make


class CompiledStep(CompiledStepBase):
    """One step of a mechanism for :func:`.newton_core.newton_iterations`, compiled: the data
    of the step, and the conversion of what the iteration returns."""

    iteration = _iterate

    def __init__(self, model: "MultibodyModel", data: StepData, params: Any):
        super().__init__(data)
        self.model, self.params = model, params

    def keep(self, s: Any, kept: tuple) -> None:
        """The kinematics of the converged state s, to the model's cache of kinematics."""
        self.model.keep_kinematics(s, self.params, kept)

    def linearization_and_factor(self, lf: tuple, counters: Counters, linearization: bool = True
                                 ) -> tuple[Any, Factor | None, Array]:
        """(Linearization, Factor, S) of the iteration's last linearization (Factor None when S
        was not regular); both only with ``linearization``: the sensitivities need them, the
        primal steps do not."""
        R_z, R_q, R_qd, R_p, S, lu, piv, _, test = lf
        if not linearization:
            return None, None, S
        lin = CompiledLinearization(R_z, R_q, R_qd, R_p if self.model.traits.n_p else None)
        factor = Factor.from_compiled_lu(lu, piv, counters) if test[0] == REGULAR and S.size else None
        return lin, factor, S
