"""``--set key.path=value`` overrides applied to the raw YAML mapping before validation."""
from __future__ import annotations

import re
from typing import Any

from ..errors import CaseError, Problem
from .yamltext import parse_yaml

_TOKEN = re.compile(r"([^.\[\]]+)|\[(\d+)\]")


def apply_overrides(raw: dict, overrides: list[str], source: str | None = None) -> dict:
    """Apply ``KEY=VALUE`` strings (dotted paths, ``[i]`` list indices) to ``raw`` in place.

    VALUE is parsed as YAML (so ``1e-3`` is a number and ``[a, b]`` a list).
    """
    problems = []
    for item in overrides:
        if "=" not in item:
            problems.append(Problem(f"--set {item}", "expected KEY=VALUE, e.g. integrator.dt=1e-3"))
            continue
        key, text = item.split("=", 1)
        try:
            value = parse_yaml(text, f"--set {key}")
        except CaseError as exc:
            problems.append(Problem(f"--set {key}", f"value {text!r} is not valid: "
                                                    + "; ".join(str(p) for p in exc.problems)))
            continue
        tokens = [(m.group(1), m.group(2)) for m in _TOKEN.finditer(key.strip())]
        if not tokens:
            problems.append(Problem(f"--set {item}", "empty key"))
            continue
        node: Any = raw
        ok = True
        for pos, (name, idx) in enumerate(tokens[:-1]):
            nxt = tokens[pos + 1]
            if idx is not None:
                if not isinstance(node, list) or int(idx) >= len(node):
                    problems.append(Problem(f"--set {key}", f"index [{idx}] does not exist"))
                    ok = False
                    break
                node = node[int(idx)]
            else:
                if not isinstance(node, dict):
                    problems.append(Problem(f"--set {key}", f"'{name}' is not inside a mapping"))
                    ok = False
                    break
                if name not in node:
                    node[name] = [] if nxt[1] is not None else {}
                node = node[name]
        if not ok:
            continue
        name, idx = tokens[-1]
        if idx is not None:
            if not isinstance(node, list) or int(idx) >= len(node):
                problems.append(Problem(f"--set {key}", f"index [{idx}] does not exist"))
                continue
            node[int(idx)] = value
        elif isinstance(node, dict):
            node[name] = value
        else:
            problems.append(Problem(f"--set {key}", f"'{name}' is not inside a mapping"))
    if problems:
        raise CaseError(problems, source)
    return raw
