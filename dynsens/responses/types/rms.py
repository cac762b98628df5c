r"""``type: rms``: the root mean square of a quantity's component over the run,

    R = √(I / T),   I = ∫ v² dt (trapezoid over the steps, as ``type: integral``),   T = t_end − t₀,

with the gradient ∇R = (∇I − (I/T) ∇T) / (2 T R); T moves only when an event ends the run.  A
component that is zero over the whole run has R = 0 and ∇I = 0 there, so its gradient is zero."""
from __future__ import annotations

from typing import Any

import numpy as np

from ...case_keys import Section, allowed
from ...case_keys.general import _LABEL, _RESPONSE_COMMON
from ...case_keys.keys import _k, _req
from ...models._keys import check_keys
from ..base import FinishContext, OutputTrace, Response, ResponseValue, Samples, TimeIntegral
from .registry import Maker, ResponseType, register_response_type

KEYS = Section("responses[i], type: rms", "Root mean square √(∫v² dt / T) of a quantity's component over the "
               "run (trapezoid over the steps; T from t0 to the end of the run).", (
    *_RESPONSE_COMMON,
    _req("quantity", "any", "the quantity (see Quantities)"),
    _k("component", "any", "component of a vector quantity: index or label; " + _LABEL, default=0),
), type_value="rms")


class RootMeanSquare(TimeIntegral):
    """√(∫ v² dt / T) of one output component: the integral of v² accumulated step by step."""

    def __init__(self, name: str, output_id: int, component: int, unit: str):
        super().__init__(name, output_id, component, unit)
        self._t0: Any = None

    def integrand(self, samples: Samples) -> tuple[Any, np.ndarray | None]:
        v, g = super().integrand(samples)
        if self._t0 is None:
            self._t0 = samples.t[0]
        return v * v, None if g is None else 2.0 * v[:, None] * g

    def finish(self, ctx: FinishContext) -> ResponseValue:
        integral = super().finish(ctx)
        span = ctx.end_sample_time - self._t0
        rms = np.sqrt(integral.value / span)
        if integral.gradient is None:
            return ResponseValue(rms, None, self.unit)
        if integral.value == 0:
            return ResponseValue(rms, np.zeros_like(integral.gradient), self.unit)
        dspan = 0.0 if ctx.end_dt_dx is None else ctx.end_dt_dx
        return ResponseValue(rms, (integral.gradient - integral.value / span * dspan) / (2.0 * span * rms), self.unit)

    def adjoint_weights(self, trace: OutputTrace) -> dict[Any, Any] | None:
        # the trapezoid weights of ∫v² (2v per instant), scaled by ∂R/∂I = 1/(2TR)
        t = np.real(trace.t)
        v = np.real(trace.value[self.output_ids[0]][:, self.component])
        tw = np.zeros(len(t))
        half = 0.5 * np.diff(t)
        tw[:-1] += half
        tw[1:] += half
        integral, span = float(np.sum(tw * v * v)), t[-1] - t[0]
        W = np.zeros(np.shape(trace.value[self.output_ids[0]]))
        if integral == 0:
            return {self.output_ids[0]: W}
        scale = 1.0 / (2.0 * span * np.sqrt(integral / span))
        W[:, self.component] = scale * tw * 2.0 * v
        out: dict[Any, Any] = {self.output_ids[0]: W}
        if trace.event is not None and len(t) >= 2:     # the run, and its last interval, end at the event
            out["dt_dx"] = scale * (0.5 * (v[-2] ** 2 + v[-1] ** 2) - integral / span)
        return out


def read(r: dict, p: str, name: str, unit: str, ctx: Any) -> Maker | None:
    """The entry ``{type: rms, quantity: ..., component: ...}``."""
    from ...case.responses_spec import quantity_and_component
    check_keys(r, p, allowed("response.rms"), ctx.pc, required=("quantity",))
    found = quantity_and_component(r, p, ctx)
    if found is None:
        return None
    oid, comp = found
    u = unit or ctx.outputs[oid].unit

    def make() -> Response:
        return RootMeanSquare(name, oid, comp, u)
    return make


# after `integral` (order 90), before `event_time` (100)
register_response_type(ResponseType("rms", 95.0, read, KEYS))
