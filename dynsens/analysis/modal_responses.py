r"""Responses on the structure's natural frequencies and linear buckling factors.

``type: frequency`` is the lowest natural frequency (Hz) at the initial state, or with
``modes: k`` a smooth minimum of the k lowest,

    KS_min = f_min − (1/ρ) ln Σ_i exp(−ρ (f_i − f_min)),   ∇KS_min = Σ_i w_i ∇f_i,  w = softmax(−ρ f),

which is differentiable where frequencies cross or repeat, provided the whole cluster lies
within the k (the sum over a repeated eigenvalue's modes is the trace of its cluster matrix).
``type: buckling_factor`` is the same for the lowest linear buckling load factors of the case's
load.  Both depend on the design only; their gradients come from :mod:`.modes` (exact
eigenvalue derivatives), are the same in direct and adjoint runs, and in a complex-step run
the value carries the first-order imaginary part Σ_j ∂v/∂x_j · Im x_j, so that the complex step
of the whole run checks them.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..responses.base import FinishContext, Response, ResponseValue
from .modes import buckling, modes


@dataclass
class ModelSubject:
    """The model, plan, scales and source file a response analyses (see :class:`.modes.Subject`)."""

    model: Any
    source: str
    plan: Any
    x0: np.ndarray
    scale: np.ndarray


def smooth_min(values: np.ndarray, grads: np.ndarray | None, rho: float | None) -> tuple[float, np.ndarray | None]:
    """KS minimum of ``values`` (k,) and its gradient from ``grads`` (k, m); the value itself when k = 1."""
    if values.size == 1 or rho is None:
        return float(values[0]), None if grads is None else grads[0]
    low = float(values.min())
    w = np.exp(-rho * (values - low))
    total = float(w.sum())
    return low - np.log(total) / rho, None if grads is None else (w / total) @ grads


class ModalResponse(Response):
    """The lowest natural frequency or buckling load factor (a KS minimum over ``count`` of them)."""

    def __init__(self, name: str, kind: str, count: int, rho: float | None, subject: ModelSubject,
                 design_names: tuple[str, ...], unit: str, load_time: float | None = None):
        self.name, self.kind, self.count, self.rho = name, kind, count, rho
        self.subject, self.design_names, self.unit, self.load_time = subject, design_names, unit, load_time

    def finish(self, ctx: FinishContext) -> ResponseValue:
        x = np.array([ctx.design[n] for n in self.design_names])
        xr = np.real(x).astype(float)
        need = ctx.m > 0 or np.iscomplexobj(x)
        if self.kind == "frequency":
            m = modes(self.subject, xr, count=self.count, sensitivities=need)
            values, grads = m.frequencies, m.gradient
        else:
            b = buckling(self.subject, xr, count=self.count, load_time=self.load_time, sensitivities=need)
            values, grads = b.factors, b.gradient
        value, grad = smooth_min(values, grads, self.rho)
        if np.iscomplexobj(x) and grad is not None:
            return ResponseValue(value + 1j * float(grad @ np.imag(x)), None, self.unit)
        return ResponseValue(value, grad if ctx.m else None, self.unit)
