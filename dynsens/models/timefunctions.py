"""Time functions that scale loads: constant, step, ramp, smoothstep, harmonic, pulse, table.

Each function is dimensionless and multiplies a load amplitude.  Its own parameters
(times in s, frequency in Hz, phase in rad, table values) may be design expressions,
so evaluation takes the model's parameter vector and is complex-safe in it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ProblemCollector
from ..case_keys import TIME_FUNCTION_TYPES, allowed
from ._keys import check_keys, did_you_mean
from .parameters import ParameterTable

KINDS = TIME_FUNCTION_TYPES   # the keys of each: dynsens/case_keys/


@dataclass(frozen=True)
class TimeFunction:
    """A load time function; ``value(t, pv)`` with pv the evaluated parameter vector."""

    kind: str
    idx: tuple[int, ...]          # indices into the parameter vector
    table_t: tuple[float, ...] = ()

    def value(self, t: float, pv: np.ndarray) -> Any:
        """Dimensionless factor at time t (s).

        ``pv`` may carry a leading batch axis (perturbed designs); branches (before, inside,
        after a ramp) follow the first entry, as finite differences of the same branch would.
        """
        k = self.kind
        if k == "constant":
            return 1.0
        p = [pv[..., i] for i in self.idx]
        if k == "step":
            return 1.0 if t >= _first(p[0]) else 0.0
        if k in ("ramp", "smoothstep"):
            t0, t1 = p
            if t <= _first(t0):
                return 0.0
            if t >= _first(t1):
                return 1.0
            tau = (t - t0) / (t1 - t0)
            return tau if k == "ramp" else tau * tau * (3.0 - 2.0 * tau)
        if k == "harmonic":
            f, phase = p
            return np.sin(2.0 * np.pi * f * t + phase)
        if k == "pulse":
            t0, d = p
            if t <= _first(t0) or t >= _first(t0 + d):
                return 0.0
            return np.sin(np.pi * (t - t0) / d) ** 2
        # table: piecewise linear in the tabulated values, constant beyond the ends
        ts = self.table_t
        vals = p
        if t <= ts[0]:
            return vals[0]
        if t >= ts[-1]:
            return vals[-1]
        j = int(np.searchsorted(ts, t, side="right")) - 1
        w = (t - ts[j]) / (ts[j + 1] - ts[j])
        return vals[j] + w * (vals[j + 1] - vals[j])

    def settled_from(self, pv: np.ndarray) -> float:
        """A time T (s) after which the value no longer changes: value(t, pv) is the same for
        every t > T (−inf for a constant, +inf when it never settles).  Lets callers keep inputs
        evaluated at one such time instead of evaluating them again at each step."""
        k = self.kind
        if k == "constant":
            return -np.inf
        p = [_first(pv[..., i]) for i in self.idx]
        if k in ("step", "ramp", "smoothstep"):
            return max(p)                   # past t0 (and t1): the last branch, 1
        if k == "pulse":
            return max(p[0], p[0] + p[1])   # past t0 and t0 + d: 0
        if k == "table":
            return self.table_t[-1]         # past the last entry: its value
        return np.inf                       # harmonic


def _first(v: Any) -> float:
    """Real part of a scalar, or of the first entry of a batch."""
    x = v.flat[0] if isinstance(v, np.ndarray) else v
    return float(x.real)


def build_time_function(spec: Any, path: str, table: ParameterTable,
                        problems: ProblemCollector) -> TimeFunction | None:
    """Read a time-function entry (``{type: ..., ...}`` or a bare kind name)."""
    if spec is None:
        spec = {"type": "constant"}
    if isinstance(spec, str):
        spec = {"type": spec}
    if not isinstance(spec, dict):
        problems.add(path, f"expected a mapping with 'type', found {spec!r}")
        return None
    kind = spec.get("type")
    if kind not in KINDS:
        problems.add(f"{path}.type", f"unknown time function {kind!r}{did_you_mean(kind, KINDS)} "
                                     f"(known: {', '.join(KINDS)})")
        return None
    check_keys(spec, path, allowed(f"function.{kind}"), problems)
    if kind == "constant":
        return TimeFunction(kind, ())
    if kind == "step":
        return TimeFunction(kind, (table.add(spec.get("t0", 0.0), f"{path}.t0", problems),))
    if kind in ("ramp", "smoothstep"):
        for key in ("t0", "t1"):
            if key not in spec and not (key == "t0"):
                problems.add(f"{path}.{key}", "missing (end time of the ramp, s)")
        i0 = table.add(spec.get("t0", 0.0), f"{path}.t0", problems)
        i1 = table.add(spec.get("t1", 1.0), f"{path}.t1", problems)
        if isinstance(spec.get("t0", 0.0), (int, float)) and isinstance(spec.get("t1"), (int, float)) \
                and spec["t1"] <= spec.get("t0", 0.0):
            problems.add(f"{path}.t1", f"must be greater than t0 ({spec.get('t0', 0.0)}), found {spec['t1']}")
        return TimeFunction(kind, (i0, i1))
    if kind == "harmonic":
        if "frequency" not in spec:
            problems.add(f"{path}.frequency", "missing (Hz)")
        return TimeFunction(kind, (table.add(spec.get("frequency", 1.0), f"{path}.frequency", problems,
                                             positive=True),
                                   table.add(spec.get("phase", 0.0), f"{path}.phase", problems)))
    if kind == "pulse":
        if "duration" not in spec:
            problems.add(f"{path}.duration", "missing (s)")
        return TimeFunction(kind, (table.add(spec.get("t0", 0.0), f"{path}.t0", problems),
                                   table.add(spec.get("duration", 1.0), f"{path}.duration", problems,
                                             positive=True)))
    ts, vs = spec.get("t"), spec.get("values")
    if not isinstance(ts, list) or not isinstance(vs, list) or len(ts) != len(vs) or len(ts) < 2:
        problems.add(path, "a table needs lists 't' and 'values' of equal length >= 2")
        return None
    if not all(isinstance(v, (int, float)) for v in ts) or any(b <= a for a, b in zip(ts, ts[1:])):
        problems.add(f"{path}.t", "must be strictly increasing numbers")
        return None
    idx = tuple(table.add(v, f"{path}.values[{i}]", problems) for i, v in enumerate(vs))
    return TimeFunction(kind, idx, tuple(float(v) for v in ts))
