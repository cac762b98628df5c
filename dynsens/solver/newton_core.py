r"""The Newton iteration of one step (method.md §3), defined once for every backend.

:func:`newton_iterations` is the iteration: correct, evaluate F_R, test, linearize and factor
S, solve, test again.  It reaches the model and the linear algebra only through the step
operations below (``step_*``), and is written in the subset of Python that numba compiles:

* run as Python, the operations are the methods of a Python object
  (:class:`~dynsens.solver.newton.StepSolver` hands one per step: any model, any matrix kind,
  real or complex);
* compiled, the operations are numba overloads for a model family's data (a named tuple of
  arrays; :mod:`dynsens.models.multibody.compiled_step`), and the whole step runs without
  returning to the interpreter.

The tests of convergence are functions here, the same for both.  What the iteration ends in
is a status code; the caller turns it into the outcome or the error message, in Python.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ._jit import HAVE_NUMBA, enabled, jit, register_jitable

# Componentwise backward error below which a residual is round-off (≈ 500 ε).
ROUNDOFF = 1e-13
# the bound of the round-off test's quick rejection, widened by more than its rounding error
ROUNDOFF_BOUND_MARGIN = 1.01

# how an iteration ends (the caller's reading of each is in StepSolver.solve_step)
CONVERGED, AT_ROUNDOFF, SOLVED_LINEAR, NOT_FINITE, SINGULAR, NOT_CONVERGED = range(6)


# ----------------------------------------------------------------------------- step operations
# Each is the method of the same name of a Python step object; a compiled model family
# overloads them for its data (numba.extending.overload), so these bodies run in Python only.

def step_correct(ops: Any, z: np.ndarray) -> Any:
    """The state at the unknowns z (the scheme's corrector)."""
    return ops.correct(z)


def step_residual(ops: Any, s: Any) -> tuple[np.ndarray, Any]:
    """(F_R at s, what its linearization may reuse)."""
    return ops.residual(s)


def step_factor_solve(ops: Any, s: Any, evaluation: Any, rhs: np.ndarray) -> tuple[bool, Any, np.ndarray]:
    """(whether S at s is regular, its linearization and factor, S⁻¹ rhs)."""
    return ops.factor_solve(s, evaluation, rhs)


def step_no_factor(ops: Any) -> Any:
    """The linearization-and-factor value before the first one (of the same type)."""
    return ops.no_factor()


def step_at_roundoff(ops: Any, lf: Any, R: np.ndarray, z: np.ndarray, rnorm: float) -> bool:
    """Whether every residual entry is within round-off of the terms S z that make it up."""
    return ops.at_roundoff(lf, R, z, rnorm)


def step_block_norms(ops: Any, z: np.ndarray, dz: np.ndarray) -> tuple[Any, Any]:
    """2-norms of the real parts of the present blocks (q̈, λ, ṗ) of z and of dz."""
    return ops.block_norms(z, dz)


# ----------------------------------------------------------------------------- tests
def _real_norm(v: np.ndarray) -> float:
    """2-norm of the real part, scaled so that huge entries do not overflow the sum of squares."""
    if not v.size:
        return 0.0
    r = v.real
    n = math.sqrt(float(r @ r))
    if 0.0 < n < 1e150:             # the common case: no overflow or underflow to guard
        return n
    big = float(np.max(np.abs(r)))
    if big == 0.0 or not math.isfinite(big):
        return big
    return big * float(np.linalg.norm(r / big))


_NORM: list[Any] = []       # the compiled norm for Python callers, or None (decided on first use)


def real_norm(v: np.ndarray) -> float:
    """:func:`_real_norm`: inlined into a compiled step, and for Python callers the same
    compiled function where compiled code is enabled.  The sum of squares is a BLAS dot product,
    and numba calls scipy's BLAS where numpy calls its own: where the two are different builds
    (the oldest supported numpy and scipy) they may differ in the last bit, and a norm decides
    when Newton stops.  (Complex or strided data, which only the Python path sees, stay with
    numpy.)"""
    if not _NORM:
        _NORM.append(jit(_real_norm) if enabled() else None)
    norm = _NORM[0]
    if norm is None or v.dtype.kind != "f" or not v.flags.c_contiguous:
        return _real_norm(v)
    return norm(v)


if HAVE_NUMBA:
    from numba.extending import overload

    @overload(real_norm)
    def _real_norm_compiled(v: np.ndarray) -> Any:    # (numba compares the annotations too)
        return _real_norm


@register_jitable
def above_roundoff_bound(rnorm: float, entries: np.ndarray, z: np.ndarray) -> bool:
    """The round-off test's quick rejection: |R_i| ≤ c·ε·(|S| |z|)_i for every row implies
    ‖R‖₂ ≤ c·ε·‖S‖_F ‖z‖₂, so a residual norm rnorm above that bound (with a margin for the
    bound's own rounding) fails the test without forming |S| |z|; entries: the stored entries of
    S when each is the matrix's own (dense, or sparse without duplicates)."""
    return rnorm > ROUNDOFF_BOUND_MARGIN * ROUNDOFF * real_norm(entries) * real_norm(z)


@register_jitable
def within_roundoff(R: np.ndarray, terms: np.ndarray) -> bool:
    """|Re R_i| ≤ c·ε·terms_i for every row i, terms = |Re S| |Re z| (Oettli–Prager)."""
    return bool(np.all(np.abs(R.real) <= ROUNDOFF * terms))


@register_jitable
def dense_at_roundoff(S: np.ndarray, R: np.ndarray, z: np.ndarray, rnorm: float) -> bool:
    """The round-off test of a compiled step with a dense real S (n, n): the quick rejection
    on all of S's entries, then |R_i| ≤ c·ε·(|S| |z|)_i with numpy's (BLAS) product."""
    if above_roundoff_bound(rnorm, S.ravel(), z):
        return False
    return within_roundoff(R, np.abs(S) @ np.abs(z))


@register_jitable
def within(ops: Any, z: np.ndarray, dz: np.ndarray, rtol: float, atol: float, scales: Any,
           present: Any) -> bool:
    """‖Δz_b‖ ≤ rtol·max(‖z_b‖, scale_b) + atol for every present block b (present: the
    indices k of the blocks; a list, or an array when compiled); scales (3,) holds the largest
    block norms of z so far in the run and is updated here.  A block that has been
    exactly zero so far (accelerations of a static start) has no scale of its own: its
    correction is measured against the whole unknown vector."""
    ok = True
    zn, dzn = step_block_norms(ops, z, dz)
    for i in range(len(present)):
        k = present[i]
        scales[k] = max(scales[k], zn[i])
        ref = max(zn[i], scales[k]) if scales[k] > 0 else real_norm(z)
        if dzn[i] > rtol * ref + atol:
            ok = False
    return ok


@register_jitable
def stagnated(history: np.ndarray, n: int, z: np.ndarray, dz: np.ndarray, rtol: float,
              atol: float) -> bool:
    """Newton at the noise floor: the last two of the n residual norms in history are not below
    half the best one before them, while the whole correction is within the tolerance of ‖z‖.
    A block that is nothing but round-off (the accelerations of a static start, ~1e-11 against
    multipliers of 1e7) can meet neither its own relative test nor the round-off test."""
    if n < 3:
        return False
    floor = 0.5 * min(history[:n - 2])
    return history[n - 1] > floor and history[n - 2] > floor and \
        real_norm(dz) <= rtol * real_norm(z) + atol


# ----------------------------------------------------------------------------- the iteration
@register_jitable
def newton_iterations(ops: Any, z: np.ndarray, rtol: float, atol: float, reuse_tol: float,
                      max_iterations: int, newton: bool, sensitivities: bool, scales: Any,
                      present: Any, history: np.ndarray) -> tuple:
    """Newton-Raphson on F_R(z) = 0 from the guess z (n_z,), with the tolerances of
    :class:`~dynsens.solver.newton.NewtonSettings`; scales and present as in :func:`within`,
    updated in place as is history (max_iterations,).

    Returns (status, iterations, z, dz, s, R, lf, fresh, residual_evaluations,
    linearizations): the status code, the iterations the outcome counts, the last unknowns and
    correction, the state at z, the last residual, the last linearization and factor, whether
    that factor serves the sensitivity solve (its iterate is one correction within the reuse
    tolerance of s) and the work done.
    """
    dz = np.zeros_like(z)   # the last correction; read only from the second iteration on
    lf = step_no_factor(ops)
    n_res = n_lin = 0
    for it in range(1, max_iterations + 1):
        s = step_correct(ops, z)
        R, evaluation = step_residual(ops, s)
        n_res += 1
        rnorm = real_norm(R)
        history[it - 1] = rnorm
        if not math.isfinite(rnorm):
            return NOT_FINITE, it, z, dz, s, R, lf, False, n_res, n_lin
        if it > 1 and step_at_roundoff(ops, lf, R, z, rnorm):
            # each residual entry is within round-off of the terms that make it up (Oettli-
            # Prager backward error): no correction can improve z, whatever the conditioning.
            # The last factor is one correction dz away from z
            fresh = sensitivities and within(ops, z, dz, reuse_tol, atol, scales, present)
            return AT_ROUNDOFF, it - 1, z, dz, s, R, lf, fresh, n_res, n_lin
        regular, lf, step = step_factor_solve(ops, s, evaluation, -R)
        n_lin += 1
        if not regular:
            return SINGULAR, it, z, dz, s, R, lf, False, n_res, n_lin
        dz = step
        z = z + dz
        if not newton:
            return SOLVED_LINEAR, it, z, dz, step_correct(ops, z), R, lf, True, n_res, n_lin
        if within(ops, z, dz, rtol, atol, scales, present) or stagnated(history, it, z, dz, rtol, atol):
            return CONVERGED, it, z, dz, step_correct(ops, z), R, lf, True, n_res, n_lin
    return NOT_CONVERGED, max_iterations, z, dz, step_correct(ops, z), R, lf, False, n_res, n_lin
