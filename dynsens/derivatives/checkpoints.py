"""The step records the adjoint sweep needs: all of them while they fit a memory budget,
otherwise checkpoints and segments recomputed during the sweep.

The grid steps are grouped in segments of L steps, L chosen from the size of the first step
record so that one segment holds about half the budget.  After each segment the stepper's
checkpoint is kept (state, the scheme's algorithmic accelerations, the Newton solver's
convergence memory: a few state vectors).  While the records held stay within the budget they
are all kept; beyond it the oldest segments give up their records (their linearizations and
factors).  The sweep takes the segments in reverse order and re-runs a dropped one forward from
its checkpoint first: the same arithmetic on the same inputs, so the records — and the gradient
— are bit-identical to those of a run that kept them (tests/test_adjoint.py,
test_checkpointing_recomputes_segments_bit_identically).
"""
from __future__ import annotations

import weakref
from typing import Any, Callable, Iterator

import numpy as np
import scipy.sparse as sp

from ..solver.linalg import Counters, Factor
from ..timeloop.stepping import PrimalStepper, StepRecord

DEFAULT_MEMORY_BUDGET = 2 * 2**30     # bytes (sensitivity.memory_budget default: 2 GiB)


def _matrix_bytes(a: Any) -> int:
    """Memory of a linearization's block (bytes): dense, sparse (its stored arrays) or None."""
    if a is None:
        return 0
    if isinstance(a, np.ndarray):       # (first: counted for every record of a dense model)
        return a.nbytes
    if sp.issparse(a):
        a = a.tocsr() if not hasattr(a, "indices") else a
        indptr = getattr(a, "indptr", None)
        return int(a.data.nbytes + a.indices.nbytes + (0 if indptr is None else indptr.nbytes))
    return int(np.asarray(a).nbytes)


def factor_bytes(f: Factor | None) -> int:
    """Memory held by a factor (bytes)."""
    return 0 if f is None else f.nbytes


class RecordStore:
    """Step records for the backward sweep, within ``budget`` bytes (see the module docstring).

    Parameters
    ----------
    stepper : the run's primal stepper (for checkpoints and recomputation).
    grid : (t_prev, h) of grid step i (1-based), as the forward loop took it.
    budget : bytes of records (linearizations, factors, states) held at most (soft: a segment
        is never split).
    counters : the run's counters (recomputation is counted apart, in ``recomputed_steps``).
    """

    def __init__(self, stepper: PrimalStepper, grid: Callable[[int], tuple[float, float]], budget: float,
                 counters: Counters):
        self.stepper, self.grid, self.budget, self.counters = stepper, grid, budget, counters
        self.initial: StepRecord | None = None
        self.segment_steps = 0                        # L, set from the first step record
        # per segment: first grid step, checkpoint before it, its records (None once dropped)
        self.segments: list[tuple[int, Any, list[StepRecord] | None]] = []
        self.segment_bytes: list[int] = []
        self.held = 0
        self.peak = 0                                 # most bytes of records held at once
        self.n_grid = 0
        # the linearizations and factors counted, while they live: an id alone would be taken
        # again by a new object once a dropped segment's records are freed
        self._seen: weakref.WeakValueDictionary[int, Any] = weakref.WeakValueDictionary()
        self.dropped = 0

    def _bytes(self, rec: StepRecord) -> int:
        """Memory a record adds: its state, and its linearization and factor unless shared."""
        n = 0
        for v in rec.state:
            n += v.nbytes
        lin = rec.lin
        if self._first_time(lin):
            n += _matrix_bytes(lin.R_z) + _matrix_bytes(lin.R_q) + _matrix_bytes(lin.R_qd) + _matrix_bytes(lin.R_p)
        if self._first_time(rec.factor):
            n += factor_bytes(rec.factor)
        return n

    def _first_time(self, obj: Any) -> bool:
        """Whether ``obj`` (a linearization or factor, or None) is not counted yet; marks it."""
        if obj is None or self._seen.get(id(obj)) is obj:
            return False
        self._seen[id(obj)] = obj
        return True

    def add_initial(self, rec: StepRecord) -> None:
        """The record of the initial solve (always kept)."""
        self.initial = rec
        self._bytes(rec)
        self.n_grid = 1
        self.segments.append((1, self.stepper.snapshot(rec.state), []))
        self.segment_bytes.append(0)

    def add_step(self, records: list[StepRecord]) -> None:
        """The records of the next grid step; a checkpoint when it closes a segment."""
        size = sum(self._bytes(r) for r in records)
        if not self.segment_steps:
            self.segment_steps = max(1, int(0.5 * self.budget // max(size, 1)))
        first, cp, held = self.segments[-1]
        assert held is not None
        held.extend(records)
        self.segment_bytes[-1] += size
        self.held += size
        self.n_grid += 1
        if self.n_grid - first >= self.segment_steps:          # the segment is complete
            self.segments.append((self.n_grid, self.stepper.snapshot(records[-1].state), []))
            self.segment_bytes.append(0)
        self.peak = max(self.peak, self.held)
        k = 0
        while self.held > self.budget and k < len(self.segments) - 1:
            if self.segments[k][2] is not None:
                self.held -= self.segment_bytes[k]
                self.segments[k] = (self.segments[k][0], self.segments[k][1], None)
                self.dropped += 1
            k += 1

    def _recompute(self, first: int, checkpoint: Any, last: int) -> list[StepRecord]:
        """Grid steps first..last again from the checkpoint (work counted apart)."""
        stepper = self.stepper
        scratch = Counters()
        saved = stepper.counters, stepper.solver.counters
        stepper.counters = stepper.solver.counters = scratch
        try:
            s = stepper.restore(checkpoint)
            out: list[StepRecord] = []
            for i in range(first, last + 1):
                t_prev, h = self.grid(i)
                recs = stepper.advance(i, t_prev, h, s)
                s = recs[-1].state
                out.extend(recs)
        finally:
            stepper.counters, stepper.solver.counters = saved
        self.counters.recomputed_steps += len(out)
        return out

    def backward(self) -> Iterator[tuple[int, StepRecord, int | None]]:
        """(index, record, grid step it closes or None) from the last record to the initial one
        (index 0)."""
        for k in range(len(self.segments) - 1, -1, -1):
            first, cp, held = self.segments[k]
            last = self.segments[k + 1][0] - 1 if k + 1 < len(self.segments) else self.n_grid - 1
            if last < first:
                continue
            records = held if held is not None else self._recompute(first, cp, last)
            for j in range(len(records) - 1, -1, -1):
                rec = records[j]
                closes = j == len(records) - 1 or records[j + 1].step != rec.step
                yield 1, rec, (rec.step if closes else None)
            if held is None:
                del records
        assert self.initial is not None
        yield 0, self.initial, 0
