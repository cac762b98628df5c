r"""Responses, events and their gradients (method.md §5), accumulated step by step.

At every step the outputs that responses and events read are evaluated once, with their
total design gradients ∇v = ∂v/∂state·∇state + ∂_x v (from the sensitivity state), and
fed to the responses; nothing needs the stored history.

Events: e = v − level crosses zero between steps i−1 and i.  The crossing is located
at the fraction ϑ = −e_{i−1}/(e_i − e_{i−1}) of the step (``interpolate``) or taken at
step i (``step``, as the paper did).  Its gradient follows from the implicit-function
rule applied to the linear interpolant, dϑ/dx = −(∇e_{i−1}(e_i − e_{i−1}) − e_{i−1}(∇e_i − ∇e_{i−1}))/(e_i − e_{i−1})²,
dt_F/dx = Δt·dϑ/dx, in both modes; in ``interpolate`` mode this is the exact derivative
of the discrete procedure.  A response r read at the event has the *total* gradient
∇r(t_F) + ṙ dt_F/dx (the event time moves) and the *fixed-time* gradient ∇r(t_F).
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from .expressions import Expression
from .models.base import Output, StepState


@dataclass
class Sample:
    """One output at one instant: value (k,), total and fixed-time gradients (k, m) or None."""

    t: Any
    value: np.ndarray
    grad: np.ndarray | None
    grad_fixed: np.ndarray | None
    dt_dx: np.ndarray | None  # gradient of the sample's time (non-zero only at events)


@dataclass
class ResponseValue:
    """Final value of a response with its gradient; ``missing`` explains an absent value."""

    value: Any
    gradient: np.ndarray | None
    unit: str = ""
    missing: str | None = None
    kind: str = ""   # "fixed_time": gradient with the event time held fixed (not what FD measures)
    extra: dict[str, Any] = field(default_factory=dict)


class Response(ABC):
    """A response accumulated over the run."""

    name: str
    unit: str = ""
    output_ids: tuple[int, ...] = ()

    def feed(self, samples: dict[int, Sample]) -> None:  # noqa: B027
        """Take the samples of one instant (default: ignore)."""

    @abstractmethod
    def finish(self, ctx: "FinishContext") -> ResponseValue:
        """Final value and gradient."""


@dataclass
class FinishContext:
    """What responses may need when the run ends."""

    events: dict[str, "EventRecord"]
    end_sample_time: Any
    end_dt_dx: np.ndarray | None
    values: dict[str, ResponseValue]
    design: dict[str, Any]
    m: int
    mass: Callable[[], tuple[Any, np.ndarray | None]]


@dataclass
class EventRecord:
    """A fired event: time (s), its gradient (m,), the step at which it was found."""

    t: Any
    dt_dx: np.ndarray | None
    step: int


class ValueAt(Response):
    """Component ``component`` of an output at a time, at the end, or at an event."""

    def __init__(self, name: str, output_id: int, component: int, unit: str, *,
                 time: float | None = None, event: str | None = None, fixed_time: bool = False):
        self.name, self.unit = name, unit
        self.output_ids = (output_id,)
        self.component = component
        self.time = time
        self.event = event
        self.fixed_time = fixed_time
        self._prev: Sample | None = None
        self._hit: tuple[Any, np.ndarray | None] | None = None

    def _pick(self, smp: Sample) -> tuple[Any, np.ndarray | None]:
        g = smp.grad_fixed if self.fixed_time else smp.grad
        return smp.value[self.component], (None if g is None else g[self.component])

    def feed(self, samples: dict[int, Sample]) -> None:
        smp = samples[self.output_ids[0]]
        if self.time is not None and self._hit is None:
            tc = float(np.real(smp.t))
            if abs(tc - self.time) <= 1e-12 * max(1.0, abs(self.time)):
                self._hit = self._pick(smp)
            elif self._prev is not None and float(np.real(self._prev.t)) < self.time < tc:
                w = (self.time - self._prev.t) / (smp.t - self._prev.t)
                v0, g0 = self._pick(self._prev)
                v1, g1 = self._pick(smp)
                self._hit = (v0 + w * (v1 - v0), None if g0 is None else g0 + w * (g1 - g0))
        self._prev = smp          # the latest sample: the end (or event) value when the run stops

    def finish(self, ctx: FinishContext) -> ResponseValue:
        kind = "fixed_time" if self.fixed_time else ""
        if self.event is not None:
            if self.event not in ctx.events:
                return ResponseValue(np.nan, None, self.unit, missing=f"event '{self.event}' never fired")
            assert self._prev is not None
            v, g = self._pick(self._prev)
            return ResponseValue(v, g, self.unit, kind=kind)
        if self.time is not None:
            if self._hit is None:
                return ResponseValue(np.nan, None, self.unit,
                                     missing=f"the run ended before t = {self.time} s")
            return ResponseValue(self._hit[0], self._hit[1], self.unit)
        assert self._prev is not None
        v, g = self._pick(self._prev)
        return ResponseValue(v, g, self.unit, kind=kind)


class KSAggregate(Response):
    r"""Kreisselmeier–Steinhauser maximum over time and components, streamed.

    KS = g_max + (1/ρ) ln Σ exp(ρ(g_k − g_max)); ∇KS = Σ w_k ∇g_k with softmax weights.
    The running maximum is updated on the fly and earlier sums rescaled (log-sum-exp).
    """

    def __init__(self, name: str, output_ids: tuple[int, ...], components: tuple[Any, ...],
                 rho: float, unit: str):
        self.name, self.unit = name, unit
        self.output_ids = output_ids
        self.components = components  # per output: index array or slice
        self.rho = rho
        self._gmax: Any = None
        self._sum: Any = 0.0
        self._wgrad: np.ndarray | None = None

    def feed(self, samples: dict[int, Sample]) -> None:
        vals = []
        grads = []
        for oid, comp in zip(self.output_ids, self.components):
            smp = samples[oid]
            vals.append(smp.value[comp])
            if smp.grad is not None:
                grads.append(smp.grad[comp])
        v = np.concatenate(vals)
        new_max = v[int(np.argmax(v.real))]
        if self._gmax is None or new_max.real > np.real(self._gmax):
            if self._gmax is not None:
                factor = np.exp(self.rho * (self._gmax - new_max))
                self._sum = self._sum * factor
                if self._wgrad is not None:
                    self._wgrad = self._wgrad * factor
            self._gmax = new_max
        w = np.exp(self.rho * (v - self._gmax))
        self._sum = self._sum + np.sum(w)
        if grads:
            contrib = w @ np.concatenate(grads)
            self._wgrad = contrib if self._wgrad is None else self._wgrad + contrib

    def finish(self, ctx: FinishContext) -> ResponseValue:
        value = self._gmax + np.log(self._sum) / self.rho
        grad = None if self._wgrad is None else self._wgrad / self._sum
        return ResponseValue(value, grad, self.unit)


class TimeIntegral(Response):
    """Trapezoidal time integral of one component, consistent with the steps taken."""

    def __init__(self, name: str, output_id: int, component: int, unit: str):
        self.name, self.unit = name, unit
        self.output_ids = (output_id,)
        self.component = component
        self._prev: Sample | None = None
        self._value: Any = 0.0
        self._grad: np.ndarray | None = None

    def feed(self, samples: dict[int, Sample]) -> None:
        smp = samples[self.output_ids[0]]
        c = self.component
        if self._prev is not None:
            p = self._prev
            h = smp.t - p.t
            mean = 0.5 * (p.value[c] + smp.value[c])
            self._value = self._value + h * mean
            if smp.grad is not None and p.grad is not None:
                g = h * 0.5 * (p.grad[c] + smp.grad[c])
                if smp.dt_dx is not None:
                    g = g + mean * smp.dt_dx  # the end of the last interval moves with the event
                self._grad = g if self._grad is None else self._grad + g
        self._prev = smp

    def finish(self, ctx: FinishContext) -> ResponseValue:
        grad = self._grad if self._grad is not None else (np.zeros(ctx.m) if ctx.m else None)
        return ResponseValue(self._value, grad, self.unit)


class EventTime(Response):
    """Time of a named event (s), or of the end of the run for ``event = None``."""

    def __init__(self, name: str, event: str | None):
        self.name, self.unit, self.event = name, "s", event

    def finish(self, ctx: FinishContext) -> ResponseValue:
        if self.event is None:
            return ResponseValue(ctx.end_sample_time, ctx.end_dt_dx, "s")
        rec = ctx.events.get(self.event)
        if rec is None:
            return ResponseValue(np.nan, None, "s", missing=f"event '{self.event}' never fired")
        return ResponseValue(rec.t, rec.dt_dx, "s")


class StructuralMass(Response):
    """Total structural mass (the lightweight-design objective); depends on x only."""

    def __init__(self, name: str, unit: str):
        self.name, self.unit = name, unit

    def finish(self, ctx: FinishContext) -> ResponseValue:
        value, grad = ctx.mass()
        return ResponseValue(value, grad, self.unit)


class Combination(Response):
    """An expression of other responses and design variables; gradient by the chain rule.

    The partial derivatives of the expression are taken by complex step (the expression
    evaluator is complex-safe), so the combination adds no approximation.
    """

    def __init__(self, name: str, expr: Expression, unit: str, design_names: tuple[str, ...]):
        self.name, self.unit, self.expr = name, unit, expr
        self.design_names = design_names

    def finish(self, ctx: FinishContext) -> ResponseValue:
        env: dict[str, Any] = {}
        for sym in self.expr.symbols:
            if sym in ctx.values:
                rv = ctx.values[sym]
                if rv.missing:
                    return ResponseValue(np.nan, None, self.unit, missing=f"needs '{sym}': {rv.missing}")
                env[sym] = rv.value
            else:
                env[sym] = ctx.design[sym]
        value = self.expr.evaluate(env)
        if ctx.m == 0 or any(ctx.values[s].gradient is None for s in self.expr.symbols if s in ctx.values):
            return ResponseValue(value, None, self.unit)
        grad = np.zeros(ctx.m, dtype=np.result_type(value, float))
        h = 1e-30
        for sym in self.expr.symbols:
            pert = dict(env)
            pert[sym] = env[sym] + 1j * h
            partial = np.imag(self.expr.evaluate(pert)) / h
            if sym in ctx.values:
                grad = grad + partial * ctx.values[sym].gradient
            else:
                grad[self.design_names.index(sym)] += partial
        return ResponseValue(value, grad, self.unit)


@dataclass(frozen=True)
class EventSpec:
    """A terminating event: component ``component`` of an output crosses ``level``."""

    name: str
    output_id: int
    component: int
    level: float
    direction: str = "either"   # rising | falling | either
    location: str = "interpolate"  # interpolate | step


class ResponseSet:
    """Evaluates the outputs once per step, detects events and feeds the responses.

    Parameters
    ----------
    outputs : the distinct outputs needed (ids are list indices).
    responses : in dependency order (combinations last).
    events : terminating events.
    """

    def __init__(self, outputs: list[Output], responses: list[Response], events: list[EventSpec]):
        self.outputs = outputs
        self.responses = responses
        self.events = events
        self._prev: dict[int, Sample] | None = None
        self.fired: dict[str, EventRecord] = {}
        self.end_time: Any = None
        self.end_dt_dx: np.ndarray | None = None

    def evaluate(self, t: float, s: StepState, ds: StepState | None, params: Any,
                 value_and_total: Callable[..., tuple[np.ndarray, np.ndarray]] | None
                 ) -> dict[int, Sample]:
        """Outputs at one step, with total gradients when ``ds`` is given
        (``value_and_total``: :meth:`.sensitivity.DesignPartials.value_and_total`)."""
        out = {}
        for oid, o in enumerate(self.outputs):
            g = None
            if ds is not None and value_and_total is not None and not o.linear:
                v, g = value_and_total(lambda st, prm, _fn=o.fn: np.asarray(_fn(t, st, prm)), s, ds,
                                       o.batched)
            else:
                v = np.asarray(o.fn(t, s, params))
                if ds is not None and o.linear:
                    g = np.asarray(o.fn(t, ds, params))
            out[oid] = Sample(t, v, g, g, None)
        return out

    def observe(self, step: int, t: Any, samples: dict[int, Sample], dt: float) -> bool:
        """Feed one step; returns True when a terminating event fired (the run stops)."""
        fired = None
        if self._prev is not None:
            best = None
            for ev in self.events:
                e0 = self._prev[ev.output_id].value[ev.component] - ev.level
                e1 = samples[ev.output_id].value[ev.component] - ev.level
                r0, r1 = float(np.real(e0)), float(np.real(e1))
                up = r0 < 0.0 <= r1
                down = r0 > 0.0 >= r1
                if (ev.direction == "rising" and up) or (ev.direction == "falling" and down) or \
                        (ev.direction == "either" and (up or down)):
                    theta = -e0 / (e1 - e0)
                    if best is None or np.real(theta) < np.real(best[1]):
                        best = (ev, theta, e0, e1)
            if best is not None:
                fired = best
        if fired is None:
            self._feed(samples)
            self._prev = samples
            return False
        ev, theta, e0, e1 = fired
        prev = self._prev
        assert prev is not None
        g0 = prev[ev.output_id].grad
        g1 = samples[ev.output_id].grad
        dtheta = None
        if g0 is not None and g1 is not None:
            de0, de1 = g0[ev.component], g1[ev.component]
            dtheta = -(de0 * (e1 - e0) - e0 * (de1 - de0)) / (e1 - e0) ** 2
        frac = theta if ev.location == "interpolate" else 1.0
        t_event = prev[ev.output_id].t + frac * dt
        dt_dx = None if dtheta is None else dt * dtheta
        event_samples = {}
        for oid, smp in samples.items():
            p = prev[oid]
            dv = smp.value - p.value
            value = p.value + frac * dv
            g_fixed = g_total = None
            if smp.grad is not None and p.grad is not None:
                g_fixed = p.grad + frac * (smp.grad - p.grad)
                g_total = g_fixed + np.outer(dv, dtheta)
            event_samples[oid] = Sample(t_event, value, g_total, g_fixed, dt_dx)
        self.fired[ev.name] = EventRecord(t_event, dt_dx, step)
        self._feed(event_samples)
        self.end_time, self.end_dt_dx = t_event, dt_dx
        return True

    def _feed(self, samples: dict[int, Sample]) -> None:
        for r in self.responses:
            if r.output_ids:
                r.feed(samples)

    def close(self, t_end: Any, m: int) -> None:
        """Mark the last fed sample as the end of a run that reached its end time."""
        if self.end_time is None:
            self.end_time = t_end
            self.end_dt_dx = np.zeros(m) if m else None

    def finish(self, design: dict[str, Any], m: int,
               mass: Callable[[], tuple[Any, np.ndarray | None]]) -> dict[str, ResponseValue]:
        """Final values of all responses, in order."""
        values: dict[str, ResponseValue] = {}
        ctx = FinishContext(self.fired, self.end_time, self.end_dt_dx, values, design, m, mass)
        for r in self.responses:
            values[r.name] = r.finish(ctx)
        return values
