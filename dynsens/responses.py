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
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from .derivatives.weights import grid_weights
from .errors import NonFiniteError
from .expressions import Expression, ExpressionError
from .models.base import Output, StepState

if TYPE_CHECKING:  # pragma: no cover
    from .records import Recorder


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


class KSAggregate(Response):
    r"""Kreisselmeier–Steinhauser maximum over time and components, streamed.

    KS = g_max + (1/ρ) ln Σ exp(ρ(g_k − g_max)); ∇KS = Σ w_k ∇g_k with softmax weights.
    The running maximum is updated block by block and earlier sums rescaled (log-sum-exp).
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

    def feed(self, samples: Samples) -> None:
        v = np.concatenate([samples.value[oid][:, comp]
                            for oid, comp in zip(self.output_ids, self.components)], axis=1).ravel()
        grads = [samples.grad[oid] for oid in self.output_ids]
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
        if all(g is not None for g in grads):
            G = np.concatenate([np.asarray(g)[:, comp] for g, comp in zip(grads, self.components)], axis=1)
            contrib = w @ G.reshape(v.size, -1)
            self._wgrad = contrib if self._wgrad is None else self._wgrad + contrib

    def adjoint_unsupported(self) -> str | None:
        return None

    def adjoint_weights(self, trace: OutputTrace) -> dict[Any, Any] | None:
        # the softmax weights w_k = exp(ρ(g_k − g_max)) / Σ exp(ρ(g − g_max)) of the final sum
        out = {oid: np.zeros(trace.value[oid].shape) for oid in self.output_ids}
        for oid, comp in zip(self.output_ids, self.components):
            out[oid][:, comp] += np.real(np.exp(self.rho * (trace.value[oid][:, comp] - self._gmax)) / self._sum)
        return out

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

    def integrand(self, samples: Samples) -> tuple[Any, np.ndarray | None]:
        vals = {n: samples.value[o][:, c] for n, o, c in self.symbols}
        f = self.expr.evaluate(vals) + 0.0 * next(iter(vals.values()))
        grads: list[Any] = [samples.grad[o] for _, o, _ in self.symbols]
        if any(g is None for g in grads):
            return f, None
        h = 1e-30
        g: Any = 0.0
        for (n, _o, c), gj in zip(self.symbols, grads):
            shifted = dict(vals)
            shifted[n] = vals[n] + 1j * h
            g = g + (np.imag(self.expr.evaluate(shifted)) / h)[:, None] * gj[:, c]
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
            out[o][:, c] += tw * (np.imag(self.expr.evaluate(shifted)) / h)
        if trace.event is not None and len(trace.t) >= 2:     # the last interval ends at the event
            f = np.real(self.expr.evaluate(vals) + 0.0 * next(iter(vals.values())))
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
        try:
            value = self.expr.evaluate(env)
        except ExpressionError as exc:   # e.g. log of a negative response: a failed run, named
            raise NonFiniteError(f"response '{self.name}': {exc}") from None
        # a combination of a fixed-time gradient is one too (e.g. g2_fixed_time = stroke_fixed_time/500 − 1)
        kind = "fixed_time" if any(ctx.values[s].kind == "fixed_time" for s in self.expr.symbols
                                   if s in ctx.values) else ""
        if ctx.m == 0 or any(ctx.values[s].gradient is None for s in self.expr.symbols if s in ctx.values):
            return ResponseValue(value, None, self.unit, kind=kind)
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
        return ResponseValue(value, grad, self.unit, kind=kind)


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


class ResponseSet:
    """Collects the steps of a run in blocks, evaluates the outputs, detects events and feeds
    the responses.

    Parameters
    ----------
    outputs : the distinct outputs needed (ids are list indices).
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

    def start(self, params: Any, partials: Any | None, stacked_one: Any | None, n_state: int,
              *, trace: bool = False) -> None:
        """Bind the run: its parameters, its :class:`.sensitivity.DesignPartials` (None without
        sensitivities, or in adjoint mode), ``stacked_one`` = ``model.stack_parameters([params])``
        (None when the model does not evaluate batches) and the size of a state (n_z);
        ``trace`` keeps the outputs' values of every instant (:meth:`trace`, adjoint mode)."""
        self._params, self._partials, self._params_one = params, partials, stacked_one
        if stacked_one is None and self._stack_parameters is not None and \
                any(oid not in self._grad_oids for oid in range(len(self.outputs))):
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
            partials = self._partials if dstates[0] is not None and oid in self._grad_oids else None
            if o.linear:
                # linear in the state, independent of the design: ∇v = fn(∇state)
                value[oid] = np.stack([np.asarray(o.fn(t, s, self._params)) for t, s in zip(times, states)])
                grad[oid] = None if partials is None else \
                    np.stack([np.asarray(o.fn(t, ds, self._params)) for t, ds in zip(times, dstates)])
            elif o.batched and o.autonomous and (partials is not None or self._params_one is not None):
                # one call for all steps (and directions); t is irrelevant to the output
                if partials is not None:
                    value[oid], grad[oid] = partials.value_and_total_block(
                        lambda st, prm, _fn=o.fn: np.asarray(_fn(times[-1], st, prm)), states, dstates)
                else:
                    if stacked_s is None:
                        stacked_s = StepState(*(np.stack(v) for v in zip(*states)))
                    value[oid], grad[oid] = np.asarray(o.fn(times[-1], stacked_s, self._params_one)), None
            elif partials is not None:
                pairs = [partials.value_and_total(lambda st, prm, _fn=o.fn, _t=t: np.asarray(_fn(_t, st, prm)),
                                                  s, ds, o.batched)
                         for t, s, ds in zip(times, states, dstates)]
                value[oid] = np.stack([v for v, _ in pairs])
                grad[oid] = np.stack([g for _, g in pairs])
            else:
                value[oid] = np.stack([np.asarray(o.fn(t, s, self._params)) for t, s in zip(times, states)])
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

