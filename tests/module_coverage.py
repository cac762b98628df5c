"""Which dynsens modules a test run exercised: the check behind ``make test-fast``.

Enabled by the environment variable ``DYNSENS_MODULE_COVERAGE=DIR`` (``conftest.py`` registers
this plugin then).  Each pytest process, the pytest-xdist workers included, writes
``DIR/<worker>.json`` at its end with

- ``ran``: the dynsens source files in which at least one function ran (a module's or a class's
  body, which an import runs, is not a function; a function that an import calls, such as a
  key table's row builder, is).  A ``sys.settrace``
  hook sees every new Python frame and returns no local tracer, so no line events are made:
  the cost is one small call per Python function call (the suite's time is spent in numpy,
  scipy and compiled kernels);
- ``compiled``: the files whose numba-compiled functions were called: they make no Python
  frame, but a dispatcher that was called holds at least one compiled signature;
- ``imported``: the dynsens modules in ``sys.modules``.

``scripts/check_module_coverage.py DIR`` merges them and fails on a module of ``dynsens/`` that
no test exercised: one with functions none of which ran, or one never imported.  This is
lighter than ``coverage`` (not installed, and line coverage is not what is asked: every module
exercised by at least one test).  Code run only in subprocesses (``--workers N``) is not seen,
which can only make the check stricter.
"""
from __future__ import annotations

import inspect
import json
import os
import sys
import threading
from pathlib import Path
from typing import Any

PACKAGE = Path(__file__).resolve().parents[1] / "dynsens"
_ran: set[str] = set()


def _on_call(frame: Any, event: str, arg: Any) -> None:
    """Global trace function: note the file of a function's frame, trace nothing inside it.

    Module and class bodies (run by an import) are not functions (no CO_OPTIMIZED flag)."""
    code = frame.f_code
    if code.co_flags & inspect.CO_OPTIMIZED:
        _ran.add(code.co_filename)
    return None


def _compiled_files() -> set[str]:
    """Files of dynsens modules with a numba dispatcher that holds a compiled signature."""
    out = set()
    for name, mod in list(sys.modules.items()):
        if not name.startswith("dynsens") or mod is None:
            continue
        for obj in list(vars(mod).values()):
            py_func = getattr(obj, "py_func", None)
            if py_func is not None and getattr(obj, "signatures", None):
                out.add(py_func.__code__.co_filename)
    return out


def pytest_configure(config: Any) -> None:
    sys.settrace(_on_call)
    threading.settrace(_on_call)


def pytest_unconfigure(config: Any) -> None:
    sys.settrace(None)
    threading.settrace(None)     # type: ignore[arg-type]
    folder = Path(os.environ["DYNSENS_MODULE_COVERAGE"])
    folder.mkdir(parents=True, exist_ok=True)
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    inside = str(PACKAGE) + os.sep

    def rel(paths: set[str]) -> list[str]:
        return sorted(str(Path(p).resolve().relative_to(PACKAGE.parent)) for p in paths
                      if str(Path(p).resolve()).startswith(inside))

    imported = {getattr(m, "__file__", None) or "" for n, m in list(sys.modules.items())
                if n.startswith("dynsens") and m is not None}
    data = {"ran": rel(_ran), "compiled": rel(_compiled_files()), "imported": rel(imported)}
    (folder / f"{worker}.json").write_text(json.dumps(data, indent=1), encoding="utf-8")
