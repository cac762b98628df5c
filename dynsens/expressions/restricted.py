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

from ..errors import DynsensError

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
# number of arguments of each function (0: one or more); the rest take one
_ARITY = {"atan2": 2, "min": 0, "max": 0}
#: names a case may not give to its own variables, responses or events (an expression
#: would read the constant or function instead)
RESERVED_NAMES: frozenset[str] = frozenset(CONSTANTS) | frozenset(FUNCTIONS)
#: deepest nesting of parentheses, calls and powers (chains of + - and * / are flat)
MAX_DEPTH = 100
MAX_LENGTH = 2000

_BINOPS: dict[type, Callable[[Number, Number], Number]] = {
    ast.Add: lambda a, b: a + b,
    ast.Sub: lambda a, b: a - b,
    ast.Mult: lambda a, b: a * b,
    ast.Div: lambda a, b: a / b,
    ast.Pow: lambda a, b: a ** b,
}


# the types of a real symbol value that a bare symbol's expression returns as it is
_REAL = (float, np.float64)


class ExpressionError(DynsensError, ValueError):
    """An expression could not be parsed, names something unknown, or has no finite value."""


def _parts(value: Any) -> tuple[Any, ...]:
    """The numbers a value is made of: itself, or a jet's value and time derivatives."""
    return value.parts() if hasattr(value, "parts") else (value,)


def _describe(exc: BaseException) -> str:
    if isinstance(exc, ZeroDivisionError) or "divide" in str(exc):
        return "division by zero"
    if isinstance(exc, OverflowError) or "overflow" in str(exc).lower():
        return "the result overflows (too large for a floating-point number)"
    if "invalid" in str(exc) or isinstance(exc, ValueError):
        return f"a value outside a function's domain ({exc})"
    return str(exc)


@dataclass(frozen=True)
class Expression:
    """A compiled expression: ``evaluate(env)`` returns its value for the given symbols."""

    text: str
    symbols: frozenset[str]
    _fn: Callable[[Mapping[str, Number]], Number]
    #: the symbol when the expression is that symbol alone (every element's own design variable)
    bare: str | None = None

    def _bare_value(self, env: Mapping[str, Number]) -> Number | None:
        """The value of the one symbol the expression is, when that is a finite real; else None."""
        if self.bare is None:
            return None
        value = env[self.bare]
        return value if type(value) in _REAL and math.isfinite(value) else None

    def evaluate(self, env: Mapping[str, Number]) -> Number:
        """Value of the expression with the symbol values in ``env`` (units as the symbols).

        Raises ExpressionError (naming the expression and the values) for a division by
        zero, an overflow, a value outside a function's domain (e.g. ``log(-1)``), a complex
        result from real values, or any other non-finite result.
        """
        value = self._bare_value(env)
        if value is not None:
            return value            # the symbol's own value, which the checks below would pass
        try:
            with np.errstate(divide="raise", over="raise", invalid="raise", under="ignore"):
                value = self._fn(env)
        except (ArithmeticError, ValueError, TypeError) as exc:
            raise ExpressionError(f"expression '{_short(self.text)}' cannot be evaluated{self._at(env)}: "
                                  f"{_describe(exc)}") from None
        parts = _parts(value)
        if any(np.iscomplexobj(v) for v in parts) and \
                not any(np.iscomplexobj(v) for n in self.symbols for v in _parts(env[n])):
            raise ExpressionError(f"expression '{_short(self.text)}' gives a complex value{self._at(env)} "
                                  f"(found {complex(np.ravel(parts[0])[0])}): a real number was expected")
        if not all(np.all(np.isfinite(v)) for v in parts):
            raise ExpressionError(f"expression '{_short(self.text)}' gives {np.real(parts[0])!r}{self._at(env)}: "
                                  "a finite number was expected")
        return value

    def derivative_problem(self, env: Mapping[str, float]) -> str | None:
        """Why the expression has no finite derivative at the real values ``env``, or None.

        The complex-step derivative of a smooth expression does not depend on the step; at a
        singular point (``sqrt(c)`` at c = 0) it grows like a power of 1/step.  Two steps,
        1e-30 and 1e-20, tell the two apart."""
        if self._bare_value(env) is not None:
            return None             # a symbol alone: its derivative is 1
        for name in sorted(self.symbols):
            d = []
            for h in (1e-30, 1e-20):
                pert: dict[str, Any] = dict(env)
                pert[name] = env[name] + 1j * h
                try:
                    with np.errstate(all="ignore"):
                        d.append(float(np.imag(self._fn(pert))) / h)
                except (ArithmeticError, ValueError, TypeError):
                    d.append(float("inf"))
            if not all(np.isfinite(d)) or abs(d[0] - d[1]) > 1e-6 * max(abs(d[0]), abs(d[1]), 1.0):
                return (f"expected an expression with a finite derivative, found that of '{_short(self.text)}' with "
                        f"respect to {name} is not finite{self._at(env)} (complex-step slopes {d[0]:.3g} and "
                        f"{d[1]:.3g} for steps 1e-30 and 1e-20): the gradient would be meaningless there")
        return None

    def _at(self, env: Mapping[str, Number]) -> str:
        if not self.symbols:
            return ""
        vals = ", ".join(f"{n} = {np.real(env[n]):.6g}" if isinstance(env[n], (int, float, complex, np.number))
                         else f"{n} = {env[n]!r}"
                         for n in sorted(self.symbols))
        return f" at {vals}"

    @property
    def is_constant(self) -> bool:
        """True when the expression names no symbol."""
        return not self.symbols


