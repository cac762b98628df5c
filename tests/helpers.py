"""Shared test helpers: complex-step derivative of a whole simulation."""
from __future__ import annotations

import numpy as np

import dynsens


def complex_step_gradients(case, x=None, h_rel=1e-20):
    """d(response)/dx for every response by complex step of the whole simulation."""
    x0 = case.x0 if x is None else np.asarray(x, float)
    h = h_rel * np.maximum(np.abs(x0), 1.0)
    out = {}
    for j in range(x0.size):
        x = x0.astype(complex)
        x[j] += 1j * h[j]
        res = dynsens.run_case(case, x)
        for name, r in res.responses.items():
            out.setdefault(name, np.zeros(x0.size))[j] = np.imag(r.value) / h[j]
    return out


def rel_err(a, b):
    """‖a − b‖ / ‖b‖."""
    return float(np.linalg.norm(np.asarray(a) - np.asarray(b)) / np.linalg.norm(b))
