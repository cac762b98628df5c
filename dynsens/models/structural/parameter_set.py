"""A structural model's parameter set whose design-dependent matrices are assembled on demand.

A gradient by numerical partials evaluates one parameter set per perturbed design (one per
design variable, or one per colour of them); most of those sets are only read for their element
data (the outputs' stacked parameters, the mass, the initial state), while the Rayleigh damping
matrix and the K₀ it is built from, each an assembly over every element, are needed only by the
sets whose residual is evaluated.  Assembling them on first access keeps every value the same
(the same function of the same element data) and makes the other sets cost the element data
alone.
"""
from __future__ import annotations

from typing import Any, Callable


class ParameterSet(dict):
    """A dict of a design's parameters whose entries named in ``deferred`` are computed on first
    access by their function (of this set), then kept.  Membership (``in``), ``get`` and pickling
    see the deferred entries as present."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._deferred: dict[str, Callable[[ParameterSet], Any]] = {}

    def defer(self, key: str, make: Callable[[ParameterSet], Any]) -> None:
        """Compute entry ``key`` as make(self) when it is first read."""
        self._deferred[key] = make

    def __missing__(self, key: str) -> Any:
        make = self._deferred.pop(key, None)
        if make is None:
            raise KeyError(key)
        value = self[key] = make(self)
        return value

    def __contains__(self, key: object) -> bool:
        return dict.__contains__(self, key) or key in self._deferred

    def get(self, key: str, default: Any = None) -> Any:  # type: ignore[override]
        return self[key] if key in self else default

    @property
    def assembled(self) -> bool:
        """Whether every deferred entry has been computed."""
        return not self._deferred

    def __reduce__(self) -> Any:
        # pickled (e.g. for another process) as a plain dict of every entry, deferred ones computed
        return dict, (dict((k, self[k]) for k in list(self) + list(self._deferred)),)
