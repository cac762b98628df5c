"""Issue 35's target table (scripts/bench_targets.py, `make bench`) runs and prints its rows.

A smoke test of the smallest setting (P1 at N = 10, a short horizon, one repeat): the table has
its three P1 targets with finite measured numbers, the CPU-seconds table has every variant with
finite times, and without JAX the JAX columns say how to install it instead of failing.  Timings
are printed, never asserted (they go to BENCHMARKS.md).  Where JAX is installed, its compiled
chain (scripts/jax_chain.py) is checked against the numpy yardstick, whose derivatives
tests/test_yardstick.py checks against dynsens.
"""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

import scripts_path  # noqa: F401  (puts scripts/ on the path)
import bench_targets
import jax_chain
import yardstick_chain as ys

SMALLEST = ["--rows", "p1-10", "--repeats", "1", "--steps", "60"]


def _seconds(text: str) -> dict[str, float]:
    """The CPU-seconds table: variant -> seconds."""
    rows = re.findall(r"^\| P1 N = 10 \| ([^|]+) \| ([^|]+) \|$", text, flags=re.M)
    return {variant.strip(): float(s) for variant, s in rows}


def _targets(text: str) -> dict[str, tuple[str, str]]:
    """The target table: target -> (measured, met)."""
    rows = re.findall(r"^\| (P1 N = 10, [^|]+) \| [^|]+ \| ([^|]+) \| ([^|]+) \|$", text, flags=re.M)
    return {name.strip(): (measured.strip(), met.strip()) for name, measured, met in rows}


def _check(text: str, jax: bool) -> None:
    targets = _targets(text)
    assert set(targets) == {"P1 N = 10, primal", "P1 N = 10, primal + gradient", "P1 N = 10, gradient ratio"}
    ratio = float(targets["P1 N = 10, gradient ratio"][0])
    assert math.isfinite(ratio) and ratio > 0 and targets["P1 N = 10, gradient ratio"][1] in ("yes", "no")
    seconds = _seconds(text)
    expected = {"dynsens primal", "dynsens + gradient", "numpy loop primal", "numpy loop + gradient"}
    if jax:
        expected |= {"JAX primal", "JAX + gradient (jacfwd)"}
    assert set(seconds) == expected
    assert all(math.isfinite(s) and s >= 0 for s in seconds.values())
    assert "uptime before:" in text and "machine:" in text
    for name in ("P1 N = 10, primal", "P1 N = 10, primal + gradient"):
        measured, met = targets[name]
        if jax:
            assert math.isfinite(float(re.search(r", ([0-9.]+)× JAX", measured).group(1))) and met in ("yes", "no")
        else:
            assert jax_chain.MISSING in measured and met == "not judged"
    if jax:   # the JAX chain agrees with dynsens, and the note says so
        note = re.search(r"JAX tip_end vs dynsens ([0-9.e+-]+), gradient ([0-9.e+-]+)", text)
        assert note and max(float(note.group(1)), float(note.group(2))) < bench_targets.AGREEMENT
        assert "MISMATCH" not in text


def test_the_smallest_table_without_jax(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(jax_chain, "AVAILABLE", False)
    text = bench_targets.main(SMALLEST)
    _check(text, jax=False)
    assert f"JAX columns: {jax_chain.MISSING}." in text


@pytest.mark.skipif(not jax_chain.AVAILABLE, reason="JAX is an optional peer: pip install 'dynsens[peers]'")
def test_the_smallest_table_with_jax() -> None:
    _check(bench_targets.main(SMALLEST), jax=True)


@pytest.mark.skipif(not jax_chain.AVAILABLE, reason="JAX is an optional peer: pip install 'dynsens[peers]'")
@pytest.mark.parametrize("per_element", [False, True])
def test_the_jax_chain_matches_the_numpy_loop(per_element: bool) -> None:
    """Forward and reverse mode of the JAX scan equal the yardstick's direct differentiation
    (shared design: its four columns; per-element stiffnesses: their sum is the shared k's
    derivative, since k_i = k for every i), to 1e-10 relative."""
    n, steps = 7, 150
    value, grad, _ = ys.run(n, steps, solver="tridiagonal")
    chain = jax_chain.JaxChain(n, steps, per_element=per_element)
    x = ys.X0 if not per_element else np.full(n, ys.X0[2])
    for v, g in (chain.forward(x), chain.reverse(x)):
        assert abs(v - value[0]) <= 1e-12 * abs(value[0])
        expected = grad[0] if not per_element else grad[0][2]
        got = g if not per_element else g.sum()
        assert np.allclose(got, expected, rtol=1e-10, atol=0), (got, expected)
