"""The registry of response types by the case's ``type``.

A :class:`ResponseType` names its ``type``, its place in the generated reference (``order``), the
reader that turns a ``responses[i]`` entry into a maker of fresh responses, and its key section.
A type declared in its own module of this package passes its section (:attr:`ResponseType.keys`)
and :func:`register_response_type` adds it to the key table (section, the ``type`` enum and the
``case.responses`` item list); the types read by :mod:`dynsens.case.responses_spec` keep their
sections in :mod:`dynsens.case_keys.general`.  Every module of this package is imported by
:func:`load_response_types`: a new response type is a new module here, nothing else.
"""
from __future__ import annotations

import importlib
import pkgutil
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable

from ...case_keys import Section, add_response_section

if TYPE_CHECKING:
    from ..base import Response

Maker = Callable[[], "Response"]
#: (entry, key path, response name, unit, reading context) -> a maker of fresh responses, or None
#: (problems in the context's collector); the context is :class:`dynsens.case.responses_spec.ResponseContext`
Reader = Callable[[dict, str, str, str, Any], "Maker | None"]


@dataclass(frozen=True)
class ResponseType:
    """One response type of the case language."""

    type: str            # the value of the entry's ``type`` key
    order: float         # place among the types (the ``type`` enum, the reference, the error messages)
    read: Reader
    keys: Section | None = None    # its key section ``response.<type>``; None: kept in case_keys.general
    aggregate: bool = False        # an aggregate over time and components


RESPONSE_REGISTRY: dict[str, ResponseType] = {}
_loaded: list[bool] = []     # non-empty once load_response_types has run


def register_response_type(rt: ResponseType) -> ResponseType:
    """Register ``rt`` under its ``type`` (its key section enters the key table when
    :func:`load_response_types` has imported every type)."""
    RESPONSE_REGISTRY[rt.type] = rt
    return rt


def load_response_types() -> dict[str, ResponseType]:
    """Import every module of this package (each registers its types), add the declared key
    sections to the key table (each after the type before it in ``order``; the ``type`` enum and
    the ``case.responses`` items list every type) and return the registry."""
    from .. import types
    if not _loaded:
        for info in pkgutil.iter_modules(types.__path__):
            importlib.import_module(f"{types.__name__}.{info.name}")
        names = response_type_names()
        for name in names:
            keys = RESPONSE_REGISTRY[name].keys
            if keys is not None:
                add_response_section(name, keys, names)
        _loaded.append(True)
    return RESPONSE_REGISTRY


def response_type_names() -> tuple[str, ...]:
    """The registered types in their order."""
    return tuple(rt.type for rt in sorted(RESPONSE_REGISTRY.values(), key=lambda rt: rt.order))
