"""numba's ``register_jitable`` where numba is installed (the function stays plain Python and is
compiled into the compiled functions that call it), the identity otherwise: for the checks and
tests the Python path and a compiled step share."""
from __future__ import annotations

from typing import Any

try:
    from numba.extending import register_jitable
except ImportError:  # pragma: no cover - numba is a dependency; without it, Python only
    def register_jitable(fn: Any) -> Any:
        return fn

__all__ = ["register_jitable"]
