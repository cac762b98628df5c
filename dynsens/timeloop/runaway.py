"""The runaway monitor: a run whose state grows without bound is stopped while it is finite.

An unstable scheme (explicit Newmark past its stability limit) or a model that is physically
unstable (a negative stiffness) grows geometrically: by the time it overflows to Inf, the
response history has long been meaningless (values of 1e223 were stored before).  The
monitor compares, per accepted step, |q|∞ and |q̇|∞ with their largest values over the early
part of the run: the initial state and the first quarter to half of the steps taken since the
state first moved (the window doubles with the run: O(1) time and memory per step), and, for
|q|, the size the model's data imply (``Model.displacement_scale``: geometry, static
deflection under the loads), so that a response that starts from tiny values is not mistaken
for a runaway while it is still small against the structure.  A
response that starts from rest grows like a power of t (a step load: t², a ramp: t³), i.e. by
a factor 4ⁿ at most against that window; a geometric growth grows without limit.  The run is
stopped when both |q| and |q̇| exceed RUNAWAY_FACTOR times their early scale.
"""
from __future__ import annotations

import numpy as np

from ..errors import NonFiniteError
from ..models.base import Model, StepState

#: growth of |q|∞ and |q̇|∞ beyond their early-run scale at which a run is stopped
RUNAWAY_FACTOR = 1e6
#: every STRIDE-th accepted step is looked at (a runaway takes hundreds of steps from 1e6 times
#: its scale to overflow; a look costs a small share of a step, BENCHMARKS.md)
STRIDE = 4
#: looks after the state first moved before the first verdict: the window then holds at least
#: four looks, so one value at round-off (a load switched on between grid points, ~1e-31)
#: cannot be the whole scale
MIN_LOOKS = 8


def _maxabs(v: np.ndarray) -> float:
    return float(abs(v).max()) if v.size else 0.0


class RunawayMonitor:
    """Watches |q|∞ and |q̇|∞ of the accepted steps of one run (see the module docstring)."""

    def __init__(self, model: Model, s0: StepState, q_scale: float = 0.0):
        self.model = model
        self.ref = [max(_maxabs(s0.q), q_scale), _maxabs(s0.qd)]   # the early scale (initial state first)
        self.pending = [0.0, 0.0]                         # running max at the last window mark
        self.run = [0.0, 0.0]                             # running max since the state moved
        self.count = 0                                    # steps since the state moved
        self.mark = 1                                     # next window mark (doubles)
        self.tick = 0

    def observe(self, t: float, step: int, s: StepState) -> None:
        """Look at every STRIDE-th accepted state (see :meth:`look`)."""
        self.tick += 1
        if self.tick == STRIDE:
            self.tick = 0
            self.look(t, step, s)

    def look(self, t: float, step: int, s: StepState) -> None:
        """Check the accepted state s at time t (s); raise NonFiniteError on runaway growth."""
        q, qd = _maxabs(s.q), _maxabs(s.qd)
        if self.count == 0 and q == 0.0 and qd == 0.0:
            return                                        # still at rest: no scale yet
        self.count += 1
        run = self.run
        run[0], run[1] = max(run[0], q), max(run[1], qd)
        ref = self.ref
        if self.count == self.mark:                       # the window moves on: the scale of
            ref[0], ref[1] = max(ref[0], self.pending[0]), max(ref[1], self.pending[1])
            self.pending = [run[0], run[1]]               # the first quarter to half of the run
            self.mark *= 2
        if self.count >= MIN_LOOKS and q > RUNAWAY_FACTOR * ref[0] and qd > RUNAWAY_FACTOR * ref[1] \
                and ref[0] > 0.0 and ref[1] > 0.0:
            k = int(np.argmax(abs(s.q)))
            raise NonFiniteError(
                f"the solution grows without bound: |q| = {q:.3g} at {self.model.describe_equation(k)} "
                f"at t = {t:.6g} s (step {step}), more than {RUNAWAY_FACTOR:.0e} times its largest value "
                f"early in the run (|q| <= {ref[0]:.3g}, |dq/dt| <= {ref[1]:.3g}); the run is stopped before "
                "it overflows to NaN/Inf. Check the stiffness signs, the load magnitudes and the time step")
