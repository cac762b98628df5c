"""What the time loop asks of a derivative mode: the :class:`DerivativeMode` protocol.

The loop (:func:`dynsens.timeloop.march.integrate`) takes the primal steps and hands their records to
one mode object; it never asks which mode runs.  Three modes implement the protocol:

* :class:`~dynsens.derivatives.direct.DirectMode` carries the sensitivities forward, trailing
  the state by a block of records, and feeds them to the responses;
* :class:`~dynsens.derivatives.adjoint.AdjointMode` keeps the records and sweeps back over them
  once the responses know their adjoint weights;
* :class:`PrimalOnlyMode` computes no derivatives (a run without sensitivities).

Implementer contract:

1. ``name`` is the mode as ``RunResult.method`` reports it ("" for no derivatives);
   ``reason`` says why it was chosen.
2. ``start(rec)`` takes the initial record (the solve at t0) and returns the sensitivities of
   the initial state, or None when the mode carries none forward.
3. ``bind_responses(responses, params)`` starts the run's responses with what they need of the
   mode (the design partials of a forward mode, the trace of the outputs of a backward one).
4. ``take_step(records)`` takes the records of one grid step, in order; ``catch_up()`` returns
   the sensitivities of every record taken since the last call (None entries when the mode
   carries none), so the responses can be fed; the loop calls it at least every
   ``trail_length`` grid steps and at every event.
5. ``finish_responses(responses, design, m, mass)`` returns the responses' final values and
   gradients (a backward mode sweeps here).
6. ``steps_ahead`` says whether the primal steps may be taken ahead of the mode, in compiled
   blocks (:mod:`dynsens.timeloop.step_blocks`): true for a mode that reads the records only
   (their states, linearizations and factors: a block's records carry the same), never the
   stepper or the solver between steps.
"""
from __future__ import annotations

from typing import Any, Callable, Protocol

import numpy as np

from ..models.base import Model, StepState
from ..responses.response_set import ResponseSet
from ..responses.base import ResponseValue
from ..timeloop.stepping import StepRecord

#: the mass response's value and gradient, evaluated when a response asks
MassOf = Callable[[], tuple[Any, np.ndarray | None]]


class DerivativeMode(Protocol):
    """A derivative mode as the time loop sees it (module docstring: the contract)."""

    name: str
    reason: str
    trail_length: int
    steps_ahead: bool

    def start(self, rec: StepRecord) -> StepState | None:
        """The initial record; the sensitivities of the initial state (or None)."""
        ...

    def bind_responses(self, responses: ResponseSet, params: Any) -> None:
        """Start the run's responses at the parameters ``params`` of the design."""
        ...

    def take_step(self, records: list[StepRecord]) -> None:
        """The records of one grid step."""
        ...

    def catch_up(self) -> list[StepState | None]:
        """The sensitivities of the records taken since the last call, in order."""
        ...

    def finish_responses(self, responses: ResponseSet, design: dict[str, Any], m: int,
                         mass: MassOf) -> dict[str, ResponseValue]:
        """The responses' final values and gradients with respect to the m design variables."""
        ...


class PrimalOnlyMode:
    """No derivatives: the responses take values only, every grid step as it comes."""

    name = ""
    reason = ""
    trail_length = 1
    steps_ahead = True       # it reads the records' states only

    def __init__(self, model: Model):
        self.model = model
        self._pending = 0

    def start(self, rec: StepRecord) -> None:
        """Nothing to start: no sensitivities."""
        return None

    def bind_responses(self, responses: ResponseSet, params: Any) -> None:
        """Responses without partials and without a trace."""
        responses.start(params, None, self.model.stack_parameters([params]), self.model.traits.n_z)

    def take_step(self, records: list[StepRecord]) -> None:
        """Count the records (their sensitivities are all None)."""
        self._pending += len(records)

    def catch_up(self) -> list[StepState | None]:
        """None for each record taken since the last call."""
        out: list[StepState | None] = [None] * self._pending
        self._pending = 0
        return out

    def finish_responses(self, responses: ResponseSet, design: dict[str, Any], m: int,
                         mass: MassOf) -> dict[str, ResponseValue]:
        """The responses' values (no gradients)."""
        return responses.finish(design, m, mass)
