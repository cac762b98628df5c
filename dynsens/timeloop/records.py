"""Recorded quantities (a case's ``output.quantities``): outputs kept over the whole run.

A recorded quantity is any output the case language can name (an element force, a stroke, a
body angle, a joint reaction, a marker position ...), stored at every step with its unit and
label, and, on request, with its total design gradient at every step (∇v = ∂v/∂state·∇state +
∂_x v, the same gradient a response reading the quantity receives).  The recorder sees the
blocks of steps the :class:`~dynsens.responses.base.ResponseSet` evaluates anyway, so the values
are on the run's own time grid (the step at which an event fires included).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..responses.base import Samples

if TYPE_CHECKING:  # pragma: no cover
    from ..responses.response_set import ResponseSet


# names the result file uses for its own members (a recorded quantity is a root-level dataset)
RESERVED = ("time", "state", "sensitivity", "monitors", "design", "responses", "stats", "dof",
            "multiplier", "pressure", "design_variable", "quantity_gradients", "optimization", "x")


@dataclass(frozen=True)
class QuantitySpec:
    """What to record: components ``components`` of output ``output_id``.

    name : identifier (the HDF5 dataset and DataFrame column); label : human-readable name for
    plots; unit : the case's unit of the quantity; component_labels : one per recorded
    component; sensitivity : also record the design gradient at every step.
    """

    name: str
    output_id: int
    components: tuple[int, ...]
    component_labels: tuple[str, ...]
    unit: str = ""
    label: str = ""
    sensitivity: bool = False

    @property
    def scalar(self) -> bool:
        """One component: stored as (N,) instead of (N, k)."""
        return len(self.components) == 1


@dataclass
class RecordedQuantity:
    """A quantity over the run.

    value : (N,) or (N, k) in ``unit``; gradient : (N, m) or (N, k, m) (unit per unit of each
    design variable), or None when not requested or the run had no sensitivities;
    components : labels of the k components (empty for a scalar quantity).
    """

    name: str
    unit: str
    label: str
    time: np.ndarray
    value: np.ndarray
    gradient: np.ndarray | None = None
    components: tuple[str, ...] = ()
    output_id: int = -1      # the case's output it records (-1: not known, e.g. read from a file)


class Recorder:
    """Collects the recorded quantities block by block (see :meth:`feed`)."""

    def __init__(self, specs: tuple[QuantitySpec, ...]):
        self.specs = specs
        self._t: list[np.ndarray] = []
        self._v: dict[str, list[np.ndarray]] = {s.name: [] for s in specs}
        self._g: dict[str, list[np.ndarray]] = {s.name: [] for s in specs}

    @property
    def output_ids(self) -> set[int]:
        """Outputs whose values are recorded."""
        return {s.output_id for s in self.specs}

    @property
    def gradient_outputs(self) -> set[int]:
        """Outputs whose design gradient is recorded."""
        return {s.output_id for s in self.specs if s.sensitivity}

    def feed(self, samples: Samples) -> None:
        """Take the outputs of a block of consecutive steps (grid steps, in time order)."""
        self._t.append(np.real(samples.t))
        for s in self.specs:
            idx = list(s.components)
            self._v[s.name].append(np.real(samples.value[s.output_id][:, idx]))
            g = samples.grad[s.output_id]
            if s.sensitivity and g is not None:
                self._g[s.name].append(np.real(g[:, idx]))

    def result(self) -> dict[str, RecordedQuantity]:
        """The recorded quantities of the run, in the order of the case."""
        t = np.concatenate(self._t) if self._t else np.empty(0)
        out = {}
        for s in self.specs:
            v = np.concatenate(self._v[s.name]) if self._v[s.name] else np.empty((0, len(s.components)))
            g = np.concatenate(self._g[s.name]) if self._g[s.name] and \
                sum(len(b) for b in self._g[s.name]) == len(t) else None
            if s.scalar:
                v = v[:, 0]
                g = None if g is None else g[:, 0]
            out[s.name] = RecordedQuantity(s.name, s.unit, s.label or s.name, t, v, g,
                                           () if s.scalar else s.component_labels, s.output_id)
        return out


def reads_in_own_unit(response: Any) -> bool:
    """Whether ``response``'s value is in the unit of the quantity it reads: a value at a time, or
    a maximum, minimum or KS of the quantity itself (±1 sides), not of a ratio of it."""
    from ..responses.base import ValueAt
    from ..responses.sizing import Aggregate
    if isinstance(response, ValueAt):
        return True
    return isinstance(response, Aggregate) and all(np.all(np.abs(t.sides) == 1.0) for t in response.terms)


def quantities_read_by(responses: "ResponseSet") -> tuple[QuantitySpec, ...]:
    """What the responses of a case read over time (each output once, all its components, in
    the response's unit), for a case that names no ``output.quantities`` of its own.  Each is
    named after its output's label (``u.displacement``, ``Z.F``) or, for an output of several
    components, after the first response reading it (``sigma_ks_quantity``)."""
    specs: list[QuantitySpec] = []
    seen: set[int] = set()
    names: set[str] = set()
    for r in responses.responses:
        for oid in r.output_ids:
            if oid in seen:
                continue
            seen.add(oid)
            out = responses.outputs[oid]
            name = out.labels[0] if len(out.labels) == 1 else f"{r.name}_quantity"
            if name in RESERVED or name.endswith("_component"):
                name = f"{r.name}_quantity"
            while name in names:
                name += "_"
            names.add(name)
            # a response in the quantity's own unit names it; a ratio (σ/σ_lim) does not
            unit = r.unit if r.unit and reads_in_own_unit(r) else out.unit
            specs.append(QuantitySpec(name, oid, tuple(range(len(out.labels))), tuple(out.labels),
                                      unit, f"{name} (read by {r.name})"))
    return tuple(specs)
