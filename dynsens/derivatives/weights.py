"""The responses' adjoint weights moved from the instants they were fed onto the grid steps
whose states the adjoint sweep seeds (the event instant is a combination of two of them)."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from ..models.base import Output
    from ..responses.base import OutputTrace


def grid_weights(trace: OutputTrace, weights: dict[Any, Any], outputs: list[Output]) -> dict[int, np.ndarray]:
    """A response's adjoint weights on the outputs' gradients at the grid steps 0 … K − 1 of the
    run (the adjoint's seeds), from its weights on the trace's instants.  Without an event the
    two are the same.  With one, the event instant is a combination of the grid steps K − 2 and
    K − 1 (method.md §5): fixed-time gradient (1 − frac) ∇v_{K−2} + frac ∇v_{K−1}, total gradient
    that plus (v_{K−1} − v_{K−2}) dϑ/dx, and dϑ/dx = (e0 ∇e_{K−1} − e1 ∇e_{K−2})/(e1 − e0)² with e
    the watched component; the event time's gradient is Δt dϑ/dx.  All of it transposed here."""
    shape = {oid: trace.value[oid].shape for oid in trace.value}
    G: dict[int, np.ndarray] = {}

    def at(oid: int) -> np.ndarray:
        if oid not in G:
            G[oid] = np.zeros(shape[oid] if oid in shape else (len(trace.t), len(outputs[oid].labels)))
        return G[oid]

    for key, W in weights.items():
        if key != "dt_dx":
            at(key[1] if isinstance(key, tuple) else key)[:] += np.real(W)
    ev = trace.event
    if ev is None:
        return G
    K = len(trace.t)
    c_theta = np.real(weights.get("dt_dx", 0.0)) * ev.dt
    frac = np.real(ev.frac)
    for key, W in weights.items():
        if key == "dt_dx":
            continue
        oid = key[1] if isinstance(key, tuple) else key
        w = np.real(W[-1])
        g = at(oid)
        g[-1] -= w                          # the event instant is not the grid step K − 1 …
        g[-2] += (1.0 - frac) * w           # … but this interpolation of it
        g[-1] += frac * w
        if not isinstance(key, tuple):      # a total gradient: the event instant moves
            c_theta = c_theta + w @ np.real(ev.cur[oid] - trace.value[oid][-2]) if K >= 2 else c_theta
    if np.any(c_theta != 0.0):
        de = np.real(ev.e1 - ev.e0) ** 2
        g = at(ev.spec.output_id)
        g[-2, ev.spec.component] += c_theta * np.real(-ev.e1) / de
        g[-1, ev.spec.component] += c_theta * np.real(ev.e0) / de
    return G
