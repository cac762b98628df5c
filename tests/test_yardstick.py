"""The benchmark's yardstick (scripts/yardstick_chain.py) computes what dynsens computes.

Its values and gradients (analytic design partials, both linear-algebra variants) are compared
with dynsens run with complex-step partials (exact to round-off) on a short chain: any
difference in the physics, the Newmark corrector or the sensitivity recursion shows far above
the tolerance (a 1 % change of one partial moves the gradient by ~1e-3).
"""
from __future__ import annotations

import numpy as np
import pytest

import scripts_path  # noqa: F401  (puts scripts/ on the path)
import yardstick_chain as ys


@pytest.mark.parametrize("n", [4, 30])
def test_yardstick_matches_dynsens(n: int) -> None:
    diffs = ys.compare_with_dynsens(n, 150)   # the pulse and its nonlinear response
    for key, err in diffs.items():
        assert err < 1e-11, (key, err)


def test_yardstick_variants_agree_and_gradient_is_not_trivial() -> None:
    v1, g1, c1 = ys.run(6, 120, solver="superlu")
    v2, g2, c2 = ys.run(6, 120, solver="tridiagonal")
    assert np.allclose(v1, v2, rtol=1e-13, atol=0) and np.allclose(g1, g2, rtol=1e-11, atol=1e-30)
    assert c1["newton_iterations"] > 120          # nonlinear: more than one iteration per step
    # against a central difference in k3 (the cubic term: the nonlinear part of the recursion)
    h = 1e-4 * ys.X0[3]
    xp, xm = ys.X0.copy(), ys.X0.copy()
    xp[3] += h
    xm[3] -= h
    fd = (ys.run(6, 120, xp, gradient=False)[0] - ys.run(6, 120, xm, gradient=False)[0]) / (2 * h)
    assert np.allclose(g1[:, 3], fd, rtol=1e-6, atol=0)
