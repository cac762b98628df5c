r"""Responses evaluated once the run is over from the design and other responses: the structural
mass (the lightweight-design objective) and combinations of responses and design variables
(expressions, gradients by the chain rule).  The responses the run feeds are in
:mod:`.responses`; the sizing aggregates in :mod:`.responses_sizing`.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import NonFiniteError
from ..expressions.restricted import Expression, ExpressionError
from .base import FinishContext, Response, ResponseValue


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
