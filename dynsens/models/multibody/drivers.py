r"""Driving constraints (``type: driving``): a joint coordinate, a body coordinate or a distance
prescribed in time — rheonomic constraints φ(q, t) = 0.

The prescribed value is either ``offset + rate·t + amplitude·sin(2π·frequency·t + phase)``
(:class:`.joints.Motion`) or ``expression``: any expression of ``t`` (s) and the design
variables in the restricted evaluator, with its first and second time derivatives evaluated
exactly along by second-order jets (:mod:`dynsens.expressions.jets`), complex-safe for complex step.

================  ================================================  =====================
target            equation                                          x(t) is
================  ================================================  =====================
joint (angle)     sin x (u_i·u_j) − cos x (v_i·u_j)                 the joint angle from
                                                                    the initial pose (rad)
joint (slide)     w_i·d − x                                          the slide (length)
body coordinate   e_k·r − (r_k,given + x)                            the COM's offset from
                                                                    its given coordinate
distance          (d·d)/(2x) − x/2,  d = P_2 − P_1                  the distance |P_2 − P_1|
================  ================================================  =====================

The distance form is in length units and needs x(t) > 0; on the constraint ∂φ/∂P_2 = d/|d|,
so its multiplier λ (N) enters the equations of motion as the force −λ d/|d| on P_2 and
+λ d/|d| on P_1 (the sign convention of every joint: M q̈ + J_Φᵀλ = Q).
"""
from __future__ import annotations

from typing import Any


from ...case_keys import allowed
from ...expressions.restricted import Expression, ExpressionError, compile_expression
from ...expressions.jets import JET_FUNCTIONS, Jet
from .._keys import check_keys, did_you_mean
from .bodies import GROUND, Const, Diff, Point
from .joints import Coef, DotEq, Joint, Motion, Prescribed, const_coef, make_driver
from .spec import Reader

DRIVER_KEYS = allowed("multibody.driver")
MOTION_KEYS = ("offset", "rate", "amplitude", "frequency", "phase")


class ExpressionMotion(Prescribed):
    """x(t) given by an expression of t and the design variables (each read from the parameter
    vector, so stacked parameter sets (pv (B, n)) and blocks of times (t (K, 1)) broadcast)."""

    def __init__(self, expr: Expression, symbols: dict[str, int]):
        self.expr = expr
        self.symbols = symbols

    def __call__(self, t: Any, prm: Any) -> tuple[Any, Any, Any]:
        pv = prm.pv
        env: dict[str, Any] = {n: pv[..., i] for n, i in self.symbols.items()}
        env["t"] = Jet(t, 1.0, 0.0)
        out = self.expr.evaluate(env)
        if not isinstance(out, Jet):          # no t in the expression
            return out, 0.0, 0.0
        return out.v, out.d, out.dd


def _prescribed(rd: Reader, j: dict, jp: str) -> Prescribed | None:
    """The driver's x(t): an ``expression`` or the offset/rate/amplitude form."""
    if "expression" not in j:
        return Motion(*(rd.num(j.get(k, 0.0), f"{jp}.{k}") for k in MOTION_KEYS))
    both = [k for k in MOTION_KEYS if k in j]
    if both:
        rd.problems.add(jp, f"give either 'expression' or {', '.join(repr(k) for k in MOTION_KEYS)}; "
                            f"found both ('expression' and {', '.join(both)})")
        return None
    text = j["expression"]
    names = rd.table.design_names
    if "t" in names:
        rd.problems.add(f"{jp}.expression", "a design variable is named 't', which an expression of "
                                            "time reads as the time: rename the design variable")
        return None
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        text = repr(float(text))
    if not isinstance(text, str):
        rd.problems.add(f"{jp}.expression", f"expected an expression of t and the design variables, "
                                            f"found {text!r}")
        return None
    try:
        expr = compile_expression(text, set(names) | {"t"}, JET_FUNCTIONS)
    except ExpressionError as exc:
        rd.problems.add(f"{jp}.expression", str(exc))
        return None
    symbols = {n: rd.num(n, f"{jp}.expression") for n in sorted(expr.symbols - {"t"})}
    return ExpressionMotion(expr, symbols)


