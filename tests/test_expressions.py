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
