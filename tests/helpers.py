"""Shared test helpers: complex-step derivative of a whole simulation; a small design problem;
the errors of a run with a compiled step and with the Python iteration."""
from __future__ import annotations

import contextlib
import signal

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


def assert_gradients_match_complex_step_and_adjoint(case, res, rtol_cs=1e-8, rtol_adjoint=1e-10):
    """Every response gradient of the direct run ``res`` equals the complex step of the whole run
    (rtol_cs) and the adjoint run's (rtol_adjoint)."""
    import copy
    from dataclasses import replace
    cs = complex_step_gradients(case)
    for name, rv in res.responses.items():
        np.testing.assert_allclose(np.real(rv.gradient), cs[name], rtol=rtol_cs,
                                   atol=1e-2 * rtol_cs * np.abs(cs[name]).max(), err_msg=name)
    c = copy.copy(case)
    c.plan = replace(case.plan, method="adjoint")
    adjoint = dynsens.run_case(c)
    for name, rv in res.responses.items():
        np.testing.assert_allclose(adjoint.responses[name].gradient, rv.gradient, rtol=rtol_adjoint,
                                   atol=1e-2 * rtol_adjoint * np.abs(rv.gradient).max(), err_msg=name)


def complex_step_jacobians(model, t, q, qd, qdd, params, h=1e-30):
    """(∂F_R/∂q, ∂F_R/∂q̇, ∂F_R/∂q̈) by complex step of the model's residual at one state."""
    from dynsens.models.base import StepState
    n, empty = len(q), np.zeros(0)
    out = []
    for which in range(3):
        J = np.zeros((n, n))
        for j in range(n):
            st = [q.astype(complex), qd.astype(complex), qdd.astype(complex)]
            st[which][j] += 1j * h
            J[:, j] = np.imag(model.residual(t, StepState(*st, empty, empty, empty), params)) / h
        out.append(J)
    return out


@contextlib.contextmanager
def time_limit(seconds):
    """Fail (not hang) when the block takes longer than ``seconds`` (SIGALRM; a fuzz example)."""
    def on_alarm(signum, frame):
        raise TimeoutError(f"one fuzz example took more than {seconds} s (a hang)")
    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def key_paths(node, prefix=()):
    """Every key path into a case mapping (dict keys and list indices), parents before children."""
    out = [prefix] if prefix else []
    if isinstance(node, dict):
        for k, v in node.items():
            out += key_paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += key_paths(v, prefix + (i,))
    return out


def pendulum_with_coaxial_hinges(raw):
    """pendulum_3d's mapping ``raw`` with a second hinge coaxial with its pivot (a dependent pair)
    and a second pendulum on a spherical joint of its own (independent), changed in place."""
    raw["model"]["bodies"]["bob2"] = {"mass": 1.0, "inertia": [1e-3, 1e-3, 1e-3], "position": [0, -1, 0]}
    raw["model"]["joints"] += [
        {"name": "hinge2", "type": "revolute", "body_1": "ground", "body_2": "bob", "point": [0, 0, 1],
         "axis": [0, 0, 1]},
        {"name": "other", "type": "spherical", "body_1": "ground", "body_2": "bob2", "point": [0, 0, 0]}]
    return raw


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


_BLAS_AGREE: list[bool] = []


def blas_builds_agree() -> bool:
    """Whether numba's BLAS (scipy's build) forms dot and matrix-vector products bit for bit as
    numpy's does, at lengths and alignments like a step's.  With current wheels the two are one
    build; under the minimum versions (numpy 1.24, scipy 1.10) they are not, and a dot product
    may differ in its last bit, depending on where its arrays lie in memory."""
    if not _BLAS_AGREE:
        from numba import njit

        @njit(cache=False)
        def dot(a, b):  # type: ignore[no-untyped-def]
            return a @ b

        @njit(cache=False)
        def mv(A, x):  # type: ignore[no-untyped-def]
            return A @ x
        buf = np.random.default_rng(0).standard_normal(20000)
        agree = True
        for n in (3, 7, 16, 30, 43, 60, 100, 257, 1000):
            for off in range(4):
                a, b = buf[off:off + n], buf[off + 100:off + 100 + n]
                m = min(n, 100)
                A, x = buf[off:off + m * m].reshape(m, m), buf[off + 7:off + 7 + m]
                agree = agree and dot(a, b) == a @ b and np.array_equal(mv(A, x), A @ x)
        _BLAS_AGREE.append(agree)
    return _BLAS_AGREE[0]


