"""Newmark-β: order of convergence, stability checks, energy conservation."""
import warnings

import numpy as np
import pytest

import dynsens
from dynsens.integrators.newmark import make_scheme
from conftest import CASES


def _undamped(dt, gamma=0.5, beta=0.25, t_end=2.0):
    case = dynsens.load_case(CASES / "sdof_step.yaml", [
        f"integrator.dt={dt}", f"integrator.t_end={t_end}", f"integrator.gamma={gamma}",
        f"integrator.beta={beta}", "design.variables[1].value=0.0"])
    res = dynsens.run_case(case, sensitivities=False)
    return res.history["q"][-1, 0]


def _exact_undamped(t, m=2.0, k=50.0, F=10.0):
    return F / k * (1 - np.cos(np.sqrt(k / m) * t))


@pytest.mark.parametrize("gamma,beta,order", [(0.5, 0.25, 2.0), (0.6, 0.3025, 1.0)])
def test_order_of_convergence(gamma, beta, order):
    dts = np.array([0.02, 0.01, 0.005, 0.0025])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        errs = np.array([abs(_undamped(dt, gamma, beta) - _exact_undamped(2.0)) for dt in dts])
    slope = np.polyfit(np.log(dts), np.log(errs), 1)[0]
    assert abs(slope - order) < 0.15, (slope, errs)


def test_gamma_below_half_rejected():
    with pytest.raises(ValueError, match="gamma"):
        make_scheme("newmark", 0.25, 0.4)


def test_beta_below_gamma_half_warns():
    with pytest.warns(UserWarning, match="conditionally stable"):
        make_scheme("newmark", 0.1, 0.5)


def test_average_acceleration_conserves_energy():
    case = dynsens.load_case(CASES / "sdof_step.yaml", [
        "integrator.t_end=20", "design.variables[1].value=0.0", "model.loads=[]",
        "model.initial={displacement: {u: 0.3}}", "output.history=[q, qd]"])
    res = dynsens.run_case(case, sensitivities=False)
    q, qd = res.history["q"][:, 0], res.history["qd"][:, 0]
    energy = 0.5 * 2.0 * qd ** 2 + 0.5 * 50.0 * q ** 2
    assert np.max(np.abs(energy - energy[0])) < 1e-12 * energy[0]
