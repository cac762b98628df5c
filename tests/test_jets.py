"""Second-order time jets of the restricted expressions: value, first and second derivatives
against complex step (first) and complex step of the jet's own first derivative, checked
independently by central differences of the plain expression (second)."""
from __future__ import annotations

import numpy as np
import pytest

from dynsens.expressions.restricted import FUNCTIONS, compile_expression
from dynsens.expressions.jets import JET_FUNCTIONS, Jet

EXPRS = ["a*t**2/2 + 0.05*sin(5*t)", "sqrt(1+t**2)*exp(-a*t)", "atan2(sin(t), 2+cos(t))",
         "log(2+t)/(1+t)**1.5", "tanh(t)*asin(0.3*t) + acos(0.2*t) + atan(t)",
         "abs(t-0.4)**3 + max(t, a)*min(t, 2) + cosh(t) - sinh(t) + tan(t) + log10(1+t)",
         "2**t + t**a + deg(rad(t)) + 1/(t + a)"]


@pytest.mark.parametrize("text", EXPRS)
@pytest.mark.parametrize("t0", [0.3, 0.7])
def test_jet_derivatives(text, t0):
    jet = compile_expression(text, {"a", "t"}, JET_FUNCTIONS)
    plain = compile_expression(text, {"a", "t"})
    a, h = 0.9, 1e-30
    f = lambda t: plain.evaluate({"a": a, "t": t})     # noqa: E731
    j = jet.evaluate({"a": a, "t": Jet(t0, 1.0, 0.0)})
    assert abs(j.v - f(t0)) <= 1e-15 * (1 + abs(f(t0)))
    d1 = np.imag(f(t0 + 1j * h)) / h
    assert abs(j.d - d1) <= 1e-14 * (1 + abs(d1))
    d2 = np.imag(jet.evaluate({"a": a, "t": Jet(t0 + 1j * h, 1.0, 0.0)}).d) / h
    assert abs(j.dd - d2) <= 1e-13 * (1 + abs(d2))
    hh = 1e-4
    fd2 = (f(t0 + hh) - 2 * f(t0) + f(t0 - hh)) / hh ** 2
    assert abs(j.dd - fd2) <= 1e-6 * (1 + abs(fd2))


def test_jets_broadcast_times_against_stacked_designs_and_complex_data():
    """A block of times (K, 1) against stacked parameter values (B,) gives (K, B) levels, each
    the scalar evaluation; complex design values pass through (complex step of a run)."""
    jet = compile_expression("a*sin(t)**2 + abs(t - a)", {"a", "t"}, JET_FUNCTIONS)
    ts = np.array([[0.1], [0.6], [1.2]])
    av = np.array([0.5, 0.9 + 1e-20j])
    j = jet.evaluate({"a": av, "t": Jet(ts, 1.0, 0.0)})
    for k in range(3):
        for b in range(2):
            s = jet.evaluate({"a": av[b], "t": Jet(ts[k, 0], 1.0, 0.0)})
            for lev in ("v", "d", "dd"):
                assert np.asarray(getattr(j, lev))[k, b] == pytest.approx(getattr(s, lev), rel=1e-15, abs=1e-300)
    assert np.imag(j.v[1, 1]) != 0.0


def test_the_jet_table_offers_every_function():
    assert set(JET_FUNCTIONS) == set(FUNCTIONS)
