r"""Second-order Taylor jets in time for the restricted expressions (prescribed motions).

A :class:`Jet` carries a value and its first and second time derivatives,
``(f, ḟ, f̈)``.  Arithmetic follows the product and chain rules exactly
(``(fg)¨ = f̈g + 2ḟġ + fg̈``, ``(φ∘u)¨ = φ''(u) u̇² + φ'(u) ü``), so an expression of time
``t`` evaluated on ``Jet(t, 1, 0)`` returns its value and exact derivatives.  Every component
may be a complex number or a numpy array (a block of times against stacked parameter sets),
so complex step of a whole run passes through.  :data:`JET_FUNCTIONS` is the evaluator's
function table with the same names as :data:`dynsens.expressions.restricted.FUNCTIONS`; ``abs``,
``min``, ``max`` branch on real parts as there.
"""
from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from .restricted import FUNCTIONS

Number = Any


class Jet:
    """(value, first, second) time derivative of a quantity."""

    __slots__ = ("v", "d", "dd")
    __array_priority__ = 1000        # numpy arrays defer to the jet's reflected operators

    def __init__(self, v: Number, d: Number = 0.0, dd: Number = 0.0):
        self.v, self.d, self.dd = v, d, dd

    def parts(self) -> tuple[Number, Number, Number]:
        """(value, first, second) time derivative, for checks that look at each."""
        return self.v, self.d, self.dd

    # -------------------------------------------------------------- arithmetic
    def __add__(self, o: Any) -> "Jet":
        o = lift(o)
        return Jet(self.v + o.v, self.d + o.d, self.dd + o.dd)

    __radd__ = __add__

    def __neg__(self) -> "Jet":
        return Jet(-self.v, -self.d, -self.dd)

    def __pos__(self) -> "Jet":
        return self

    def __sub__(self, o: Any) -> "Jet":
        return self + (-lift(o))

    def __rsub__(self, o: Any) -> "Jet":
        return lift(o) + (-self)

    def __mul__(self, o: Any) -> "Jet":
        o = lift(o)
        return Jet(self.v * o.v, self.d * o.v + self.v * o.d,
                   self.dd * o.v + 2.0 * self.d * o.d + self.v * o.dd)

    __rmul__ = __mul__

    def reciprocal(self) -> "Jet":
        r = 1.0 / self.v
        return chain(self, r, -r * r, 2.0 * r * r * r)

    def __truediv__(self, o: Any) -> "Jet":
        return self * lift(o).reciprocal()

    def __rtruediv__(self, o: Any) -> "Jet":
        return lift(o) * self.reciprocal()

    def __pow__(self, o: Any) -> "Jet":
        if isinstance(o, Jet):
            return jexp(o * jlog(self))
        c = o
        if np.ndim(c) == 0 and np.isreal(c):
            if c == 0:
                return Jet(np.ones_like(self.v) if np.ndim(self.v) else 1.0)
            if c == 1:
                return self
            if c == 2:
                return self * self
        return chain(self, self.v ** c, c * self.v ** (c - 1), c * (c - 1) * self.v ** (c - 2))

    def __rpow__(self, o: Any) -> "Jet":
        return jexp(self * np.log(o))

    @property
    def real(self) -> Number:
        return np.real(self.v)


def lift(x: Any) -> Jet:
    """A constant (zero derivatives) as a jet; jets pass through."""
    return x if isinstance(x, Jet) else Jet(x, 0.0, 0.0)


def chain(u: Jet, f0: Number, f1: Number, f2: Number) -> Jet:
    """φ(u) from φ(u.v) = f0, φ'(u.v) = f1, φ''(u.v) = f2."""
    return Jet(f0, f1 * u.d, f2 * u.d * u.d + f1 * u.dd)


def _unary(plain: Callable[[Number], Number], rule: Callable[[Number], tuple[Number, Number, Number]]
           ) -> Callable[[Any], Any]:
    def fn(u: Any) -> Any:
        if not isinstance(u, Jet):
            return plain(u)
        return chain(u, *rule(u.v))
    return fn


def _tan(v: Number) -> tuple[Number, Number, Number]:
    t = np.tan(v)
    s = 1.0 + t * t
    return t, s, 2.0 * t * s


def _sqrt(v: Number) -> tuple[Number, Number, Number]:
    r = np.sqrt(v)
    return r, 0.5 / r, -0.25 / (r * v)


