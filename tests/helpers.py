"""Shared test helpers: complex-step derivative of a whole simulation; a small design problem;
the errors of a run with a compiled step and with the Python iteration."""
from __future__ import annotations

import numpy as np
import pytest

import dynsens
from dynsens.errors import ConvergenceError, NonFiniteError


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


# 2-variable SDOF design problem: cost = k + 10 c subject to max displacement (KS) <= 0.2 m
SDOF_DESIGN = {
    "name": "sdof_design",
    "design": {"variables": [
        {"name": "c", "value": 2.0, "lower": 0.1, "upper": 20.0},
        {"name": "k", "value": 100.0, "lower": 10.0, "upper": 400.0},
    ]},
    "model": {
        "type": "structural", "dofs": ["u"],
        "elements": [
            {"type": "mass", "name": "body", "dof": "u", "mass": 2.0},
            {"type": "spring", "name": "spring", "dofs": ["u", "ground"], "k": "k"},
            {"type": "damper", "name": "damper", "dofs": ["u", "ground"], "c": "c"},
        ],
        "loads": [{"dof": "u", "value": 10.0, "function": "constant"}],
    },
    "integrator": {"scheme": "newmark", "beta": 0.25, "gamma": 0.5, "dt": 1.0e-2, "t_end": 3.0},
    "sensitivity": {"enabled": True, "partials": "forward"},
    "responses": [
        {"name": "q_ks", "type": "ks", "quantity": {"dof": "u", "kind": "displacement"}, "rho": 50.0},
        {"name": "cost", "type": "expression", "expression": "k + 10*c"},
    ],
    "optimization": {"objective": "cost", "constraints": [{"response": "q_ks", "upper": 0.2}]},
}


# the SDOF case with three design variables [m, c, k] that the CLI and reliability tests run
SDOF_RUN = {
    "name": "sdof_cli",
    "design": {"variables": [
        {"name": "m", "value": 2.0, "lower": 0.5, "upper": 10.0},
        {"name": "c", "value": 0.8, "lower": 0.0, "upper": 5.0},
        {"name": "k", "value": 50.0, "lower": 10.0, "upper": 200.0},
    ]},
    "model": {
        "type": "structural",
        "dofs": ["u"],
        "elements": [
            {"type": "mass", "name": "body", "dof": "u", "mass": "m"},
            {"type": "spring", "name": "spring", "dofs": ["u", "ground"], "k": "k"},
            {"type": "damper", "name": "damper", "dofs": ["u", "ground"], "c": "c"},
        ],
        "loads": [{"dof": "u", "value": 10.0, "function": "constant"}],
    },
    "integrator": {"scheme": "newmark", "beta": 0.25, "gamma": 0.5, "dt": 2.0e-3, "t_end": 0.5},
    "sensitivity": {"enabled": True, "partials": "forward"},
    "responses": [
        {"name": "q_end", "type": "value", "quantity": {"dof": "u", "kind": "displacement"}},
        {"name": "q_ks", "type": "ks", "quantity": {"dof": "u", "kind": "displacement"}, "rho": 100.0},
    ],
}


def python_iteration(monkeypatch, model_class):
    """Make every model of ``model_class`` iterate its steps in Python (no compiled step)."""
    monkeypatch.setattr(model_class, "compiled_step", lambda self, newton, refactor: None)


def failures_compiled_and_python(monkeypatch, run, model_class):
    """(type, message, residual history) of the error run() raises, first with the compiled
    step of ``model_class``'s models, then with the Python iteration."""
    out = []
    for python in (False, True):
        with monkeypatch.context() as m:
            if python:
                python_iteration(m, model_class)
            with pytest.raises((ConvergenceError, NonFiniteError)) as err:
                run()
            out.append((type(err.value), str(err.value), getattr(err.value, "residual_history", None)))
    return out


def assert_identical_runs(compiled, python):
    """Two runs agree bit for bit: counters, responses (values and gradients) and every
    history field."""
    assert compiled.counters == python.counters
    assert compiled.responses.keys() == python.responses.keys()
    for key, r in compiled.responses.items():
        np.testing.assert_array_equal(r.value, python.responses[key].value, err_msg=key)
        if r.gradient is not None:
            np.testing.assert_array_equal(r.gradient, python.responses[key].gradient, err_msg=key)
    assert compiled.history.keys() == python.history.keys()
    for field, a in compiled.history.items():
        np.testing.assert_array_equal(a, python.history[field], err_msg=field)


def assert_same_failures(compiled, python):
    """Two (type, message, residual history) of :func:`failures_compiled_and_python` agree: the
    same error and message, and the same residual norms.  A norm is a BLAS dot product, and the
    compiled step calls scipy's BLAS through numba where the Python iteration calls numpy's: with
    the same build (current wheels) the norms are bit for bit the same, with different builds
    (the minimum versions) one may differ in its last bit."""
    assert compiled[:2] == python[:2]
    if compiled[2] is None or python[2] is None:
        assert compiled[2] == python[2]
    else:
        np.testing.assert_allclose(compiled[2], python[2], rtol=4 * np.finfo(float).eps, atol=0)
