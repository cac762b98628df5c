r"""The response set of a run: collects the steps in blocks, evaluates the outputs with their
gradients, detects events and feeds the responses (:mod:`dynsens.responses.base` defines them and
the event arithmetic of method.md §5)."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from ..derivatives.weights import grid_weights
from ..models.base import Output, StepState
from .base import (EventHit, EventInstant, EventRecord, EventSpec, FinishContext, OutputTrace, Response,
                        ResponseValue, Samples)

if TYPE_CHECKING:  # pragma: no cover
    from ..timeloop.records import Recorder


class ResponseSet:
    """Collects the steps of a run in blocks, evaluates the outputs, detects events and feeds
    the responses.

    Parameters
    ----------
    outputs : the distinct outputs of the case (ids are list indices); those that no response,
        event or recorded quantity reads are not evaluated.
    responses : in dependency order (combinations last).
    events : terminating events.
    block : most steps evaluated together (fewer when many gradient directions, a large state
        or large parameter sets make the batch large: at most ``BATCH_STATES`` states,
        ``BATCH_VALUES`` state entries and ``BATCH_BYTES`` of stacked parameter sets per call).
    recorder : keeps recorded quantities (``output.quantities``) at every step; outputs only
        it reads, without their sensitivity, are evaluated for values alone.
    stack_parameters : the model's ``stack_parameters`` (values of batched outputs in one call).
    """

    BATCH_STATES = 2048
    BATCH_VALUES = 250_000
    BATCH_BYTES = 32 * 2**20

    def __init__(self, outputs: list[Output], responses: list[Response], events: list[EventSpec],
                 block: int = 128, recorder: "Recorder | None" = None,
                 stack_parameters: Callable[[list[Any]], Any] | None = None):
        self.outputs = outputs
        self.recorder = recorder
        self._stack_parameters = stack_parameters
        # outputs whose gradients something reads: responses, events (at their crossing) and
        # quantities recorded with their sensitivity
        self._grad_oids = {oid for r in responses for oid in r.output_ids} | \
            {ev.output_id for ev in events} | (recorder.gradient_outputs if recorder else set())
        self.responses = responses
        self.events = events
        # outputs something reads (the others, quantities when none are recorded, are skipped)
        self._used_oids = {oid for r in responses for oid in r.output_ids} | \
            {ev.output_id for ev in events} | (recorder.output_ids if recorder else set())
        self.block = block
        self.fired: dict[str, EventRecord] = {}
        self.end_time: Any = None
        self.end_dt_dx: np.ndarray | None = None
        self._event_oids = sorted({ev.output_id for ev in events})
        self._pending: list[tuple[Any, StepState, StepState | None]] = []
        self._event_prev: dict[int, np.ndarray] | None = None   # watched values at the last step
        self._last: Samples | None = None                       # the last instant fed
        self._params: Any = None
        self._partials: Any = None
        self._params_one: Any = None
        self._trace: list[Samples] | None = None
        self._event: EventInstant | None = None

    def attach_recorder(self, recorder: "Recorder") -> None:
        """Record quantities in this run (before :meth:`start`)."""
        self.recorder = recorder
        self._grad_oids |= recorder.gradient_outputs
        self._used_oids |= recorder.output_ids

    def start(self, params: Any, partials: Any | None, stacked_one: Any | None, n_state: int,
              *, trace: bool = False) -> None:
        """Bind the run: its parameters, its :class:`.sensitivity.DesignPartials` (None without
        sensitivities, or in adjoint mode), ``stacked_one`` = ``model.stack_parameters([params])``
        (None when the model does not evaluate batches) and the size of a state (n_z);
        ``trace`` keeps the outputs' values of every instant (:meth:`trace`, adjoint mode)."""
        self._params, self._partials, self._params_one = params, partials, stacked_one
        if stacked_one is None and self._stack_parameters is not None and \
                any(oid not in self._grad_oids for oid in self._used_oids):
            self._params_one = self._stack_parameters([params])
        self._trace = [] if trace else None
        entries = partials.block_entries if partials is not None else 1
        # the parameter sets are stacked once per entry and step of a block (without
        # sensitivities one set serves the whole block)
        set_bytes = partials.parameter_set_bytes if partials is not None else 0
        self.block = max(1, min(self.block, self.BATCH_STATES // entries,
                                self.BATCH_VALUES // (entries * max(n_state, 1)),
                                self.BATCH_BYTES // max(entries * set_bytes, 1)))

    # ------------------------------------------------------------------ per step
    def push(self, step: int, t: Any, s: StepState, ds: StepState | None, dt: float,
             fired: EventHit | None) -> None:
        """Take one step (time t, s; state s with its sensitivities ds; step size dt, s) and what
        :meth:`watch` said of it, in step order; the sensitivities may trail the state by a
        block of steps, so a step is pushed once they are known."""
        self._pending.append((t, s, ds))
        if fired is None:
            if len(self._pending) >= self.block:
                self._feed(self._evaluate())
            return
        block = self._evaluate()
        if len(block) > 1:
            self._feed(block.part(0, len(block) - 1))
        assert self._last is not None, "an event needs the instant before it"
        ev, theta, e0, e1 = fired
        self._fire(ev, theta, e0, e1, self._last, block.part(len(block) - 1, len(block)), dt, step)

    def watch(self, t: Any, s: StepState) -> EventHit | None:
        """The first event whose watched value crossed its level in the step that ended at
        (t, s), if any (values only: called at every step, as soon as the step's state is known;
        the run stops when one fires)."""
        if not self.events:
            return None
        now = {oid: np.asarray(self.outputs[oid].fn(t, s, self._params)) for oid in self._event_oids}
        prev, self._event_prev = self._event_prev, now
        if prev is None:
            return None
        best = None
        for ev in self.events:
            e0 = prev[ev.output_id][ev.component] - ev.level
            e1 = now[ev.output_id][ev.component] - ev.level
            r0, r1 = float(np.real(e0)), float(np.real(e1))
            up = r0 < 0.0 <= r1
            down = r0 > 0.0 >= r1
            if (ev.direction == "rising" and up) or (ev.direction == "falling" and down) or \
                    (ev.direction == "either" and (up or down)):
                theta = -e0 / (e1 - e0)
                if best is None or np.real(theta) < np.real(best[1]):
                    best = (ev, theta, e0, e1)
        return best

    def _fire(self, ev: EventSpec, theta: Any, e0: Any, e1: Any, prev: Samples, cur: Samples,
              dt: float, step: int) -> None:
        """Feed the event instant, interpolated between the last step and this one."""
        oid, c = ev.output_id, ev.component
        g0, g1 = prev.grad[oid], cur.grad[oid]
        dtheta = None
        if g0 is not None and g1 is not None:
            de0, de1 = g0[0, c], g1[0, c]
            dtheta = -(de0 * (e1 - e0) - e0 * (de1 - de0)) / (e1 - e0) ** 2
        frac = theta if ev.location == "interpolate" else 1.0
        t_event = prev.t[0] + frac * dt
        dt_dx = None if dtheta is None else dt * dtheta
        value: dict[Any, Any] = {}
        grad: dict[Any, Any] = {}
        grad_fixed: dict[Any, Any] = {}
        for k in cur.value:
            dv = cur.value[k] - prev.value[k]
            value[k] = prev.value[k] + frac * dv
            pg, cg = prev.grad[k], cur.grad[k]
            grad[k] = grad_fixed[k] = None
            if pg is not None and cg is not None:
                grad_fixed[k] = pg + frac * (cg - pg)
                grad[k] = grad_fixed[k] + dv[:, :, None] * dtheta
        self.fired[ev.name] = EventRecord(t_event, dt_dx, step)
        self._event = EventInstant(ev, e0, e1, frac, dt, {k: v[0] for k, v in cur.value.items()})
        self._feed(Samples(np.array([t_event]), value, grad, grad_fixed, dt_dx))
        self.end_time, self.end_dt_dx = t_event, dt_dx

    # ------------------------------------------------------------------ per block
    def _evaluate(self) -> Samples:
        """The outputs at the pending steps, with total gradients when they carry sensitivities."""
        steps, self._pending = self._pending, []
        times = np.array([t for t, _, _ in steps])
        states = [s for _, s, _ in steps]
        dstates = [ds for _, _, ds in steps]
        stacked_s: StepState | None = None
        value: dict[int, np.ndarray] = {}
        grad: dict[int, np.ndarray | None] = {}
        for oid, o in enumerate(self.outputs):
            if oid not in self._used_oids:
                continue
            partials = self._partials if dstates[0] is not None and oid in self._grad_oids else None
            if o.linear:
                # linear in the state, independent of the design: ∇v = fn(∇state)
                # (np.array of a list of equal arrays: np.stack's copies, without its per-array work)
                value[oid] = np.array([np.asarray(o.fn(t, s, self._params)) for t, s in zip(times, states)])
                grad[oid] = None if partials is None else \
                    np.array([np.asarray(o.fn(t, ds, self._params)) for t, ds in zip(times, dstates)])
            elif o.batched and o.autonomous and (partials is not None or self._params_one is not None):
                # one call for all steps (and directions); t is irrelevant to the output
                if partials is not None:
                    value[oid], grad[oid] = partials.value_and_total_block(
                        lambda st, prm, _fn=o.fn: np.asarray(_fn(times[-1], st, prm)), states, dstates)
                else:
                    if stacked_s is None:
                        stacked_s = StepState(*(np.array(v) for v in zip(*states)))
                    value[oid], grad[oid] = np.asarray(o.fn(times[-1], stacked_s, self._params_one)), None
            elif partials is not None:
                pairs = [partials.value_and_total(lambda st, prm, _fn=o.fn, _t=t: np.asarray(_fn(_t, st, prm)),
                                                  s, ds, o.batched)
                         for t, s, ds in zip(times, states, dstates)]
                value[oid] = np.array([v for v, _ in pairs])
                grad[oid] = np.array([g for _, g in pairs])
            else:
                value[oid] = np.array([np.asarray(o.fn(t, s, self._params)) for t, s in zip(times, states)])
                grad[oid] = None
        samples = Samples(times, value, grad, dict(grad))
        if self.recorder is not None:
            self.recorder.feed(samples)
        return samples

    def adjoint_unsupported(self) -> list[str]:
        """What keeps the adjoint mode from differentiating this set (empty: nothing)."""
        why = []
        for r in self.responses:
            reason = r.adjoint_unsupported()
            if reason:
                why.append(f"response '{r.name}': {reason}")
        return why

    def trace(self) -> OutputTrace:
        """The outputs' values at every instant fed (``start(..., trace=True)``)."""
        assert self._trace is not None, "start(..., trace=True) first"
        blocks = self._trace
        return OutputTrace(np.concatenate([b.t for b in blocks]),
                           {oid: np.concatenate([b.value[oid] for b in blocks]) for oid in blocks[0].value},
                           self._event)

    def _feed(self, samples: Samples) -> None:
        if self._trace is not None:
            self._trace.append(samples)
        for r in self.responses:
            if r.output_ids:
                r.feed(samples)
        self._last = samples.part(len(samples) - 1, len(samples))

    def close(self, t_end: Any, m: int) -> None:
        """Evaluate the steps still pending; mark the end of a run that reached its end time."""
        if self._pending:
            self._feed(self._evaluate())
        if self.end_time is None:
            self.end_time = t_end
            self.end_dt_dx = np.zeros(m) if m else None

    def finish(self, design: dict[str, Any], m: int,
               mass: Callable[[], tuple[Any, np.ndarray | None]],
               adjoint: Callable[[OutputTrace, dict[str, dict[int, np.ndarray]]], dict[str, np.ndarray]]
               | None = None) -> dict[str, ResponseValue]:
        """Final values of all responses, in order.  In adjoint mode, ``adjoint(trace, weights)``
        turns the responses' adjoint weights into their gradients (before the expressions that
        combine them are evaluated)."""
        values: dict[str, ResponseValue] = {}
        grads: dict[str, np.ndarray] = {}
        if adjoint is not None:
            trace = self.trace()
            weights = {r.name: r.adjoint_weights(trace) for r in self.responses}
            grads = adjoint(trace, {name: grid_weights(trace, w, self.outputs) for name, w in weights.items()
                                    if w is not None})
        ctx = FinishContext(self.fired, self.end_time, self.end_dt_dx, values, design, m, mass)
        for r in self.responses:
            rv = r.finish(ctx)
            if r.name in grads and not rv.missing:
                rv.gradient = grads[r.name]
            values[r.name] = rv
        return values