_CHAINS = ((ast.Add, ast.Sub), (ast.Mult, ast.Div))


def _chain(node: ast.BinOp) -> tuple[list[ast.AST], list[type]]:
    """Operands and operators of a left-nested chain ``a + b - c + ...`` (or ``* /``)."""
    family = next(f for f in _CHAINS if isinstance(node.op, f))
    ops: list[type] = []
    operands: list[ast.AST] = []
    cur: ast.AST = node
    while isinstance(cur, ast.BinOp) and isinstance(cur.op, family):
        ops.append(type(cur.op))
        operands.append(cur.right)
        cur = cur.left
    operands.append(cur)
    return operands[::-1], ops[::-1]


def _member_symbol(node: ast.AST) -> str | None:
    """``A[diag7]`` (a member of the design-variable family A) as the symbol 'A[diag7]'."""
    if isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name):
        key = node.slice
        if isinstance(key, ast.Name):
            return f"{node.value.id}[{key.id}]"
        if isinstance(key, ast.Constant) and isinstance(key.value, int) and not isinstance(key.value, bool):
            return f"{node.value.id}[{key.value}]"
    return None


Compiled = Callable[[Mapping[str, Number]], Number]


class _Compiler:
    """Turns the syntax tree of one expression into nested closures: one method per kind of node
    (``_KINDS``); any other node is not allowed.  ``names`` collects the symbols read."""

    def __init__(self, text: str, known: frozenset[str] | None,
                 functions: Mapping[str, Callable[..., Number]] | None):
        self.text = text
        self.known = known
        self.table = FUNCTIONS if functions is None else functions
        self.names: set[str] = set()

    def compile(self, node: ast.AST, depth: int = 0) -> Compiled:
        if depth > MAX_DEPTH:
            raise ExpressionError(f"expression '{_short(self.text)}' nests parentheses, calls or powers more than "
                                  f"{MAX_DEPTH} levels deep: split it into simpler terms")
        handler = self._KINDS.get(type(node))
        fn = handler(self, node, depth) if handler is not None else None
        if fn is None:
            raise ExpressionError(
                f"expression '{self.text}': '{ast.dump(node)[:40]}...' is not allowed "
                "(only numbers, names, + - * / **, parentheses and math functions)")
        return fn

    def _expression(self, node: ast.Expression, depth: int) -> Compiled:
        return self.compile(node.body, depth)

    def _binop(self, node: ast.BinOp, depth: int) -> Compiled | None:
        if isinstance(node.op, (ast.Add, ast.Sub, ast.Mult, ast.Div)):
            return self._chain(node, depth)
        if type(node.op) not in _BINOPS:
            return None
        op = _BINOPS[type(node.op)]
        left = self.compile(node.left, depth + 1)
        right = self.compile(node.right, depth + 1)
        return lambda env: op(left(env), right(env))

    def _chain(self, node: ast.BinOp, depth: int) -> Compiled:
        """A long sum (or product) is evaluated in a loop, not by one nested call per term."""
        operands, ops = _chain(node)
        first, *rest = [self.compile(o, depth + 1) for o in operands]
        if not rest:
            return first
        fns = [_BINOPS[o] for o in ops]
        pairs = list(zip(fns, rest))

        def chain(env: Mapping[str, Number]) -> Number:
            acc = first(env)
            for op, term in pairs:
                acc = op(acc, term(env))
            return acc
        return chain

    def _constant(self, node: ast.Constant, depth: int) -> Compiled | None:
        if not isinstance(node.value, (int, float)) or isinstance(node.value, bool):
            return None
        try:
            value = float(node.value)
        except OverflowError:
            raise ExpressionError(f"expression '{_short(self.text)}' has a number too large for a floating-point "
                                  "value") from None
        return lambda env: value

    def _name(self, node: ast.Name, depth: int) -> Compiled:
        return self._symbol(node.id)

    def _subscript(self, node: ast.Subscript, depth: int) -> Compiled | None:
        member = _member_symbol(node)
        return None if member is None else self._symbol(member)

    def _symbol(self, name: str) -> Compiled:
        """A constant (pi, ...) or a symbol the environment gives (checked against ``known``)."""
        if name in CONSTANTS:
            c = CONSTANTS[name]
            return lambda env: c
        if self.known is not None and name not in self.known:
            close = difflib.get_close_matches(name, sorted(self.known), n=1)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            raise ExpressionError(
                f"expression '{self.text}' names unknown symbol '{name}'{hint} "
                f"(known: {', '.join(sorted(self.known)) or 'none'})")
        self.names.add(name)
        return lambda env: env[name]

    def _unary(self, node: ast.UnaryOp, depth: int) -> Compiled | None:
        if not isinstance(node.op, (ast.USub, ast.UAdd)):
            return None
        operand = self.compile(node.operand, depth + 1)
        if isinstance(node.op, ast.USub):
            return lambda env: -operand(env)
        return operand

    def _call(self, node: ast.Call, depth: int) -> Compiled | None:
        if not isinstance(node.func, ast.Name) or node.keywords:
            return None
        fname = node.func.id
        if fname not in self.table:
            raise ExpressionError(
                f"expression '{self.text}' calls '{fname}', which is not allowed "
                f"(allowed: {', '.join(sorted(self.table))})")
        want = _ARITY.get(fname, 1)
        if (len(node.args) != want) if want else not node.args:
            raise ExpressionError(
                f"expression '{_short(self.text)}': {fname}() takes "
                f"{f'{want} argument' + ('s' if want > 1 else '') if want else 'one or more arguments'}, "
                f"found {len(node.args)}")
        fn = self.table[fname]
        args = [self.compile(a, depth + 1) for a in node.args]
        return lambda env: fn(*(a(env) for a in args))

    _KINDS: dict[type, Callable[..., Compiled | None]] = {
        ast.Expression: _expression, ast.BinOp: _binop, ast.Constant: _constant, ast.Name: _name,
        ast.Subscript: _subscript, ast.UnaryOp: _unary, ast.Call: _call}


