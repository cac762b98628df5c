"""Model kinds by name: ``model.type`` in a case selects a builder registered here."""
from __future__ import annotations

import difflib
from typing import Any, Callable

from ..errors import ProblemCollector
from .base import Model
from .parameters import ParameterTable

Builder = Callable[[dict, str, ParameterTable, ProblemCollector], "Model | None"]
_BUILDERS: dict[str, Builder] = {}


def register(kind: str) -> Callable[[Builder], Builder]:
    """Decorator: register ``builder(spec, path, table, problems) -> Model`` under ``kind``."""
    def deco(fn: Builder) -> Builder:
        _BUILDERS[kind] = fn
        return fn
    return deco


def kinds() -> list[str]:
    """Registered model kinds."""
    _load_builtin()
    return sorted(_BUILDERS)


def build_model(spec: Any, path: str, table: ParameterTable,
                problems: ProblemCollector) -> Model | None:
    """Build the model described by ``spec`` (the case's ``model`` mapping)."""
    _load_builtin()
    if not isinstance(spec, dict):
        problems.add(path, f"expected a mapping, found {spec!r}")
        return None
    kind = spec.get("type")
    if kind not in _BUILDERS:
        close = difflib.get_close_matches(str(kind), list(_BUILDERS), n=1)
        hint = f"; did you mean '{close[0]}'?" if close else ""
        problems.add(f"{path}.type", f"unknown model type {kind!r}{hint} (known: {', '.join(kinds())})")
        return None
    return _BUILDERS[kind](spec, path, table, problems)


def _load_builtin() -> None:
    # import for the side effect of registration; kept lazy so the core imports fast
    from .structural import build  # noqa: F401
    try:
        from . import multibody  # noqa: F401
    except ImportError as exc:  # pragma: no cover - only while multibody is absent
        if "multibody" not in str(exc):
            raise
