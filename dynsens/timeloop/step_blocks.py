"""Primal steps taken ahead in compiled blocks, handed out one record at a time.

Where the derivative mode reads the step records only, never the solver between steps (all
three modes: :attr:`~dynsens.derivatives.mode.DerivativeMode.steps_ahead`), the steps of a grid
known beforehand (fixed or replayed: :meth:`.step_sequence.StepSequence.ahead`) can run ahead of
the time loop: one compiled call (:mod:`dynsens.solver.compiled_march`) predicts, iterates,
corrects and advances up to :data:`BLOCK_STEPS` steps, keeping each step's last linearization
and factor when sensitivities follow, and the loop receives their records one by one, as if
each had just been taken.  What follows a step in Python (the model's projection and range
checks, the runaway monitor, the histories, the responses and their event watch) runs when its
record is handed out, in order, so a run stopped by an event or an error reports the same step as
before; the steps computed beyond it are dropped.

A block stops before a step it cannot take as it is (Newton failed, a singular matrix, a
non-finite state, a spring whose ends met): that step is taken again by the Python path, with
its step cuts and messages, and the next block starts after it.  The records are the per-step
path's bit for bit (tests/test_step_blocks.py); without sensitivities they carry no
linearization or factor (nothing reads them).
"""
from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from ..integrators.newmark import Aux
from ..models.base import StepState
from ..solver.compiled_march import BLOCK_STOPPED

if TYPE_CHECKING:  # pragma: no cover
    from .stepping import PrimalStepper, StepRecord

#: grid steps a block takes at most (the histories of a block are kept until handed out),
#: and the bytes of its states and factors at most (a large model takes fewer steps a block)
BLOCK_STEPS = 64
BLOCK_BYTES = 16 * 2**20
#: bytes of one step's factor above which a run with sensitivities takes its steps one at a
#: time: copying the factor out of the block costs more than the Python a block saves (the
#: 10 000-DOF chain, 1 MB a step, was no faster in blocks; the 1 000-mass chain, 0.1 MB, was)
FACTOR_BYTES_MAX = 256 * 2**10

#: the grid ahead of a step: (i, t_prev, count) -> [(t_prev, h)] of grid steps i, i + 1, ... (s),
#: or None where it is not known before the steps are taken
GridAhead = Callable[[int, float, int], "list[tuple[float, float]] | None"]


class StepBlocks:
    """The blocks of one run's stepper: :meth:`take` hands out the record of grid step i, from
    the queue of the last block or from a new one, or None where the step is the Python path's."""

    def __init__(self, stepper: "PrimalStepper", ahead: GridAhead):
        self.stepper, self.ahead = stepper, ahead
        self.queue: deque[tuple[Any, ...]] = deque()
        self.last: StepState | None = None        # the state of the last record handed out
        self.python_step = 0                     # a grid step a block stopped before
        self.off = False                         # the run's steps have no compiled blocks

    def take(self, i: int, t_prev: float, h: float, s: StepState) -> "StepRecord | None":
        """The record of grid step i from the state s at t_prev by h (s), or None: the Python
        path takes it (a block stopped before it, or the model runs no blocks at this step)."""
        if self.queue and not (s is self.last and self.queue[0][:3] == (i, t_prev, h)):
            self.queue.clear()                    # (the run went elsewhere: the queue is stale)
        if not self.queue:
            if self.off or i == self.python_step or not self._fill(i, t_prev, h, s):
                return None
        return self._hand_out(*self.queue.popleft())

    def _hand_out(self, i: int, t_prev: float, h: float, t: float, state: StepState, aux: Aux,
                  counts: np.ndarray, scales: np.ndarray, compiled: Any, lf: tuple | None) -> "StepRecord":
        stepper = self.stepper
        status, iterations, n_res, n_lin, fresh = counts.tolist()
        out = stepper.solver.compiled_outcome(compiled.at_time(t) if lf is not None else compiled, t, state,
                                              stepper.params, stepper.scheme.coefficients(h), status, iterations,
                                              lf, bool(fresh), n_res, n_lin, scales)
        record = stepper._accept(i, t, h, out)
        stepper.aux = aux
        self.last = record.state
        return record

    def _fill(self, i: int, t_prev: float, h: float, s: StepState) -> bool:
        """Run a block from grid step i; whether it took a step (the queue holds its records)."""
        stepper = self.stepper
        solver, scheme, params = stepper.solver, stepper.scheme, stepper.params
        aux, ahead = stepper.aux, self.ahead(i, t_prev, BLOCK_STEPS)
        assert aux is not None
        compiled = None
        if ahead:
            # each step ends at t_prev + h, as the per-step path's (PrimalStepper._solve)
            grid = [(tp, hk, tp + hk) for tp, hk in ahead]
            pred = scheme.predict(s, aux, h)
            compiled = solver.compiled_for(grid[0][2], pred, params, scheme.coefficients(h))
        if compiled is None or compiled.march is None:
            # (decided by the model, the design and the step sequence: the same for the whole run)
            self.off = True
            return False
        keep = solver.sensitivities        # the records carry their linearization and factor
        leaves = [np.ascontiguousarray(v, np.float64) for v in (*s, *aux)]
        factor_bytes = sum(f.nbytes for f in compiled.factor_buffers(1)) if keep else 0
        if factor_bytes > FACTOR_BYTES_MAX:
            self.off = True
            return False
        # a large model takes fewer steps a block: its states and factors within BLOCK_BYTES
        per_step = sum(v.nbytes for v in leaves) + factor_bytes
        K = max(1, min(len(grid), BLOCK_BYTES // max(per_step, 1)))
        grid = grid[:K]
        hs = np.array([g[1] for g in grid])
        f_ext = np.stack([compiled.loads(g[2]) for g in grid])
        out = tuple(np.empty((K, v.shape[0])) for v in leaves) + (np.zeros((K, 5), np.int64), np.empty((K, 3)))
        factors = compiled.factor_buffers(K if keep else 0)     # (no rows: one compiled signature)
        done = np.zeros(1, np.intp)
        try:
            taken, how = compiled.march()(compiled.data, *leaves, hs, f_ext, scheme.beta, scheme.gamma,
                                          scheme.alpha_m, scheme.alpha_f, scheme.c_a, *solver.iteration_arguments(),
                                          out, factors, done)
        except ZeroDivisionError:        # a law divided by zero: the Python path names the element
            taken, how = int(done[0]), BLOCK_STOPPED
        for k in range(taken):
            state = StepState(*(x[k] for x in out[:6]))
            lf = tuple(f[k] for f in factors) if keep else None
            self.queue.append((i + k, *grid[k], state, Aux(out[6][k], out[7][k]), out[8][k], out[9][k],
                               compiled, lf))
        self.python_step = i + taken if how == BLOCK_STOPPED else 0
        if taken:
            self.last = s
        return taken > 0
