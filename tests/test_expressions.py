"""The restricted expression evaluator: arithmetic and math only, complex-safe, never eval."""
import numpy as np
import pytest

from dynsens.expressions.restricted import ExpressionError, compile_expression


@pytest.mark.parametrize("text", ["__import__('os')", "x.real", "[x for x in y]", "lambda: 1", "open('f')",
                                  "x if y else 1", "'a' + 'b'", "x[0]", "(1).__class__"])
def test_rejects_everything_but_arithmetic(text):
    with pytest.raises(ExpressionError):
        compile_expression(text, {"x", "y"})


def test_unknown_symbol_with_hint():
    with pytest.raises(ExpressionError, match="did you mean 'l_AZ'"):
        compile_expression("2*l_ZA", {"l_AZ", "theta"})


def test_values_and_complex_step():
    e = compile_expression("sqrt(a)*sin(b) + atan2(a, b)**2 - abs(-a) + min(a, b)", {"a", "b"})
    f = lambda a, b: np.sqrt(a) * np.sin(b) + np.arctan2(a, b) ** 2 - a + min(a, b)
    assert e.evaluate({"a": 2.0, "b": 0.5}) == pytest.approx(f(2.0, 0.5), rel=1e-14)
    h = 1e-30
    d = np.imag(e.evaluate({"a": 2.0 + 1j * h, "b": 0.5})) / h
    fd = (f(2.0 + 1e-7, 0.5) - f(2.0 - 1e-7, 0.5)) / 2e-7
    assert d == pytest.approx(fd, rel=1e-7)


def test_a_symbol_alone_is_its_value_and_is_checked_as_any_expression():
    """A bare symbol (every element's own design variable) returns the symbol's value as it is,
    without the general evaluation; a non-finite or complex value takes the general path, with its
    errors; anything more than the symbol is not bare."""
    e = compile_expression(" k1 ")
    assert e.bare == "k1"
    for value in (2.5, np.float64(-3.0), 0.0):
        got = e.evaluate({"k1": value})
        assert got is value
        assert e.derivative_problem({"k1": float(value)}) is None
    assert e.evaluate({"k1": 2.0 + 1e-20j}) == 2.0 + 1e-20j          # complex steps as before
    for bad in (np.nan, np.inf):
        with pytest.raises(ExpressionError, match="a finite number was expected"):
            e.evaluate({"k1": bad})
    for text in ("pi", "-k1", "k1 + 0", "2*k1", "sqrt(k1)"):
        assert compile_expression(text).bare is None, text