def _half_reciprocal(x: Prescribed) -> Coef:
    """c = 1/(2x) with its time derivatives."""
    def fn(t: float, prm: Any) -> tuple[Any, Any, Any]:
        v, d, dd = x(t, prm)
        r = 0.5 / v
        return r, -2.0 * r * r * d, -2.0 * r * r * dd + 8.0 * r * r * r * d * d
    return fn


def _half(x: Prescribed) -> Coef:
    def fn(t: float, prm: Any) -> tuple[Any, Any, Any]:
        v, d, dd = x(t, prm)
        return 0.5 * v, 0.5 * d, 0.5 * dd
    return fn


def read_driver(rd: Reader, j: dict, jp: str, name: str, by_name: dict[str, Joint]) -> Joint | None:
    """A ``type: driving`` entry of ``joints`` (module docstring)."""
    check_keys(j, jp, DRIVER_KEYS, rd.problems)
    heads = [k for k in ("joint", "body", "distance") if k in j]
    if len(heads) != 1:
        rd.problems.add(jp, "a driver prescribes exactly one of 'joint' (its angle or slide), 'body' "
                            f"(with 'coordinate': x, y or z) or 'distance' ([body.marker, body.marker]); "
                            f"found {heads or 'none'}")
        return None
    x = _prescribed(rd, j, jp)
    if "joint" in j:
        target = by_name.get(j["joint"])
        if target is None:
            rd.problems.add(f"{jp}.joint", f"unknown joint {j['joint']!r} (a driver must follow the "
                                           f"joint it drives){did_you_mean(j['joint'], by_name)}")
            return None
        coord = j.get("coordinate", target.extra.get("drive") or None)
        allowed = {"revolute": ("angle",), "prismatic": ("slide",), "cylindrical": ("angle", "slide")}
        if coord not in allowed.get(target.kind, ()):
            rd.problems.add(f"{jp}.coordinate", f"a {target.kind} joint can be driven in "
                            f"{' or '.join(allowed.get(target.kind, ())) or 'nothing'}; found {coord!r}")
            return None
        if x is None:
            return None
        target.extra["drive"] = coord
        jt = make_driver(name, target, x)
        target.extra["drive"] = {"revolute": "angle", "prismatic": "slide"}.get(target.kind, "")
        return jt
    if "distance" in j:
        pair = j["distance"]
        if not isinstance(pair, list) or len(pair) != 2:
            rd.problems.add(f"{jp}.distance", f"expected [body.marker, body.marker], found {pair!r}")
            return None
        m1, m2 = rd.marker_ref(pair[0], f"{jp}.distance[0]"), rd.marker_ref(pair[1], f"{jp}.distance[1]")
        if m1 is None or m2 is None or x is None:
            return None
        if m1[0] is m2[0]:
            rd.problems.add(f"{jp}.distance", "the two markers must be on different bodies")
            return None
        for (b, key), k in ((m1, 0), (m2, 1)):
            rd.attached(b, key, f"marker {pair[k]} of driver '{name}'")
        d = Diff(Point(m2[0].index, m2[1]), Point(m1[0].index, m1[1]))
        eq = DotEq([(_half_reciprocal(x), d, d)], shift=_half(x))
        return Joint(name, "driving", m1[0].index, m2[0].index, [eq], labels=("drive",))
    body = rd.body(j.get("body"), f"{jp}.body")
    coord = j.get("coordinate")
    if body is None:
        return None
    if body.index == GROUND:
        rd.problems.add(f"{jp}.body", "the ground cannot be driven")
        return None
    if coord not in ("x", "y", "z"):
        rd.problems.add(f"{jp}.coordinate", f"a body driver prescribes x, y or z of the COM; found {coord!r}")
        return None
    if x is None:
        return None
    r0 = body.position["xyz".index(coord)]

    def shift(t: float, prm: Any) -> tuple[Any, Any, Any]:
        # relative to the given initial COM coordinate (read from pv: see joints.Coef)
        v, vd, vdd = x(t, prm)
        return prm.pv[..., r0] + v, vd, vdd
    eq = DotEq([(const_coef(1.0), Const(f"e_{coord}"), Point(body.index, "zero"))], shift=shift)
    return Joint(name, "driving", GROUND, body.index, [eq], labels=("drive",))
