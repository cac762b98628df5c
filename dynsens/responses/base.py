r"""Responses, events and their gradients (method.md §5), accumulated as the run goes.

The outputs that responses read are evaluated with their total design gradients
∇v = ∂v/∂state·∇state + ∂_x v (from the sensitivity state) and fed to the responses;
nothing needs the stored history.  Steps are collected in blocks: an output that accepts a
batch of states and does not depend on t explicitly is evaluated for the whole block (all
steps and gradient directions) in one call, which removes the per-step cost of calling it.
Only the outputs that events watch are evaluated at every step (values only), so a run stops
at the step where its event fires.

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

from ..expressions.restricted import Expression


@dataclass
class Samples:
    """The outputs at K consecutive instants: a block of steps, or one event instant.

    t : (K,) times (s); value[oid] : (K, k); grad[oid], grad_fixed[oid] : (K, k, m) or None
    (total and fixed-time gradients; they differ only at an event); dt_dx : gradient (m,) of
    the time of the last instant (an event's; None otherwise).
    """

    t: np.ndarray
    value: dict[int, np.ndarray]
    grad: dict[int, np.ndarray | None]
    grad_fixed: dict[int, np.ndarray | None]
    dt_dx: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t)

    def part(self, start: int, stop: int) -> "Samples":
        """Instants start:stop (an event's dt_dx stays with the last instant only)."""
        sl = slice(start, stop)

        def cut(d: dict[int, Any]) -> dict[int, Any]:
            return {k: None if v is None else v[sl] for k, v in d.items()}
        keep_dt = self.dt_dx if stop >= len(self) else None
        return Samples(self.t[sl], cut(self.value), cut(self.grad), cut(self.grad_fixed), keep_dt)


@dataclass
class OutputTrace:
    """The outputs' values at every instant fed to the responses (kept in adjoint mode: the
    adjoint weights of a response may need its whole history, e.g. a KS maximum).

    t : (K,) times (s); value[oid] : (K, k).
    event : when a terminating event fired, its last instant is the event instant, interpolated
        between the grid steps K − 2 and K − 1 (see :class:`EventInstant`); else None.
    """

    t: np.ndarray
    value: dict[int, np.ndarray]
    event: "EventInstant | None" = None


@dataclass(frozen=True)
class EventInstant:
    """How the event instant was formed (what its gradients depend on): the event, the crossing
    values e0, e1 of its watched component at the grid steps before and at the crossing, the
    fraction ``frac`` of the step taken (ϑ, or 1 in ``step`` mode), the step size dt (s) and the
    outputs' values at the grid step of the crossing (``cur``, (k,) each)."""

    spec: "EventSpec"
    e0: Any
    e1: Any
    frac: Any
    dt: float
    cur: dict[int, np.ndarray]


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

    def feed(self, samples: Samples) -> None:  # noqa: B027
        """Take the outputs of the next instants, in time order (default: ignore)."""

    @abstractmethod
    def finish(self, ctx: "FinishContext") -> ResponseValue:
        """Final value and gradient."""

    # ---- adjoint hooks (additive: a response that reads outputs implements both to be
    # differentiated by the adjoint mode; until it does, the adjoint refuses the case)
    def adjoint_unsupported(self) -> str | None:
        """Why the adjoint mode cannot differentiate this response, or None when it can.
        Responses that read no outputs (mass, expressions of other responses) need no seeds;
        the default refuses any response reading outputs."""
        return f"response type {type(self).__name__} has no adjoint seeds" if self.output_ids else None

    def adjoint_weights(self, trace: OutputTrace) -> dict[Any, Any] | None:
        """The response's gradient as a weighted sum of the gradients the direct mode feeds it
        (called once the run has ended; the weights may use the whole history).  Keys:

        * ``oid`` → W (K, k): weights of the total gradients ∇v_oid(t_i) at the K instants of
          the trace, dJ/dx = Σ_i Σ_c W[i, c] ∇v_oid,c(t_i) + …;
        * ``("fixed", oid)`` → W (K, k): weights of the fixed-time gradients (they differ from
          the total ones only at an event instant);
        * ``"dt_dx"`` → c: weight of the gradient of the event time (the end of an event run).

        These are the adjoint seeds: the adjoint mode turns them into ∂J/∂state_i and ∂_x J.
        None (the default for responses that read no outputs): no sweep needed."""
        if self.output_ids:
            raise NotImplementedError(type(self).__name__)
        return None


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
        # the latest instant (t, value, gradient): the end (or event) value when the run stops
        self._prev: tuple[Any, Any, np.ndarray | None] | None = None
        self._hit: tuple[Any, np.ndarray | None] | None = None

    def _pick(self, smp: Samples) -> tuple[np.ndarray, np.ndarray | None]:
        """Values (K,) and gradients (K, m) of the component."""
        oid = self.output_ids[0]
        g = (smp.grad_fixed if self.fixed_time else smp.grad)[oid]
        return smp.value[oid][:, self.component], (None if g is None else g[:, self.component])

    def feed(self, samples: Samples) -> None:
        v, g = self._pick(samples)
        if self.time is not None and self._hit is None:
            tr = np.real(samples.t)
            tol = 1e-12 * max(1.0, abs(self.time))
            after = np.flatnonzero(tr >= self.time - tol)
            if after.size:
                j = int(after[0])
                if abs(tr[j] - self.time) <= tol:
                    self._hit = (v[j], None if g is None else g[j])
                else:
                    # the first instant past the time: interpolate from the one before it
                    prev = (samples.t[j - 1], v[j - 1], None if g is None else g[j - 1]) if j \
                        else self._prev
                    if prev is not None and float(np.real(prev[0])) < self.time:
                        w = (self.time - prev[0]) / (samples.t[j] - prev[0])
                        g_hit = None if g is None or prev[2] is None else prev[2] + w * (g[j] - prev[2])
                        self._hit = (prev[1] + w * (v[j] - prev[1]), g_hit)
        self._prev = (samples.t[-1], v[-1], None if g is None else g[-1])

    def adjoint_unsupported(self) -> str | None:
        return None

    def adjoint_weights(self, trace: OutputTrace) -> dict[Any, Any] | None:
        oid = self.output_ids[0]
        W = np.zeros(trace.value[oid].shape)
        if self.time is None or self.event is not None:          # the last instant (or the event's)
            W[-1, self.component] = 1.0
            return {("fixed", oid) if self.fixed_time else oid: W}
        # the instant (or the two around it) that :meth:`feed` picked
        tr = np.real(trace.t)
        tol = 1e-12 * max(1.0, abs(self.time))
        after = np.flatnonzero(tr >= self.time - tol)
        if after.size:
            j = int(after[0])
            if abs(tr[j] - self.time) <= tol:
                W[j, self.component] = 1.0
            elif j and tr[j - 1] < self.time:
                w = (self.time - trace.t[j - 1]) / (trace.t[j] - trace.t[j - 1])
                W[j - 1, self.component] = 1.0 - w
                W[j, self.component] = w
        return {oid: W}

    def finish(self, ctx: FinishContext) -> ResponseValue:
        kind = "fixed_time" if self.fixed_time else ""
        if self.event is not None and self.event not in ctx.events:
            return ResponseValue(np.nan, None, self.unit, missing=f"event '{self.event}' never fired")
        if self.time is not None and self.event is None:
            if self._hit is None:
                return ResponseValue(np.nan, None, self.unit,
                                     missing=f"the run ended before t = {self.time} s")
            return ResponseValue(self._hit[0], self._hit[1], self.unit)
        assert self._prev is not None
        return ResponseValue(self._prev[1], self._prev[2], self.unit, kind=kind)


class TimeIntegral(Response):
    """Trapezoidal time integral of one component, consistent with the steps taken."""

    def __init__(self, name: str, output_id: int, component: int, unit: str):
        self.name, self.unit = name, unit
        self.output_ids = (output_id,)
        self.component = component
        self._prev: tuple[Any, Any, np.ndarray | None] | None = None
        self._value: Any = 0.0
        self._grad: np.ndarray | None = None

    def integrand(self, samples: Samples) -> tuple[Any, np.ndarray | None]:
        """The integrand (K,) at the instants and its gradient (K, m) (None without sensitivities)."""
        oid, c = self.output_ids[0], self.component
        g = samples.grad[oid]
        return samples.value[oid][:, c], None if g is None else g[:, c]

    def feed(self, samples: Samples) -> None:
        t = samples.t
        v, g = self.integrand(samples)
        last = (t[-1], v[-1], None if g is None else g[-1])
        if self._prev is not None:
            # the interval from the previous block's last instant to this block's first
            pt, pv, pg = self._prev
            t = np.concatenate([[pt], t])
            v = np.concatenate([[pv], v])
            g = None if g is None or pg is None else np.concatenate([pg[None], g])
        if len(t) >= 2:
            h = np.diff(t)
            mean = 0.5 * (v[:-1] + v[1:])
            self._value = self._value + np.sum(h * mean)
            if g is not None:
                dg = (0.5 * h) @ (g[:-1] + g[1:])
                if samples.dt_dx is not None:
                    dg = dg + mean[-1] * samples.dt_dx  # the end of the last interval moves with the event
                self._grad = dg if self._grad is None else self._grad + dg
        self._prev = last

    def adjoint_unsupported(self) -> str | None:
        return None

    def adjoint_weights(self, trace: OutputTrace) -> dict[Any, Any] | None:
        oid, c = self.output_ids[0], self.component
        W = np.zeros(trace.value[oid].shape)
        half = 0.5 * np.real(np.diff(trace.t))          # trapezoid: half an interval to each end
        W[:-1, c] += half
        W[1:, c] += half
        out: dict[Any, Any] = {oid: W}
        if trace.event is not None and len(trace.t) >= 2:     # the last interval ends at the event
            out["dt_dx"] = 0.5 * (trace.value[oid][-2, c] + trace.value[oid][-1, c])
        return out

    def finish(self, ctx: FinishContext) -> ResponseValue:
        grad = self._grad if self._grad is not None else (np.zeros(ctx.m) if ctx.m else None)
        return ResponseValue(self._value, grad, self.unit)


class ExpressionIntegral(TimeIntegral):
    """Trapezoidal time integral of an expression f(v_1, …, v_n) of output components (∫q² dt);
    gradient ∇f = Σ_j ∂f/∂v_j ∇v_j with ∂f/∂v_j by complex step of the expression (real data)."""

    def __init__(self, name: str, expr: Expression, symbols: list[tuple[str, int, int]], unit: str):
        self.name, self.unit = name, unit
        self.expr = expr
        self.symbols = symbols                        # (symbol, output id, component)
        self.output_ids = tuple(dict.fromkeys(o for _, o, _ in symbols))
        self._prev = None
        self._value = 0.0
        self._grad = None

    def _at(self, vals: dict[str, Any]) -> np.ndarray:
        """f at every sample of ``vals`` (symbol → (k,) values); an expression that reads none of
        its symbols (a constant) is broadcast to the samples."""
        return self.expr.evaluate(vals) + 0.0 * next(iter(vals.values()))

    def integrand(self, samples: Samples) -> tuple[Any, np.ndarray | None]:
        vals = {n: samples.value[o][:, c] for n, o, c in self.symbols}
        f = self._at(vals)
        grads: list[Any] = [samples.grad[o] for _, o, _ in self.symbols]
        if any(g is None for g in grads):
            return f, None
        h = 1e-30
        g: Any = 0.0
        for (n, _o, c), gj in zip(self.symbols, grads):
            shifted = dict(vals)
            shifted[n] = vals[n] + 1j * h
            g = g + (np.imag(self._at(shifted)) / h)[:, None] * gj[:, c]
        return f, g

    def adjoint_weights(self, trace: OutputTrace) -> dict[Any, Any] | None:
        # trapezoid weights times ∂f/∂v_j at each instant (complex step of the expression)
        vals = {n: np.real(trace.value[o][:, c]) for n, o, c in self.symbols}
        tw = np.zeros(len(trace.t))
        half = 0.5 * np.real(np.diff(trace.t))
        tw[:-1] += half
        tw[1:] += half
        out: dict[Any, Any] = {o: np.zeros(np.shape(trace.value[o])) for o in self.output_ids}
        h = 1e-30
        for n, o, c in self.symbols:
            shifted: dict[str, Any] = dict(vals)
            shifted[n] = vals[n] + 1j * h
            out[o][:, c] += tw * (np.imag(self._at(shifted)) / h)
        if trace.event is not None and len(trace.t) >= 2:     # the last interval ends at the event
            f = np.real(self._at(vals))
            out["dt_dx"] = 0.5 * (f[-2] + f[-1])
        return out


class EventTime(Response):
    """Time of a named event (s), or of the end of the run for ``event = None``."""

    def __init__(self, name: str, event: str | None):
        self.name, self.unit, self.event = name, "s", event

    def adjoint_weights(self, trace: OutputTrace) -> dict[Any, Any] | None:
        fired = trace.event is not None and (self.event is None or trace.event.spec.name == self.event)
        return {"dt_dx": 1.0} if fired else None

    def finish(self, ctx: FinishContext) -> ResponseValue:
        if self.event is None:
            return ResponseValue(ctx.end_sample_time, ctx.end_dt_dx, "s")
        rec = ctx.events.get(self.event)
        if rec is None:
            return ResponseValue(np.nan, None, "s", missing=f"event '{self.event}' never fired")
        return ResponseValue(rec.t, rec.dt_dx, "s")


@dataclass(frozen=True)
class EventSpec:
    """A terminating event: component ``component`` of an output crosses ``level``."""

    name: str
    output_id: int
    component: int
    level: float
    direction: str = "either"   # rising | falling | either
    location: str = "interpolate"  # interpolate | step


# an event that fired: its spec, the fraction ϑ of the step and the crossing values e0, e1
EventHit = tuple[EventSpec, Any, Any, Any]
