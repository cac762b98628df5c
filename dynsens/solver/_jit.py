"""numba where it is installed, for every compiled piece of dynsens (the multibody kernel, the
compiled steps, the checks a compiled step shares with the Python path).

* ``register_jitable``: the function stays plain Python and is compiled into the compiled
  functions that call it (the identity without numba);
* ``jit`` / ``inline``: compiled functions cached on disk beside the package (``inline``: always
  inlined into their callers, for small helpers that take arrays);
* :func:`enabled`: whether compiled code is used at all (``DYNSENS_KERNEL``).
"""
from __future__ import annotations

import os
from typing import Any

from ..errors import ConfigurationError

try:  # numba is a dependency; without it (an unsupported platform) everything runs as Python
    from numba import njit
    from numba.extending import register_jitable
    HAVE_NUMBA = True
except ImportError:  # pragma: no cover - exercised only where numba cannot be installed
    HAVE_NUMBA = False

    def register_jitable(fn: Any) -> Any:
        return fn

KERNELS = ("compiled", "numpy")

if HAVE_NUMBA:
    jit = njit(cache=True, nogil=True)
    # small helpers inlined into their callers: a call that passes arrays costs reference
    # counting that exceeds the helper's arithmetic
    inline = njit(cache=True, nogil=True, inline="always")
else:  # pragma: no cover
    def jit(fn: Any) -> Any:
        return fn
    inline = jit


def enabled() -> bool:
    """Whether compiled code is used (the multibody kernel, the compiled steps): numba importable
    and the environment variable ``DYNSENS_KERNEL`` unset or ``compiled`` (``numpy``: numpy and
    Python only).

    Raises ConfigurationError for any other value of ``DYNSENS_KERNEL``.
    """
    choice = os.environ.get("DYNSENS_KERNEL", "compiled").strip().lower() or "compiled"
    if choice not in KERNELS:
        raise ConfigurationError(
            f"environment variable DYNSENS_KERNEL = {os.environ['DYNSENS_KERNEL']!r}: expected one of "
            f"{', '.join(KERNELS)} (unset means compiled)")
    return HAVE_NUMBA and choice == "compiled"


__all__ = ["HAVE_NUMBA", "KERNELS", "enabled", "inline", "jit", "register_jitable"]
