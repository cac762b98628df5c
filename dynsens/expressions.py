"""Restricted, complex-step-safe arithmetic expressions for case files.

Any numeric entry of a case may be a number or a string such as ``"2*l_AZ*cos(theta)"``.
The string is parsed with :mod:`ast` and only numbers, names (``A[diag7]``: the member
diag7 of a design-variable family A), ``+ - * / **``, unary
signs, parentheses and calls of the whitelisted math functions are accepted; the tree
is turned into nested closures.  Nothing is ever passed to ``eval``.

All functions accept complex arguments so that a complex-step derivative of a whole
simulation passes through the expressions unchanged (``abs``, ``min``, ``max`` branch
on the real part).
"""
from __future__ import annotations

import ast
import difflib
import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np

from .errors import DynsensError

Number = Any  # float or complex scalar, or numpy scalar/array


def _cs_abs(a: Number) -> Number:
    return a if np.real(a) >= 0 else -a


def _cs_min(*args: Number) -> Number:
    return min(args, key=lambda v: np.real(v))


def _cs_max(*args: Number) -> Number:
    return max(args, key=lambda v: np.real(v))


def _atan2(y: Number, x: Number) -> Number:
    if np.iscomplexobj(y) or np.iscomplexobj(x):
        # atan2 = angle of (x + i y); analytic continuation valid away from the branch cut
        base = math.atan2(float(np.real(y)), float(np.real(x)))
        return base + (np.arctan(y / x) - np.arctan(np.real(y) / np.real(x)))
    return math.atan2(y, x)


FUNCTIONS: dict[str, Callable[..., Number]] = {
    "sin": np.sin, "cos": np.cos, "tan": np.tan,
    "asin": np.arcsin, "acos": np.arccos, "atan": np.arctan, "atan2": _atan2,
    "sinh": np.sinh, "cosh": np.cosh, "tanh": np.tanh,
    "sqrt": np.sqrt, "exp": np.exp, "log": np.log, "log10": np.log10,
    "abs": _cs_abs, "min": _cs_min, "max": _cs_max,
    "deg": lambda a: a * (180.0 / math.pi), "rad": lambda a: a * (math.pi / 180.0),
}
CONSTANTS: dict[str, float] = {"pi": math.pi, "e": math.e}

_BINOPS: dict[type, Callable[[Number, Number], Number]] = {
    ast.Add: lambda a, b: a + b,
    ast.Sub: lambda a, b: a - b,
    ast.Mult: lambda a, b: a * b,
    ast.Div: lambda a, b: a / b,
    ast.Pow: lambda a, b: a ** b,
}


class ExpressionError(DynsensError, ValueError):
    """An expression could not be parsed or names something unknown."""


@dataclass(frozen=True)
class Expression:
    """A compiled expression: ``evaluate(env)`` returns its value for the given symbols."""

    text: str
    symbols: frozenset[str]
    _fn: Callable[[Mapping[str, Number]], Number]

    def evaluate(self, env: Mapping[str, Number]) -> Number:
        """Value of the expression with the symbol values in ``env`` (units as the symbols)."""
        return self._fn(env)

    @property
    def is_constant(self) -> bool:
        """True when the expression names no symbol."""
        return not self.symbols


def _member_symbol(node: ast.AST) -> str | None:
    """``A[diag7]`` (a member of the design-variable family A) as the symbol 'A[diag7]'."""
    if isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name):
        key = node.slice
        if isinstance(key, ast.Name):
            return f"{node.value.id}[{key.id}]"
        if isinstance(key, ast.Constant) and isinstance(key.value, int) and not isinstance(key.value, bool):
            return f"{node.value.id}[{key.value}]"
    return None


def _compile_node(node: ast.AST, names: set[str], known: frozenset[str] | None,
                  text: str) -> Callable[[Mapping[str, Number]], Number]:
    if isinstance(node, ast.Expression):
        return _compile_node(node.body, names, known, text)
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) \
            and not isinstance(node.value, bool):
        value = float(node.value)
        return lambda env: value
    member = _member_symbol(node)
    if isinstance(node, ast.Name) or member is not None:
        name = member or node.id
        if name in CONSTANTS:
            c = CONSTANTS[name]
            return lambda env: c
        if known is not None and name not in known:
            close = difflib.get_close_matches(name, sorted(known), n=1)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            raise ExpressionError(
                f"expression '{text}' names unknown symbol '{name}'{hint} "
                f"(known: {', '.join(sorted(known)) or 'none'})")
        names.add(name)
        return lambda env: env[name]
    if isinstance(node, ast.BinOp) and type(node.op) in _BINOPS:
        op = _BINOPS[type(node.op)]
        left = _compile_node(node.left, names, known, text)
        right = _compile_node(node.right, names, known, text)
        return lambda env: op(left(env), right(env))
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        operand = _compile_node(node.operand, names, known, text)
        if isinstance(node.op, ast.USub):
            return lambda env: -operand(env)
        return operand
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and not node.keywords:
        fname = node.func.id
        if fname not in FUNCTIONS:
            raise ExpressionError(
                f"expression '{text}' calls '{fname}', which is not allowed "
                f"(allowed: {', '.join(sorted(FUNCTIONS))})")
        fn = FUNCTIONS[fname]
        args = [_compile_node(a, names, known, text) for a in node.args]
        return lambda env: fn(*(a(env) for a in args))
    raise ExpressionError(
        f"expression '{text}': '{ast.dump(node)[:40]}...' is not allowed "
        "(only numbers, names, + - * / **, parentheses and math functions)")


def compile_expression(text: str, known: frozenset[str] | set[str] | None = None) -> Expression:
    """Parse ``text`` into an :class:`Expression`.

    Parameters
    ----------
    text : the expression, e.g. ``"0.5*m + 1e-3"``.
    known : allowed symbol names; ``None`` accepts any name.

    Raises
    ------
    ExpressionError : syntax errors, disallowed constructs, unknown symbols.
    """
    if len(text) > 2000:
        raise ExpressionError("expression longer than 2000 characters")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        raise ExpressionError(f"expression '{text}' is not valid: {exc.msg}") from None
    names: set[str] = set()
    fn = _compile_node(tree, names, frozenset(known) if known is not None else None, text)
    return Expression(text, frozenset(names), fn)
