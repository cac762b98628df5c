"""What every compiled step shares: the compiled iteration, its cache key, the regularity codes.

A model family that runs :func:`~.newton_core.newton_iterations` compiled overloads the step
operations for a named tuple of its step's arrays (the multibody kernel's in
:mod:`dynsens.models.multibody.compiled_step`, spring networks' in
:mod:`dynsens.models.structural.step`) and compiles the iteration with :func:`compiled_iteration`.
numba caches the result on disk: the types of the arguments, not the model, select the overloads.
"""
from __future__ import annotations

import functools
import hashlib
import inspect
import sys
from pathlib import Path
from types import ModuleType
from typing import Any, Callable, Iterable

import numpy as np

from . import newton_core as core
from ._jit import jit, register_jitable
from .linalg import all_finite, pivot_test

# regularity of S as an iteration leaves it in its last factor: (code, column or 0, pivot ratio)
REGULAR, NON_FINITE_ENTRIES, ZERO_PIVOT, SMALL_PIVOT = 0, 1, 2, 3


def read_only(a: Any, dtype: Any = None) -> np.ndarray:
    """a as a C-contiguous read-only array (a view when it is one already in that dtype): a step's
    arrays are passed read-only, so that every model of a family shares one compiled signature."""
    a = np.ascontiguousarray(a, dtype)
    if a.flags.writeable:
        a = a.view()
        a.flags.writeable = False
    return a


def sources_stamp(modules: Iterable[ModuleType]) -> str:
    """A hash of the sources of ``modules`` and of those every compiled step inlines (the
    iteration, the newmark corrector, the factor's tests of :mod:`.linalg`).  numba's cache
    checks only the file of the function it compiles; a step inlines the iteration, its
    overloads and the model's kernels, so a change to any of them must select another cache
    entry (the stamp is part of the entry's key, as the contents of a closure are)."""
    from .. import __version__
    from ..integrators import newmark
    from . import linalg
    h = hashlib.sha256()
    for module in (core, newmark, linalg, sys.modules[__name__], *modules):
        try:
            h.update(Path(inspect.getfile(module)).read_bytes())
        except OSError:      # no source file to read (a frozen or zipped install): the version
            h.update(f"{module.__name__} {__version__}".encode())
    return h.hexdigest()


def step_kept(ops: Any, s: Any) -> Any:
    """What a model family computes, still compiled, at the state s an iteration ends at, for
    the Python that follows the step (the mechanisms: its kinematics, which the drift guard,
    the monitors and the event outputs read).  Each family overloads it; as Python it keeps
    nothing (the Python path's models evaluate what is asked when it is asked)."""
    return None


@register_jitable
def state_finite(s: Any) -> bool:
    """Whether every entry of the state s (the six leaves of a StepState) is finite."""
    return (all_finite(s[0]) and all_finite(s[1]) and all_finite(s[2]) and all_finite(s[3])
            and all_finite(s[4]) and all_finite(s[5]))


def dense_solver() -> Any:
    """A compiled step's dense LU (numba only; called where a family registers its overloads):
    ``factor_solve(lu, piv, x)`` factors the real (n, n) matrix whose column-major array is lu
    (C-ordered: its rows are the matrix's columns) in place, with pivots piv (n,) int32, solves
    for x (n,) in place, and returns the test of regularity (code, column of a zero pivot, pivot
    ratio), in the words of :class:`~.linalg.Factor`'s dense branch.  The routine is LAPACK's
    dgesv as scipy exports it (numba calls scipy's cython_lapack): dgetrf, then dgetrs, the
    routines scipy.linalg.lapack's getrf and getrs call for the Python path, so the factor and
    the solution are the same numbers."""
    from numba import types
    from numba.np.linalg import _LAPACK, ensure_lapack

    ensure_lapack()
    gesv = _LAPACK().numba_xgesv(types.float64)
    kind = ord("d")   # LAPACK's type character (passed as int8, as numba.np.linalg does)

    @register_jitable
    def factor_solve(lu, piv, x):  # type: ignore[no-untyped-def]
        n = piv.shape[0]
        test = np.zeros(3)              # (code, column of a zero pivot, pivot ratio)
        if not all_finite(lu):
            test[0] = NON_FINITE_ENTRIES
            return test
        info = gesv(np.int8(kind), n, 1, lu.ctypes, n, piv.ctypes, x.ctypes, n)
        if info > 0:
            test[0], test[1] = ZERO_PIVOT, info
        else:
            regular, ratio = pivot_test(np.diag(lu))
            if not regular:
                test[0], test[2] = SMALL_PIVOT, ratio
        return test
    return factor_solve


