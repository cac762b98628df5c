"""The time loop does not know the derivative modes (issue 32): ``march.integrate`` reaches the
mode only through the DerivativeMode protocol, so its source names neither direct nor adjoint
differentiation — no ``method == "direct"``, no ``isinstance(mode, AdjointMode)``, no
``adjoint=`` keyword, no string naming a mode.  The check parses march.py with ``ast``."""
from __future__ import annotations

import ast
import re
from pathlib import Path

import dynsens.timeloop.march

MODE_WORDS = {"direct", "adjoint"}
MODE_CLASSES = {"DirectMode", "AdjointMode", "PrimalOnlyMode"}


def _words(identifier: str) -> set[str]:
    """The lowercase words of a snake_case or CamelCase identifier."""
    parts = re.split(r"_|(?<=[a-z0-9])(?=[A-Z])", identifier)
    return {p.lower() for p in parts if p}


def mode_names(function: ast.FunctionDef) -> list[str]:
    """Every place in ``function`` that names a derivative mode: identifiers, attributes,
    keyword arguments and string constants containing the word direct or adjoint, and the
    mode classes."""
    found = []
    for node in ast.walk(function):
        names: list[str] = []
        if isinstance(node, ast.Name):
            names = [node.id]
        elif isinstance(node, ast.Attribute):
            names = [node.attr]
        elif isinstance(node, ast.keyword) and node.arg is not None:
            names = [node.arg]
        elif isinstance(node, ast.arg):
            names = [node.arg]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            if MODE_WORDS & set(re.findall(r"[a-z]+", node.value.lower())):
                found.append(f"line {node.lineno}: string {node.value!r}")
            continue
        for name in names:
            if name in MODE_CLASSES or MODE_WORDS & _words(name):
                found.append(f"line {node.lineno}: {name}")
    return found


def _integrate() -> ast.FunctionDef:
    tree = ast.parse(Path(dynsens.timeloop.march.__file__).read_text(encoding="utf-8"))
    return next(n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == "integrate")


def test_integrate_names_no_derivative_mode() -> None:
    assert mode_names(_integrate()) == []


def test_the_check_finds_the_mode_names_the_loop_used_to_have() -> None:
    # the forms the loop had before the protocol: the check must not pass them
    old = ast.parse('''
def integrate(plan, mode, responses, params, partials, model):
    method, reason = choose_method(plan)
    responses.start(params, partials if method == "direct" else None, trace=method == "adjoint")
    return responses.finish(adjoint=mode.gradients if isinstance(mode, AdjointMode) else None)
''').body[0]
    assert isinstance(old, ast.FunctionDef)
    found = " ".join(mode_names(old))
    for expected in ("'direct'", "'adjoint'", "AdjointMode", ": adjoint"):
        assert expected in found, (expected, found)
    clean = ast.parse("def integrate(mode, responses):\n    return mode.finish_responses(responses)\n").body[0]
    assert isinstance(clean, ast.FunctionDef)
    assert mode_names(clean) == []
