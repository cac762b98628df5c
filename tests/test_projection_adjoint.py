"""The projection's derivative from its linearized equations (dynsens/models/multibody/
projection_adjoint.py): the forward map (direct mode) against complex step of the whole
projection solved from scratch, and the transposed map (adjoint sweep) against the forward one
by the dot-product test, on a dense mechanism without drivers (N-four-bar, dense and sparse
J_Φ), the pendulum with mode output, and the weir (drivers with time coefficients, mm units).

Tolerances: 1e-12 relative where the projection's own convergence (1e-13) allows; the weir,
whose Newton matrix M = J*J₀ᵀ is far less well conditioned in its mixed mm / Euler-parameter
coordinates, 1e-8 against complex step (measured 1.3e-9) and 1e-9 in the dot test (2.4e-11).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import dynsens
from conftest import CASES
from dynsens.models.multibody import projection as P
from dynsens.models.multibody.projection_adjoint import apply_state, transpose_state

RUNS = [("n_four_bar", ["integrator.t_end=0.05", "model.projection={mode: state}"], 10 ** 9, 1e-12, 1e-12),
        ("n_four_bar", ["integrator.t_end=0.05", "model.projection={mode: state}", "model.linear_algebra=sparse"],
         0, 1e-12, 1e-12),
        ("pendulum_projection", ["integrator.t_end=0.1"], 10 ** 9, 1e-12, 1e-12),
        ("tyrolean_weir", ["integrator.t_end=0.05", "model.projection={mode: state}"], 10 ** 9, 1e-8, 1e-9)]


def _projections(name, sets, monkeypatch):
    """The projections of a direct run's steps with the run's design partials."""
    caught = []
    orig = P.Projection.apply

    def spy(self, ds, partials):
        caught.append((self, partials))
        return orig(self, ds, partials)
    monkeypatch.setattr(P.Projection, "apply", spy)
    case = dynsens.load_case(CASES / f"{name}.yaml", sets)
    case.plan = replace(case.plan, method="direct")
    dynsens.run_case(case)
    monkeypatch.setattr(P.Projection, "apply", orig)
    assert caught
    return [caught[0], caught[len(caught) // 2], caught[-1]]


@pytest.mark.parametrize("name, sets, sparse_min, tol_cs, tol_dot", RUNS)
def test_projection_derivative_forward_and_transposed(name, sets, sparse_min, tol_cs, tol_dot, monkeypatch):
    monkeypatch.setattr(P, "SPARSE_MIN_EQ", sparse_min)
    rng = np.random.default_rng(3)
    h = 1e-30
    for proj, partials in _projections(name, sets, monkeypatch):
        prm, n = partials.params0, proj.raw.q.shape[0]
        dq, dqd = rng.standard_normal((n, 3)), rng.standard_normal((n, 3))
        fwd = apply_state(proj, dq, dqd, prm)
        assert fwd is not None
        # independent: complex step of the projection solved from scratch (chord iterations)
        Qs, QDs, _, _ = P._project_columns(proj.model, proj.settings, proj.t,
                                           proj.raw.q[:, None] + 1j * h * dq, proj.raw.qd[:, None] + 1j * h * dqd, prm)
        for got, ref in ((fwd[0], Qs.imag / h), (fwd[1], QDs.imag / h)):
            assert np.max(np.abs(got - ref)) <= tol_cs * np.max(np.abs(ref)) + 1e-300
        q_bar, qd_bar = rng.standard_normal((n, 2)), rng.standard_normal((n, 2))
        back = transpose_state(proj, q_bar, qd_bar, prm)
        assert back is not None
        lhs = q_bar.T @ fwd[0] + qd_bar.T @ fwd[1]
        rhs = back[0].T @ dq + back[1].T @ dqd
        assert np.max(np.abs(lhs - rhs)) <= tol_dot * np.max(np.abs(lhs))


def test_numpy_kernel_keeps_the_projected_columns(monkeypatch):
    """Without compiled kinematics the linearized equations are not used: the derivative comes
    from complex step of the projection (the full map for the adjoint)."""
    monkeypatch.setenv("DYNSENS_KERNEL", "numpy")
    proj, partials = _projections("pendulum_projection", ["integrator.t_end=0.05"], monkeypatch)[1]
    n = proj.raw.q.shape[0]
    assert apply_state(proj, np.eye(n), np.zeros((n, n)), partials.params0) is None
    assert transpose_state(proj, np.eye(n), np.zeros((n, n)), partials.params0) is None
