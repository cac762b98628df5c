"""The law of a structural spring, one definition for every evaluation path: the numpy model
(:meth:`~dynsens.models.structural.elements.springs.Springs.state`, any batch shape) and the
compiled step of spring networks (:mod:`dynsens.models.structural.step`)."""
from __future__ import annotations

from typing import Any

from ...solver._jit import register_jitable


@register_jitable
def spring_law(delta: Any, k1: Any, k2: Any, k3: Any) -> tuple[Any, Any]:
    """(f, k_t) of springs with elongations delta (m): force f = k₁δ + k₂δ² + k₃δ³ (N) and tangent
    k_t = df/dδ = k₁ + 2k₂δ + 3k₃δ² (N/m); arrays of one shape (or broadcasting), real or complex.

    δ² is formed once as δ·δ (what numpy's δ ** 2 computes) and δ³ as δ²·δ: numpy's δ ** 3
    calls pow(), about 60 times the cost of a product."""
    d2 = delta * delta
    f = k1 * delta + k2 * d2 + k3 * (d2 * delta)
    # k1 + 2 k2 δ equals (k1 + 0·δ) + 2 k2 δ for finite δ (a non-finite δ is caught anyway)
    kt = (2 * k2 * delta + k1) + 3 * k3 * d2
    return f, kt