# where numba's BLAS and numpy's are different builds, the compiled and Python iterations take
# their convergence decisions on norms and products one rounding apart: their runs then agree to
# the Newton tolerance, not bit for bit (measured under the minimum versions: 2e-6 relative)
DIFFERENT_BLAS_RTOL = 1e-5


def assert_same_or_blas_close(a: np.ndarray, b: np.ndarray, what: str) -> None:
    """Compiled against Python numbers: bit for bit where the BLAS builds agree, else within
    DIFFERENT_BLAS_RTOL of b's largest entry."""
    if blas_builds_agree():
        np.testing.assert_array_equal(a, b, err_msg=what)
    else:
        scale = max(float(np.max(np.abs(b), initial=0.0)), 1e-300)
        np.testing.assert_allclose(a, b, rtol=0, atol=DIFFERENT_BLAS_RTOL * scale, err_msg=what)


def random_dense_records(rng: np.random.Generator, K: int, n_q: int, n_lam: int, n_p: int,
                         with_R_p: bool = True) -> list:
    """K step records with random dense real linearizations and LU factors (S well conditioned),
    n_q + n_lam + n_p unknowns, step sizes varying as after step cuts or adaptive steps; without
    R_p (a residual that does not depend on p) unless ``with_R_p``."""
    from dynsens.models.base import Linearization
    from dynsens.solver.linalg import Counters, Factor
    from dynsens.timeloop.stepping import StepRecord
    n_z = n_q + n_lam + n_p
    out = []
    for k in range(K):
        S = rng.standard_normal((n_z, n_z)) + n_z * np.eye(n_z)
        lin = Linearization(S, rng.standard_normal((n_z, n_q)), rng.standard_normal((n_z, n_q)),
                            rng.standard_normal((n_z, n_p)) if n_p and with_R_p else None)
        factor = Factor(S, Counters(), dense_general=True)
        h = 1e-3 * (1.0 + 0.5 * k)
        out.append(StepRecord(k + 1, 0.0, h, None, lin, factor, 2))   # type: ignore[arg-type]
    return out


def assert_identical_runs(compiled, python):
    """Two runs agree bit for bit (counters, responses with their gradients, every history
    field) where numba's BLAS is numpy's build; otherwise to :data:`DIFFERENT_BLAS_RTOL` of each
    array's largest entry, with the same number of steps."""
    exact = blas_builds_agree()
    assert compiled.counters == python.counters if exact else compiled.counters["steps"] == python.counters["steps"]

    def same(a, b, what):  # type: ignore[no-untyped-def]
        if exact:
            np.testing.assert_array_equal(a, b, err_msg=what)
        else:
            scale = max(float(np.max(np.abs(b), initial=0.0)), 1e-300)
            np.testing.assert_allclose(a, b, rtol=0, atol=DIFFERENT_BLAS_RTOL * scale, err_msg=what)
    assert compiled.responses.keys() == python.responses.keys()
    for key, r in compiled.responses.items():
        same(r.value, python.responses[key].value, key)
        if r.gradient is not None:
            same(r.gradient, python.responses[key].gradient, key)
    assert compiled.history.keys() == python.history.keys()
    for field, a in compiled.history.items():
        same(a, python.history[field], field)


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


def ipopt_missing() -> bool:
    """Whether cyipopt (the ``ipopt`` extra, built on the system's Ipopt) is missing here: its
    tests are skipped then, except where ``DYNSENS_REQUIRE_IPOPT`` is set (CI installs it), where
    a missing cyipopt is an error, not a skip."""
    import importlib.util
    import os
    missing = importlib.util.find_spec("cyipopt") is None
    if missing and os.environ.get("DYNSENS_REQUIRE_IPOPT"):
        raise RuntimeError("DYNSENS_REQUIRE_IPOPT is set but cyipopt is not installed "
                           "(apt-get install coinor-libipopt-dev liblapack-dev libblas-dev pkg-config; "
                           "pip install 'dynsens[ipopt]')")
    return missing


def ctrl_c_after_rows(monkeypatch, rows: int = 3):  # type: ignore[no-untyped-def]
    """Make ``dynsens optimize`` stop as Ctrl-C does once ``rows`` iteration rows are written (its
    progress callback raises KeyboardInterrupt); returns the real callback, to restore."""
    import dynsens.cli.optimize as cli_opt
    real, seen = cli_opt.progress_line, []

    def interrupting(msg, objective):  # type: ignore[no-untyped-def]
        if msg["kind"] == "iteration":
            seen.append(msg["row"]["iteration"])
            if len(seen) == rows:                 # rows 0 .. rows-1 are written: Ctrl-C now
                raise KeyboardInterrupt
        return real(msg, objective)

    monkeypatch.setattr(cli_opt, "progress_line", interrupting)
    return real