def _asin(v: Number) -> tuple[Number, Number, Number]:
    w = 1.0 - v * v
    return np.arcsin(v), 1.0 / np.sqrt(w), v / (w * np.sqrt(w))


def _acos(v: Number) -> tuple[Number, Number, Number]:
    a, b, c = _asin(v)
    return np.arccos(v), -b, -c


def _atan(v: Number) -> tuple[Number, Number, Number]:
    w = 1.0 + v * v
    return np.arctan(v), 1.0 / w, -2.0 * v / (w * w)


def _tanh(v: Number) -> tuple[Number, Number, Number]:
    t = np.tanh(v)
    s = 1.0 - t * t
    return t, s, -2.0 * t * s


_LN10 = math.log(10.0)
jexp = _unary(np.exp, lambda v: (np.exp(v),) * 3)
jlog = _unary(np.log, lambda v: (np.log(v), 1.0 / v, -1.0 / (v * v)))


def _select(cond: Any, a: Any, b: Any) -> Any:
    """Elementwise a where cond else b, for jets or numbers (cond on real parts)."""
    if not isinstance(a, Jet) and not isinstance(b, Jet):
        return np.where(cond, a, b) if np.ndim(cond) else (a if cond else b)
    a, b = lift(a), lift(b)
    if np.ndim(cond):
        return Jet(np.where(cond, a.v, b.v), np.where(cond, a.d, b.d), np.where(cond, a.dd, b.dd))
    return a if cond else b


def _value(x: Any) -> Number:
    return x.v if isinstance(x, Jet) else x


def _jabs(u: Any) -> Any:
    return _select(np.real(_value(u)) >= 0, u, -u if isinstance(u, Jet) else -np.asarray(u))


def _jmin(*args: Any) -> Any:
    out = args[0]
    for a in args[1:]:
        out = _select(np.real(_value(a)) < np.real(_value(out)), a, out)
    return out


def _jmax(*args: Any) -> Any:
    out = args[0]
    for a in args[1:]:
        out = _select(np.real(_value(a)) > np.real(_value(out)), a, out)
    return out


def _atan2_value(y: Number, x: Number) -> Number:
    base = np.arctan2(np.real(y), np.real(x))
    if np.iscomplexobj(y) or np.iscomplexobj(x):
        # analytic continuation away from the branch cut (as expressions._atan2)
        return base + (np.arctan(y / x) - np.arctan(np.real(y) / np.real(x)))
    return base


def _jatan2(y: Any, x: Any) -> Any:
    if not isinstance(y, Jet) and not isinstance(x, Jet):
        return FUNCTIONS["atan2"](y, x) if np.ndim(y) == 0 and np.ndim(x) == 0 else _atan2_value(y, x)
    y, x = lift(y), lift(x)
    D = x.v * x.v + y.v * y.v
    N = x.v * y.d - y.v * x.d
    Nd = x.v * y.dd - y.v * x.dd
    Dd = 2.0 * (x.v * x.d + y.v * y.d)
    return Jet(_atan2_value(y.v, x.v), N / D, (Nd * D - N * Dd) / (D * D))


JET_FUNCTIONS: dict[str, Callable[..., Any]] = {
    "sin": _unary(np.sin, lambda v: (np.sin(v), np.cos(v), -np.sin(v))),
    "cos": _unary(np.cos, lambda v: (np.cos(v), -np.sin(v), -np.cos(v))),
    "tan": _unary(np.tan, _tan),
    "asin": _unary(np.arcsin, _asin), "acos": _unary(np.arccos, _acos), "atan": _unary(np.arctan, _atan),
    "atan2": _jatan2,
    "sinh": _unary(np.sinh, lambda v: (np.sinh(v), np.cosh(v), np.sinh(v))),
    "cosh": _unary(np.cosh, lambda v: (np.cosh(v), np.sinh(v), np.cosh(v))),
    "tanh": _unary(np.tanh, _tanh),
    "sqrt": _unary(np.sqrt, _sqrt), "exp": jexp, "log": jlog,
    "log10": _unary(np.log10, lambda v: (np.log10(v), 1.0 / (v * _LN10), -1.0 / (v * v * _LN10))),
    "abs": _jabs, "min": _jmin, "max": _jmax,
    "deg": lambda a: a * (180.0 / math.pi), "rad": lambda a: a * (math.pi / 180.0),
}
assert set(JET_FUNCTIONS) == set(FUNCTIONS), "the jet table must offer every evaluator function"
