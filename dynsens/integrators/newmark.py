r"""Newmark-β and its α-family (HHT-α, generalized-α), acceleration as primary unknown.

Newmark (method.md §2): predictor from step i−1 and corrector with the new accelerations
(first-order states use the same γ-rule):

.. math::

   q^{pred} = q + Δt\,\dot q + (½-β)Δt^2 a, \qquad \dot q^{pred} = \dot q + (1-γ)Δt\,a,
   \qquad p^{pred} = p + (1-γ)Δt\,b

   q_i = q^{pred} + βΔt^2 a_i,\quad \dot q_i = \dot q^{pred} + γΔt\,a_i,\quad
   p_i = p^{pred} + γΔt\,b_i

For plain Newmark the "algorithmic" accelerations a, b are the true ones, q̈ and ṗ.  The
generalized-α method (Chung & Hulbert 1993, in the form of Arnold & Brüls 2007 that keeps
the equations of motion — and constraints — exactly at t_i) uses instead

.. math:: (1-α_m)\,a_i + α_m a_{i-1} = (1-α_f)\,\ddot q_i + α_f \ddot q_{i-1}

so a_i = c_a q̈_i + a_rest with c_a = (1−α_f)/(1−α_m).  Parameters from the spectral radius
at infinity ρ∞: α_m = (2ρ∞−1)/(ρ∞+1), α_f = ρ∞/(ρ∞+1), γ = ½ + α_f − α_m, β = ¼(γ+½)².
HHT-α is the member α_m = 0, α_f = α ∈ [0, ⅓] (γ = ½ + α, β = ¼(1+α)²); for linear problems
it coincides with the classical HHT scheme.  Second order for γ = ½ + α_f − α_m.

All maps are linear in the state, so the same code predicts and corrects the primal
vectors (n,) and the sensitivity matrices (n, m): the sensitivities are derived from the
scheme's own step equations.  The scheme also gives the transposes of these maps, which the
discrete adjoint (:mod:`dynsens.derivatives.adjoint`) runs backwards, the constants of its
local error estimates (:meth:`Newmark.error_constants`, read by the adaptive steps of
:mod:`dynsens.timeloop.step_sequence`) and its stability limit (:meth:`Newmark.stability_limit`, read by
:mod:`dynsens.timeloop.runchecks`).

Local error (Zienkiewicz & Xie 1991, extended to the α-family): for exact values at the start
of a step, the displacement update errs by C_q h³ q⃛ with C_q = β − 1/6 + (α_m − α_f)/2
(β − 1/6 for Newmark, 1/12 + (γ − ½)²/4 for the second-order α-members); the γ-rule of the
first-order states by C_p h³ p⃛ with C_p = 1/12 − (α_m − α_f)²/2 (the trapezoid rule's 1/12).

Stability for linear undamped problems: Newmark is unconditionally stable for 2β ≥ γ ≥ ½ and
otherwise stable for ω Δt ≤ Ω_crit = 1/sqrt(γ/2 − β) (Newmark 1959; Hughes, *The Finite Element
Method*, 1987, §9.1); HHT-α for α ∈ [0, ⅓] (Hilber, Hughes & Taylor 1977) and generalized-α for
α_m ≤ α_f ≤ ½, β ≥ ¼ + (α_f − α_m)/2 (Chung & Hulbert 1993) are unconditionally stable.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..models.base import StepState


class Aux(NamedTuple):
    """Algorithmic accelerations a (n_q) and rates b (n_p) carried from step to step."""

    a: np.ndarray
    b: np.ndarray


class Prediction(NamedTuple):
    """Predicted q, q̇, p and the parts of the new algorithmic accelerations known before the solve."""

    q: np.ndarray
    qd: np.ndarray
    p: np.ndarray
    a_rest: np.ndarray | float   # 0.0 for plain Newmark (α_m = α_f = 0)
    b_rest: np.ndarray | float


@dataclass(frozen=True)
class Newmark:
    """Newmark-β (α_m = α_f = 0) or a generalized-α member; β, γ, α_m, α_f dimensionless."""

    beta: float = 0.25
    gamma: float = 0.5
    alpha_m: float = 0.0
    alpha_f: float = 0.0
    name: str = "newmark"

    @property
    def order(self) -> int:
        """Order of accuracy: 2 when γ = ½ + α_f − α_m, else 1."""
        return 2 if abs(self.gamma - 0.5 - self.alpha_f + self.alpha_m) < 1e-12 else 1

    @property
    def c_a(self) -> float:
        """c_a = (1 − α_f)/(1 − α_m): ∂a/∂q̈ of the algorithmic accelerations (1 for plain Newmark)."""
        return (1.0 - self.alpha_f) / (1.0 - self.alpha_m)

    def start(self, s: StepState) -> Aux:
        """Algorithmic accelerations at t0: the true ones."""
        return Aux(s.qdd, s.pd)

    def coefficients(self, dt: float) -> tuple[float, float, float]:
        """(c_q, c_qd, c_p) = (∂q/∂q̈, ∂q̇/∂q̈, ∂p/∂ṗ) of the corrector for step size dt (s)."""
        return corrector_coefficients(dt, self.beta, self.gamma, self.c_a)

    def predict(self, s: StepState, aux: Aux, dt: float) -> Prediction:
        """Predictor from the state at the previous step (vectors or (n, m) matrices)."""
        b, g, am, af = self.beta, self.gamma, self.alpha_m, self.alpha_f
        if am == 0.0 and af == 0.0:
            # plain Newmark: no remainder terms (the predictor is evaluated every step, also for
            # the (n, m) sensitivity matrices)
            return Prediction(*predict_arrays(s.q, s.qd, s.p, aux.a, aux.b, dt, b, g), 0.0, 0.0)
        return Prediction(*predict_alpha_arrays(s.q, s.qd, s.qdd, s.p, s.pd, aux.a, aux.b, dt, b, g, am, af))

    def correct(self, pred: Prediction, qdd: np.ndarray, lam: np.ndarray, pd: np.ndarray,
                dt: float) -> StepState:
        """New state from the prediction and the new unknowns z = (q̈, λ, ṗ)."""
        c_q, c_qd, c_p = self.coefficients(dt)
        q, qd, p = correct_arrays(pred.q, pred.qd, pred.p, c_q, c_qd, c_p, qdd, pd)
        return StepState(q, qd, qdd, lam, p, pd)

    def advance(self, pred: Prediction, s: StepState) -> Aux:
        """Algorithmic accelerations of the new step."""
        return Aux(*advance_arrays(pred.a_rest, pred.b_rest, s.qdd, s.pd, self.c_a))

    # ------------------------------------------------------------------ transposes (adjoint)
    # Each is the transpose of the linear map of the same name: for the forward map A and any
    # u, v, <A u, v> = <u, Aᵀ v> (tests/test_scheme_algebra.py).  Bars are vectors or (n, r)
    # matrices, one column per response.

    def start_transpose(self, aux_bar: Aux, s_bar: StepState) -> StepState:
        """Transpose of :meth:`start` (a0 = q̈0, b0 = ṗ0): ``s_bar`` plus the bars of a0, b0
        moved onto q̈0 and ṗ0."""
        q, qd, qdd, lam, p, pd = s_bar
        return StepState(q, qd, qdd + aux_bar.a, lam, p, pd + aux_bar.b)

    def advance_transpose(self, aux_bar: Aux, s_bar: StepState) -> tuple[StepState, Aux]:
        """Transpose of :meth:`advance` (a = a_rest + c_a q̈, b = b_rest + c_a ṗ): ``s_bar`` plus
        c_a times the bars of a, b on q̈, ṗ, and the bars of the prediction's a_rest, b_rest
        (as an :class:`Aux`; the other fields of the prediction :meth:`advance` does not read)."""
        s, rest = advance_transpose_arrays(tuple(s_bar), tuple(aux_bar), self.c_a)
        return StepState(*s), Aux(*rest)

    def correct_transpose(self, s_bar: StepState, dt: float
                          ) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, ...]]:
        """Transpose of :meth:`correct` for step size dt (s): the bars of the prediction's
        q, q̇, p (its a_rest, b_rest the corrector does not read) and of the unknowns
        z = (q̈, λ, ṗ)."""
        return correct_transpose_arrays(tuple(s_bar), *self.coefficients(dt))

    def predict_transpose(self, pred_bar: Prediction, dt: float, lam_bar: np.ndarray) -> tuple[StepState, Aux]:
        """Transpose of :meth:`predict` for step size dt (s): the bars of the previous state
        and of its algorithmic accelerations.  The predictor does not read λ: its bar is
        ``lam_bar`` (zeros of λ's shape, passed in since the scheme does not know the sizes)."""
        s, aux = predict_transpose_arrays(pred_bar.q, pred_bar.qd, pred_bar.p, pred_bar.a_rest, pred_bar.b_rest,
                                          lam_bar, dt, self.beta, self.gamma, self.alpha_m, self.alpha_f)
        return StepState(*s), Aux(*aux)

    # ------------------------------------------------------------------ error and stability
    def error_constants(self) -> tuple[float, float]:
        """(C_q, C_p): the local error of a step is C_q h³ q⃛ in q and C_p h³ p⃛ in p (module
        docstring); the adaptive steps estimate h q⃛ by the change of the algorithmic
        accelerations."""
        delta = self.alpha_m - self.alpha_f
        return self.beta - 1.0 / 6.0 + 0.5 * delta, 1.0 / 12.0 - 0.5 * delta * delta

    @property
    def unconditionally_stable(self) -> bool:
        """Whether the scheme is stable for every step size on linear undamped problems."""
        return math.isinf(self.stability_limit())

    def stability_limit(self) -> float:
        """Ω_crit: the scheme is stable on a linear undamped problem for ω Δt ≤ Ω_crit (ω: its
        highest natural frequency, rad/s); ``inf`` when it is unconditionally stable, 0 when it
        is stable for no step (Newmark with γ < ½).  Raises ValueError for an α-member outside
        the unconditionally stable range, whose limit has no closed form here."""
        beta, gamma, am, af = self.beta, self.gamma, self.alpha_m, self.alpha_f
        if am == 0.0 and af == 0.0:
            if gamma < 0.5:
                return 0.0
            if not beta < gamma / 2:
                return math.inf
            return float(1.0 / np.sqrt(gamma / 2 - beta))
        if self.order == 2 and am <= af <= 0.5 and beta >= 0.25 + 0.5 * (af - am):
            return math.inf
        raise ValueError(f"the {self.name} scheme with alpha_m = {am:g}, alpha_f = {af:g}, beta = {beta:g}, "
                         f"gamma = {gamma:g} is outside the unconditionally stable range of the alpha family "
                         "(alpha_m <= alpha_f <= 1/2, beta >= 1/4 + (alpha_f - alpha_m)/2, second order): "
                         "its stability limit has no closed form here")


# The scheme's maps as functions of arrays and numbers: the methods above call them, and so do
# the compiled steps (Newton's and the sensitivities'), so each map has one definition.

def corrector_coefficients(dt: float, beta: float, gamma: float, c_a: float) -> tuple[float, float, float]:
    """(c_q, c_q̇, c_p) of the corrector for step size dt (s); c_a = (1 − α_f)/(1 − α_m)."""
    return beta * dt * dt * c_a, gamma * dt * c_a, gamma * dt * c_a


def predict_arrays(q: np.ndarray, qd: np.ndarray, p: np.ndarray, a: np.ndarray, b: np.ndarray, dt: float,
                   beta: float, gamma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Plain Newmark's predicted (q, q̇, p) from the previous step's state and algorithmic
    accelerations a, b (vectors or (n, m) matrices), step size dt (s)."""
    return (q + dt * qd + (dt * dt * (0.5 - beta)) * a, qd + (dt * (1.0 - gamma)) * a,
            p + (dt * (1.0 - gamma)) * b)


def predict_alpha_arrays(q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, p: np.ndarray, pd: np.ndarray,
                         a: np.ndarray, b: np.ndarray, dt: float, beta: float, gamma: float, alpha_m: float,
                         alpha_f: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """An α-member's predicted (q, q̇, p) and the parts (a_rest, b_rest) of the new algorithmic
    accelerations known before the solve, from the previous step's state, its accelerations q̈,
    ṗ and algorithmic accelerations a, b (vectors or (n, m) matrices), step size dt (s)."""
    a_rest = (alpha_f * qdd - alpha_m * a) / (1.0 - alpha_m)
    b_rest = (alpha_f * pd - alpha_m * b) / (1.0 - alpha_m)
    return (q + dt * qd + dt * dt * ((0.5 - beta) * a + beta * a_rest),
            qd + dt * ((1.0 - gamma) * a + gamma * a_rest),
            p + dt * ((1.0 - gamma) * b + gamma * b_rest), a_rest, b_rest)


def advance_arrays(a_rest: np.ndarray | float, b_rest: np.ndarray | float, qdd: np.ndarray, pd: np.ndarray,
                   c_a: float) -> tuple[np.ndarray, np.ndarray]:
    """The new algorithmic accelerations (a, b) = (a_rest + c_a q̈, b_rest + c_a ṗ)."""
    if c_a == 1.0:
        return a_rest + qdd, b_rest + pd
    return a_rest + c_a * qdd, b_rest + c_a * pd


def advance_transpose_arrays(s_bar: tuple, aux_bar: tuple, c_a: float) -> tuple[tuple, tuple]:
    """Transpose of :func:`advance_arrays`: the state's bars ``s_bar`` (q, q̇, q̈, λ, p, ṗ) with
    c_a times the bars of a, b (``aux_bar``) added to q̈, ṗ, and the bars of a_rest, b_rest."""
    q, qd, qdd, lam, p, pd = s_bar
    a, b = aux_bar
    return (q, qd, qdd + c_a * a, lam, p, pd + c_a * b), (a, b)


def correct_transpose_arrays(s_bar: tuple, c_q: float, c_qd: float, c_p: float) -> tuple[tuple, tuple]:
    """Transpose of :func:`correct_arrays` with its coefficients: the bars of the predicted
    (q, q̇, p) and of the unknowns (q̈, λ, ṗ), from the state's bars ``s_bar``."""
    q, qd, qdd, lam, p, pd = s_bar
    return (q, qd, p), (qdd + c_q * q + c_qd * qd, lam, pd + c_p * p)


def predict_transpose_arrays(pq: np.ndarray, pqd: np.ndarray, pp: np.ndarray, a_rest_bar: np.ndarray | float,
                             b_rest_bar: np.ndarray | float, lam_bar: np.ndarray, dt: float, beta: float, gamma: float,
                             alpha_m: float, alpha_f: float) -> tuple[tuple, tuple]:
    """Transpose of the predictor (:func:`predict_arrays`, :func:`predict_alpha_arrays`) for
    step size dt (s): from the bars of the predicted (q, q̇, p) and of a_rest, b_rest, the bars
    of the previous state (λ's: ``lam_bar``) and of its algorithmic accelerations (a, b)."""
    h, am, af = dt, alpha_m, alpha_f
    # a_rest = (α_f q̈ − α_m a)/(1 − α_m) is read by q^pred and q̇^pred; b_rest likewise
    a_rest = a_rest_bar + (h * h * beta) * pq + (h * gamma) * pqd
    b_rest = b_rest_bar + (h * gamma) * pp
    s_bar = (pq, h * pq + pqd, (af / (1.0 - am)) * a_rest, lam_bar, pp, (af / (1.0 - am)) * b_rest)
    aux_bar = ((h * h * (0.5 - beta)) * pq + (h * (1.0 - gamma)) * pqd - (am / (1.0 - am)) * a_rest,
               (h * (1.0 - gamma)) * pp - (am / (1.0 - am)) * b_rest)
    return s_bar, aux_bar


def correct_arrays(q_pred: np.ndarray, qd_pred: np.ndarray, p_pred: np.ndarray, c_q: float, c_qd: float,
                   c_p: float, qdd: np.ndarray, pd: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q, q̇, p) = (q_pred + c_q q̈, q̇_pred + c_q̇ q̈, p_pred + c_p ṗ): the corrector of every
    scheme here (also compiled into a model's step)."""
    # a model without first-order states (pd empty) keeps the predicted empty p: two numpy
    # calls fewer per Newton iteration, where per-call cost dominates small models
    p = p_pred + c_p * pd if pd.size else p_pred
    return q_pred + c_q * qdd, qd_pred + c_qd * qdd, p


SCHEMES = ("newmark", "hht", "generalized_alpha")


def make_scheme(name: str, beta: float | None = None, gamma: float | None = None, *,
                alpha: float | None = None, rho_inf: float | None = None) -> Newmark:
    """Build the time-integration scheme named in a case.

    ``newmark`` takes β, γ (default ¼, ½): γ < ½ is rejected (negative numerical damping,
    unstable), β < γ/2 warns (only conditionally stable), γ > ½ warns (numerical damping, first
    order).  ``hht`` takes α with |α| ≤ ⅓ in either sign convention: dynsens' α ∈ [0, ⅓]
    (weights the end-of-step forces by 1 − α) or Hilber–Hughes–Taylor's original
    α_HHT = −α ∈ [−⅓, 0]; the two ranges meet only at 0, so the sign tells which one is meant.
    ``generalized_alpha`` takes ρ∞ ∈ [0, 1].  A parameter the named scheme does not use
    (β or γ with hht or generalized_alpha, α with newmark or generalized_alpha, ρ∞ with
    newmark or hht) is an error, never silently ignored.
    """
    if name not in SCHEMES:
        raise ValueError(f"unknown scheme {name!r} (known: {', '.join(SCHEMES)})")
    uses = {"newmark": ("beta", "gamma"), "hht": ("alpha",), "generalized_alpha": ("rho_inf",)}[name]
    given = {"beta": beta, "gamma": gamma, "alpha": alpha, "rho_inf": rho_inf}
    ignored = [k for k, v in given.items() if v is not None and k not in uses]
    if ignored:
        derived = {"hht": "β = (1 + α)²/4 and γ = ½ + α follow from α",
                   "generalized_alpha": "β, γ, α_m and α_f follow from ρ∞",
                   "newmark": "β and γ set it"}[name]
        raise ValueError(f"integrator.{', integrator.'.join(ignored)} given, but the {name} scheme does "
                         f"not use {'it' if len(ignored) == 1 else 'them'} ({derived}; its "
                         f"parameter{'s are' if len(uses) > 1 else ' is'} {', '.join(uses)}): remove "
                         f"{'it' if len(ignored) == 1 else 'them'} or choose the scheme that uses "
                         f"{'it' if len(ignored) == 1 else 'them'}")
    if name == "hht":
        a = 0.05 if alpha is None else alpha
        if not -1.0 / 3.0 <= a <= 1.0 / 3.0:
            raise ValueError(f"integrator.alpha = {a}: HHT-alpha needs |alpha| <= 1/3; dynsens reads "
                             "alpha in [0, 1/3] (end-of-step forces weighted by 1 - alpha) and also "
                             "accepts the original convention alpha_HHT = -alpha in [-1/3, 0]")
        a = abs(a)      # the original (negative) convention: α_HHT = −α
        return Newmark(beta=0.25 * (1 + a) ** 2, gamma=0.5 + a, alpha_m=0.0, alpha_f=a, name="hht")
    if name == "generalized_alpha":
        r = 0.8 if rho_inf is None else rho_inf
        if not 0.0 <= r <= 1.0:
            raise ValueError(f"integrator.rho_inf = {r}: must be in [0, 1] (spectral radius at infinity)")
        am = (2 * r - 1) / (r + 1)
        af = r / (r + 1)
        g = 0.5 + af - am
        return Newmark(beta=0.25 * (g + 0.5) ** 2, gamma=g, alpha_m=am, alpha_f=af, name="generalized_alpha")
    beta = 0.25 if beta is None else beta
    gamma = 0.5 if gamma is None else gamma
    if gamma < 0.5:
        raise ValueError(f"integrator.gamma = {gamma}: must be >= 0.5 (gamma < 1/2 gives "
                         "negative numerical damping and an unstable scheme)")
    if beta < 0:
        raise ValueError(f"integrator.beta = {beta}: must be >= 0")
    if beta > 1.0 or gamma > 1.0:
        # q = q_pred + β Δt² q̈: a huge β makes q̈ round-off, and the run's numbers and gradients
        # meaningless while they stay finite (β = 1e300 ran "successfully")
        name, value = ("beta", beta) if beta > 1.0 else ("gamma", gamma)
        raise ValueError(f"integrator.{name} = {value}: must be <= 1 (Newmark's useful range: beta in "
                         "[gamma/2, 1], gamma in [1/2, 1]; the trapezoidal rule is beta = 1/4, gamma = 1/2)")
    if beta < gamma / 2:
        warnings.warn(f"integrator.beta = {beta} < gamma/2 = {gamma / 2}: Newmark is only "
                      "conditionally stable; keep dt below the stability limit or use beta = 1/4",
                      stacklevel=2)
    if gamma > 0.5:
        warnings.warn(f"integrator.gamma = {gamma} > 1/2 adds numerical damping and the scheme "
                      "is only first-order accurate", stacklevel=2)
    return Newmark(beta=beta, gamma=gamma)


__all__ = ["SCHEMES", "Aux", "Newmark", "Prediction", "make_scheme"]
