"""The residual and its linearization by the compiled kernel (:mod:`.compiled`,
:mod:`.compiled_linearization`): the compiled backend of :class:`.residual.Evaluation`, and
:func:`evaluate`, where the backend is chosen."""
from __future__ import annotations

from typing import TYPE_CHECKING, cast

import numpy as np

from ...errors import ModelError
from ..base import Linearization
from . import compiled as cc
from . import compiled_linearization as clin
from .kernel import Kin
from .kernel_compiled import CompiledKin
from .residual import Evaluation, NumpyEvaluation, other_forces_jacobians, other_forces_q, time_inputs

if TYPE_CHECKING:  # pragma: no cover
    from .model import MultibodyModel

Array = np.ndarray


class CompiledLinearization(Linearization):
    """A dense linearization of the compiled kernel: the iteration matrix is assembled by it
    too (one call instead of a handful of array operations per Newton iteration)."""

    def iteration_matrix(self, c_q: float, c_qd: float, c_p: float, n_q: int) -> Array:
        R_p = self.R_p if self.R_p is not None else np.zeros((self.R_z.shape[0], 0), self.R_z.dtype)
        return clin.iteration_matrix(self.R_z, self.R_q, self.R_qd, R_p, float(c_q), float(c_qd), float(c_p))



class CompiledEvaluation(Evaluation):
    """Constraint levels, force laws, forces and F_R in one compiled call, and the linearization
    by a second; ``inputs`` (cf, shift, ext, f_ext, g) per entry serve a block of steps at
    different times (:meth:`.model.MultibodyModel.residual_batch_steps`), otherwise the time
    functions are evaluated at t."""

    compiled = True

    def __init__(self, model: "MultibodyModel", kin: CompiledKin, t: float, lam: Array, p: Array, pd: Array,
                 inputs: tuple[Array, ...] | None = None):
        super().__init__(model, kin, t, lam, p, pd)
        self._given_inputs = inputs
        m, kp, lay = self.model, self.kp, self.model.layout
        kin = cast(CompiledKin, self.kin)   # the compiled path runs on compiled kinematics
        cl, ck, t, dt = kin.arrays, kin.params, self.t, kin.dtype
        if self._given_inputs is not None:
            cf, shift, ext, f_ext, g = self._given_inputs
        else:
            cf, shift = m.coefficients(t, kp)
            ext, f_ext, g = time_inputs(m, kp, t, dt)
        try:
            out = cc.forces_and_residual(
                kin.Lp, kin.Lr, kin.C, kin.ABV, kin.X, kin.N, cl.pb, cl.is_point, cl.side_ptr, cl.side_prim,
                cl.side_coef, cl.prod_eq, np.ascontiguousarray(cf, dt), np.ascontiguousarray(shift, dt),
                cl.norm_eq, cl.norm_body, cl.ax_kind, cl.ax_pidx, ck.ax_c, ext, f_ext, ck.mass, ck.J, g,
                np.ascontiguousarray(self.lam, dt), np.ascontiguousarray(self.p, dt),
                np.ascontiguousarray(self.pd, dt), float(m.scale), float(m.alpha),
                float(m.beta), cc.TG, cl.rot_prod, ck.rot_c)
        except ZeroDivisionError:
            raise zero_length_error(m, kin, t) from None
        (R, self.Phi, self.w, self.f, self._ax, self._Pp, _, self._hL, self._hLd, self._hp, self._rot) = out
        if m.other_forces and self._given_inputs is None:
            # (a block of steps at different times: Model.residual_batch_steps adds them per step)
            R[:, :lay.n_q] -= other_forces_q(m, t, kin.q, kin.qd, kp.prms)
        self.cf, self._R = cf, R

    def residual(self) -> Array:
        """F_R (B, n_z)."""
        return self._R

    def linearization(self) -> Linearization:
        """Exact ∂F_R/∂(z, q, q̇, p) of the first batch entry, by the compiled kernel; the axial
        laws' partials enter as arrays."""
        m, lay = self.model, self.model.layout
        kin = cast(CompiledKin, self.kin)   # the compiled path runs on compiled kinematics
        tr = m.traits
        cl, ck = kin.arrays, kin.params
        G = clin.product_rows(kin.C[0], kin.ABV[0], cl.pb, cl.is_point, cl.side_ptr, cl.side_prim,
                            cl.side_coef, tr.n_q)
        R_z, R_q, R_qd, R_p = clin.linearization(
            kin.Lp[0], kin.C[0], kin.ABV[0], G, cl.pb, cl.is_point, ck.Ts4[0], cl.side_ptr, cl.side_prim,
            cl.side_coef, lay.n_cp, cl.prod_eq, np.ascontiguousarray(self.cf[0], kin.dtype), m.eq_row_weights,
            m.norm_row_weights, cl.norm_eq, cl.norm_body, float(m.scale), self.w[0], self.f[0],
            np.asarray(self.lam[0], kin.dtype), ck.mass[0], ck.J[0], cc.TG, cl.ax_prod, self._ax[0], self._Pp[0],
            cl.p_owner, self._hL[0], self._hLd[0], self._hp[0], cl.rot_prod, self._rot[0])
        if m.other_forces:
            Kq, Kqd = other_forces_jacobians(m, self.t, kin.q[0], kin.qd[0], kin.kp.prms[0])
            R_q[:tr.n_q] -= Kq
            R_qd[:tr.n_q] -= Kqd
        return CompiledLinearization(R_z, R_q, R_qd, R_p if tr.n_p else None)


def zero_length_error(model: "MultibodyModel", kin: CompiledKin, t: float) -> ModelError:
    """The error of a step where an axial element's two points met: its length is zero and the
    direction of its force undefined (the compiled kernel divides by the length)."""
    lay = model.layout
    names = [el.name for i, el in enumerate(lay.axial)
             if not np.all(np.real(kin.X[:, lay.n_cp + i, 0]) > 0.0)]
    which = ", ".join(f"'{n}'" for n in names) if names else "an axial force element"
    return ModelError(f"at t = {t:.6g} s the two points of force {which} coincide: its length is zero and "
                      "the direction of its force undefined (keep the ends of a spring apart)")


def serves(model: "MultibodyModel", kin: Kin, lam: Array, p: Array, pd: Array) -> bool:
    """Whether the compiled kernel evaluates at this state: compiled kinematics, every force
    law compiled, and the multipliers and pressures in the kinematics' arithmetic (complex
    kinematics hold real ones too)."""
    return (isinstance(kin, CompiledKin) and model.layout.compiled_laws
            and (kin.dtype.kind == "c" or (lam.dtype.kind != "c" and p.dtype.kind != "c" and pd.dtype.kind != "c")))


def evaluate(model: "MultibodyModel", kin: Kin, t: float, lam: Array, p: Array, pd: Array,
             inputs: tuple[Array, ...] | None = None) -> Evaluation:
    """The residual pieces at one (batched) state, by the backend that serves it (chosen here,
    once for the evaluation; :func:`serves`).  Time inputs per entry (``inputs``) need the
    compiled kernel."""
    if serves(model, kin, lam, p, pd):
        return CompiledEvaluation(model, cast(CompiledKin, kin), t, lam, p, pd, inputs)
    if inputs is not None:
        raise ValueError("time inputs per entry need the compiled kernel")
    return NumpyEvaluation(model, kin, t, lam, p, pd)
