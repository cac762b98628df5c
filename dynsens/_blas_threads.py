"""One BLAS thread for the OpenBLAS libraries already loaded when dynsens is imported.

``import dynsens`` sets ``OPENBLAS_NUM_THREADS=1`` (unless the user set it), which OpenBLAS
reads when it loads.  When numpy or scipy was imported first, their OpenBLAS had already
started its threads: a product or a dot then sums in another order, and a run's last bits — an
optimizer's path, and with it the optimum to ~1e-5 (the lightweight truss: measured 2e-5) —
depended on the import order.  Here the loaded OpenBLAS libraries (numpy's and scipy's wheels
bundle their own) are set to one thread through their exported ``*_set_num_threads``.

Linux only (the loaded libraries are read from ``/proc/self/maps``); elsewhere, and for MKL or
Accelerate, import dynsens before numpy or set the variables before Python starts.
"""
from __future__ import annotations

import ctypes
import sys
from typing import Any

# the names OpenBLAS builds export (plain, 64-bit-integer, and the scipy-openblas wheels')
_SETTERS = ("openblas_set_num_threads", "openblas_set_num_threads64_", "scipy_openblas_set_num_threads",
            "scipy_openblas_set_num_threads64_")
_GETTERS = tuple(name.replace("_set_", "_get_") for name in _SETTERS)


def loaded_openblas() -> list[str]:
    """Paths of the OpenBLAS shared libraries loaded in this process (Linux; else empty)."""
    if not sys.platform.startswith("linux"):
        return []
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as maps:
            paths = {line.split(maxsplit=5)[-1].strip() for line in maps if "/" in line}
    except OSError:
        return []
    return sorted(p for p in paths if "openblas" in p.rsplit("/", 1)[-1].lower() and ".so" in p)


def _function(path: str, names: tuple[str, ...]) -> Any:
    """The first of ``names`` the library at ``path`` exports (a ctypes function), or None."""
    try:
        lib = ctypes.CDLL(path)
    except OSError:
        return None
    return next((f for f in (getattr(lib, name, None) for name in names) if f is not None), None)


def single_threaded_openblas() -> None:
    """Set every loaded OpenBLAS library to one thread."""
    for path in loaded_openblas():
        setter = _function(path, _SETTERS)
        if setter is not None:
            setter.argtypes, setter.restype = [ctypes.c_int], None
            setter(1)


def openblas_threads() -> dict[str, int]:
    """The thread count of each loaded OpenBLAS library (file name -> threads), for tests."""
    out = {}
    for path in loaded_openblas():
        getter = _function(path, _GETTERS)
        if getter is not None:
            getter.argtypes, getter.restype = [], ctypes.c_int
            out[path.rsplit("/", 1)[-1]] = int(getter())
    return out