def compiled_iteration(stamp: str) -> Any:
    """:func:`~.newton_core.newton_iterations` compiled (the overloads of the step operations
    registered first), its cache entries keyed by ``stamp``; its result is followed by
    :func:`step_kept` at the state it ends at and by :func:`state_finite` of that state."""

    def iterate(ops, z, rtol, atol, reuse_tol, max_iterations, newton, sensitivities,  # type: ignore[no-untyped-def]
                scales, present, history):
        stamp          # noqa: B018 - a closure variable: part of numba's cache key
        out = core.newton_iterations(ops, z, rtol, atol, reuse_tol, max_iterations, newton, sensitivities,
                                     scales, present, history)
        return out + (step_kept(ops, out[4]), state_finite(out[4]))
    return jit(iterate)


def is_step_data(ops: Any, data_class: type) -> bool:
    """In an overload of a step operation: whether numba's type ``ops`` is the named tuple
    ``data_class`` (the model family the overload serves)."""
    from numba import types
    return isinstance(ops, types.BaseNamedTuple) and ops.instance_class is data_class


class LazyIteration:
    """A model family's compiled iteration, made on first use: ``register()`` (its overloads of
    the step operations) first, then ``build`` (:func:`compiled_iteration`, or
    :func:`.compiled_march.compiled_march` for blocks of steps) keyed by ``stamp()``."""

    def __init__(self, register: Callable[[], None], stamp: Callable[[], str],
                 build: Callable[[str], Any] = compiled_iteration):
        self._register, self._stamp, self._build = register, stamp, build
        self._compiled: Any = None

    def __call__(self) -> Any:
        if self._compiled is None:
            self._register()
            self._compiled = self._build(self._stamp())
        return self._compiled


class CompiledStep:
    """One step of a model family for :func:`~.newton_core.newton_iterations`, compiled: the
    step's data and the family's :class:`LazyIteration` (``iteration``, set by each family's
    subclass, which also turns the iteration's last factor into the Python path's objects);
    ``march``: the family's blocks of steps, which take this step's data as their template."""

    iteration: LazyIteration
    #: the family's compiled blocks of steps (:mod:`.compiled_march`), None where it has none;
    #: a family with blocks keeps nothing at a converged state (its :meth:`keep` is not called)
    march: LazyIteration | None = None

    def __init__(self, data: Any):
        self.data = data

    def iterate(self, *args: Any) -> tuple:
        """:func:`~.newton_core.newton_iterations` with this step's data (same arguments after
        ops), what :func:`step_kept` computed at the state it ended at, and whether that state is
        finite."""
        return type(self).iteration()(self.data, *args)  # type: ignore[no-any-return]

    # what the blocks of steps (:mod:`.compiled_march`) ask of a family with ``march``
    def loads(self, t: float) -> np.ndarray:
        """The external loads f_ext (n,) of the step's model and design at time t (s)."""
        raise NotImplementedError(f"{type(self).__name__} runs no blocks of steps")

    def factor_buffers(self, steps: int) -> tuple[np.ndarray, ...]:
        """Arrays of ``steps`` rows for the last linearization and factor of each step of a block
        (one row a step, as :func:`.compiled_march.store_factor` writes them)."""
        raise NotImplementedError(f"{type(self).__name__} runs no blocks of steps")

    def at_time(self, t: float) -> "CompiledStep":
        """This step's design at another step ending at time t (s): what turns that step's row of
        the factor buffers into the Python path's objects (:meth:`linearization_and_factor`)."""
        raise NotImplementedError(f"{type(self).__name__} runs no blocks of steps")

    def keep(self, s: Any, kept: Any) -> None:
        """Hand what :func:`step_kept` computed at the converged state s to the model (by
        default nothing)."""

    @staticmethod
    def state(s: tuple) -> Any:
        """The StepState of the iteration's state tuple."""
        return _step_state()._make(s)

    @staticmethod
    def singular_reason(lf: tuple) -> str:
        """Why S was not regular, in the words of :class:`~dynsens.solver.linalg.Factor` (the
        last entry of the factor tuple: its code, column and pivot ratio)."""
        return singular_reason(lf[-1])


@functools.cache
def _step_state() -> Any:
    # (models import the solver: the state type is looked up on first use, then kept)
    from ..models.base import StepState
    return StepState


def singular_reason(test: np.ndarray) -> str:
    """Why S was not regular, from a compiled factor's (code, column, pivot ratio), in the words
    of :class:`~dynsens.solver.linalg.Factor`."""
    code, col, ratio = test
    if code == NON_FINITE_ENTRIES:
        return "matrix has non-finite entries"
    if code == ZERO_PIVOT:
        return f"exactly zero pivot in column {int(col)}"
    return f"pivot ratio {ratio:.1e}"
