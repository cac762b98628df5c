"""Key checking for case mappings: unknown keys are errors, with a did-you-mean hint."""
from __future__ import annotations

import difflib
from typing import Any, Iterable

from ..errors import ProblemCollector


def check_keys(spec: Any, path: str, allowed: Iterable[str], problems: ProblemCollector,
               required: Iterable[str] = ()) -> bool:
    """Report unknown and missing keys of mapping ``spec`` at YAML ``path``; False if not a mapping."""
    if not isinstance(spec, dict):
        problems.add(path, f"expected a mapping, found {type(spec).__name__} {spec!r}")
        return False
    allowed = sorted(set(allowed))
    for key in spec:
        if key not in allowed:
            close = difflib.get_close_matches(str(key), allowed, n=1)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            problems.add(f"{path}.{key}", f"unknown key{hint} (allowed: {', '.join(allowed)})")
    for key in required:
        if key not in spec:
            problems.add(f"{path}.{key}", "missing required key")
    return True


def did_you_mean(name: Any, options: Iterable[str]) -> str:
    """'; did you mean 'x'?' or '' for an unknown name."""
    close = difflib.get_close_matches(str(name), list(options), n=1)
    return f"; did you mean '{close[0]}'?" if close else ""