def compile_expression(text: str, known: frozenset[str] | set[str] | None = None,
                       functions: Mapping[str, Callable[..., Number]] | None = None) -> Expression:
    """Parse ``text`` into an :class:`Expression`.

    Parameters
    ----------
    text : the expression, e.g. ``"0.5*m + 1e-3"``.
    known : allowed symbol names; ``None`` accepts any name.
    functions : the function table (default :data:`FUNCTIONS`; :data:`dynsens.expressions.jets.JET_FUNCTIONS`
        evaluates time derivatives along).

    Raises
    ------
    ExpressionError : syntax errors, disallowed constructs, unknown symbols.
    """
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"expected an expression of at most {MAX_LENGTH} characters, found {len(text)}")
    try:
        tree = ast.parse(text.strip(), mode="eval")
        compiler = _Compiler(text, frozenset(known) if known is not None else None, functions)
        fn = compiler.compile(tree)
    except SyntaxError as exc:
        raise ExpressionError(f"expression '{_short(text)}' is not valid: {exc.msg}") from None
    except (RecursionError, MemoryError):
        raise ExpressionError(f"expression '{_short(text)}' nests too deeply: split it into simpler terms") \
            from None
    body = tree.body
    bare = body.id if isinstance(body, ast.Name) and body.id in compiler.names else None
    return Expression(text, frozenset(compiler.names), fn, bare)


def _short(text: str) -> str:
    return text if len(text) <= 80 else text[:60] + " ... " + text[-15:]
