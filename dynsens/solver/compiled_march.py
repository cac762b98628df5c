r"""Blocks of primal steps compiled: predict, iterate, correct and advance, step after step,
without returning to the interpreter.

:func:`march_steps` is the stepper's sequence of a step (:class:`~dynsens.timeloop.stepping.PrimalStepper`:
Newmark's predictor, :func:`.newton_core.newton_iterations`, the corrector, the new algorithmic
accelerations) over the steps of a block, composed of the same functions the Python path calls
(:func:`~dynsens.integrators.newmark.predict_arrays` or, for the α-methods, ``predict_alpha_arrays``,
``corrector_coefficients``, ``advance_arrays``, the iteration).  A model family serves it by overloading one more step
operation, :func:`step_with` (its step's data at a new prediction and load); what the block
returns becomes the stepper's records in Python (:mod:`dynsens.timeloop.step_blocks`).

A block stops early at the first step it cannot accept as it is: a Newton iteration that did
not converge, a singular matrix, a non-finite state.  It returns how many steps it took; the
Python path takes the failing step again, with its step cuts and its error messages.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..integrators.newmark import advance_arrays, corrector_coefficients, predict_alpha_arrays, predict_arrays
from . import newton_core as core
from ._jit import jit, register_jitable
from .compiled_iteration import state_finite

# how a block ended: every step taken, or stopped before the step it returns
BLOCK_DONE, BLOCK_STOPPED = 0, 1

# the scheme's maps, callable from compiled code as they are (the same functions the Python path calls)
for _scheme_map in (predict_arrays, predict_alpha_arrays, corrector_coefficients, advance_arrays):
    register_jitable(_scheme_map)


def step_with(ops: Any, q_pred: np.ndarray, qd_pred: np.ndarray, p_pred: np.ndarray, coeffs: np.ndarray,
              f_ext: np.ndarray) -> Any:
    """The step data of a model family (``ops``: the data of another step of the run) at the
    prediction (q, q̇, p), corrector coefficients (c_q, c_q̇, c_p) and loads f_ext (n,) of a new
    step.  Each family that runs blocks overloads it; as Python it is never called."""
    raise NotImplementedError("step_with runs compiled only (a model family's overload)")


def store_factor(ops: Any, lf: Any, factors: tuple, k: int) -> None:
    """Copy the linearization-and-factor value ``lf`` an iteration ended with into row k of the
    family's buffers ``factors`` (:meth:`~.compiled_iteration.CompiledStep.factor_buffers`).
    Each family that runs blocks overloads it; as Python it is never called."""
    raise NotImplementedError("store_factor runs compiled only (a model family's overload)")


def _march_steps(template, q, qd, qdd, lam, p, pd, a, b, h, f_ext, beta, gamma, alpha_m, alpha_f, c_a,  # type: ignore[no-untyped-def]
                 rtol, atol, reuse_tol, max_iterations, newton, sensitivities, scales, present, history,
                 out, factors, done):
    """Take the steps of sizes h (K,) (s) of the scheme (β, γ, α_m, α_f, c_a) from the state
    (q, q̇, q̈, λ, p, ṗ) and algorithmic accelerations (a, b), loads f_ext (K, n); Newton's settings as in
    :func:`.newton_core.newton_iterations`.  ``out`` holds the results, row k for step k: the six
    state leaves, a, b (each (K, size)), then (K, 5) int: the iteration's status, iterations,
    residual evaluations, linearizations and whether its last factor is fresh, and (K, 3)
    float: the block scales after the step; with ``sensitivities``, the last linearization and
    factor of each step go to the family's buffers ``factors`` (:func:`store_factor`).
    ``done[0]`` counts the steps taken as they are taken (read when a step raises).

    Returns (steps taken, BLOCK_DONE or BLOCK_STOPPED)."""
    plain = alpha_m == 0.0 and alpha_f == 0.0
    a_rest, b_rest = np.zeros_like(a), np.zeros_like(b)     # plain Newmark: nothing known before the solve
    for k in range(h.shape[0]):
        if plain:
            q_pred, qd_pred, p_pred = predict_arrays(q, qd, p, a, b, h[k], beta, gamma)
        else:
            q_pred, qd_pred, p_pred, a_rest, b_rest = predict_alpha_arrays(q, qd, qdd, p, pd, a, b, h[k], beta,
                                                                           gamma, alpha_m, alpha_f)
        c_q, c_qd, c_p = corrector_coefficients(h[k], beta, gamma, c_a)
        ops = step_with(template, q_pred, qd_pred, p_pred, np.array((c_q, c_qd, c_p)), f_ext[k])
        z = np.concatenate((qdd, lam, pd))
        result = core.newton_iterations(ops, z, rtol, atol, reuse_tol, max_iterations, newton, sensitivities,
                                        scales, present, history)
        status, s = result[0], result[4]
        accepted = status == core.CONVERGED or status == core.AT_ROUNDOFF or status == core.SOLVED_LINEAR
        if not accepted or not state_finite(s):
            return k, BLOCK_STOPPED
        q, qd, qdd, lam, p, pd = s
        a, b = advance_arrays(a_rest, b_rest, qdd, pd, c_a)
        out[0][k], out[1][k], out[2][k], out[3][k], out[4][k], out[5][k] = q, qd, qdd, lam, p, pd
        out[6][k], out[7][k] = a, b
        out[8][k, 0], out[8][k, 1], out[8][k, 2], out[8][k, 3] = status, result[1], result[8], result[9]
        out[8][k, 4] = result[7]
        out[9][k] = scales
        if sensitivities:
            store_factor(template, result[6], factors, k)
        done[0] = k + 1
    return h.shape[0], BLOCK_DONE


march_steps = register_jitable(_march_steps)


def compiled_march(stamp: str) -> Any:
    """:func:`march_steps` compiled (a family's overloads registered first), its cache entries
    keyed by ``stamp`` (:func:`~.compiled_iteration.sources_stamp`)."""

    def march(template, q, qd, qdd, lam, p, pd, a, b, h, f_ext, beta, gamma, alpha_m, alpha_f, c_a,  # type: ignore[no-untyped-def]
              rtol, atol, reuse_tol, max_iterations, newton, sensitivities, scales, present, history, out,
              factors, done):
        stamp          # noqa: B018 - a closure variable: part of numba's cache key
        return march_steps(template, q, qd, qdd, lam, p, pd, a, b, h, f_ext, beta, gamma, alpha_m, alpha_f, c_a,
                           rtol, atol,
                           reuse_tol, max_iterations, newton, sensitivities, scales, present, history, out,
                           factors, done)
    return jit(march)
