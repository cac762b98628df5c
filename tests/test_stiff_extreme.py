"""Stiff and extreme structural cases: huge stiffness ratios and time steps, long runs,
parameters spanning 1e-6..1e9, and Newton failures recovered by step cutting."""
import numpy as np
import pytest

import dynsens
from dynsens.errors import ConvergenceError
from helpers import complex_step_gradients, rel_err
from scripts_path import exact_two_dof, hard_step_case, sdof_in_units, two_dof


# (stiffness ratio, Δt·ω_max): the slow mode is resolved (Δt·ω_slow ≤ 0.1) in the first two;
# the last one steps over the slow period too and must merely stay bounded
STIFF = [(1e6, 1e2, 2e-2), (1e8, 1e3, 2e-2), (1e8, 1e4, None)]


@pytest.mark.parametrize("ratio,omega_dt,slow_tol", STIFF)
def test_stiff_two_dof_far_beyond_the_stiff_period(ratio, omega_dt, slow_tol):
    dt = omega_dt / np.sqrt(2 * ratio)
    t_end = 18.0                                                         # two slow periods
    res = {}
    for label, scheme in (("newmark", ("newmark", {})), ("galpha", ("generalized_alpha", {"rho_inf": 0.0}))):
        r = dynsens.run_case(two_dof(ratio, dt, t_end, scheme), sensitivities=False)
        q = r.history["q"]
        assert np.all(np.isfinite(q)) and np.max(np.abs(q)) < 1.01      # no blow-up, no energy gain
        if slow_tol is not None:
            exact = exact_two_dof(ratio, r.time)
            slow, slow_exact = 0.5 * (q[:, 0] + q[:, 1]), 0.5 * (exact[0] + exact[1])
            assert np.max(np.abs(slow - slow_exact)) < slow_tol          # slow mode accurate
        res[label] = q[:, 1] - q[:, 0]                                   # stiff-mode content
    # undamped Newmark keeps the unresolved stiff mode; generalized-α with ρ∞ = 0 removes it
    assert np.max(np.abs(res["newmark"][-20:])) > 1e-5
    assert np.max(np.abs(res["galpha"][-20:])) < 1e-3 * np.max(np.abs(res["newmark"][-20:]))


def test_long_run_energy_bounded():
    """1000 periods of an undamped cubic (Duffing) oscillator: the energy stays bounded."""
    m, k, k3 = 1.0, 1.0, 0.5
    period = 2 * np.pi
    case = dynsens.load_case_dict({
        "model": {"type": "structural", "dofs": ["u"], "elements": [
            {"type": "mass", "name": "m", "dof": "u", "mass": m},
            {"type": "spring", "name": "s", "dofs": ["u", "ground"], "k": k, "k3": k3}],
            "initial": {"displacement": {"u": 1.0}}},
        "integrator": {"dt": period / 20, "t_end": 1000 * period}, "output": {"history": ["q", "qd"]}})
    r = dynsens.run_case(case, sensitivities=False)
    q, v = r.history["q"][:, 0], r.history["qd"][:, 0]
    energy = 0.5 * m * v ** 2 + 0.5 * k * q ** 2 + 0.25 * k3 * q ** 4
    assert r.counters["steps"] == 20000
    assert np.max(np.abs(energy - energy[0])) < 0.02 * energy[0]
    # no secular drift: the last hundred periods look like the first hundred
    assert abs(energy[-2000:].mean() - energy[:2000].mean()) < 1e-3 * energy[0]


@pytest.mark.parametrize("L,M,T", [(1e3, 1e-3, 1.0), (1e-6, 1e9, 1.0), (1.0, 1e-6, 1e-3), (1e9, 1e6, 1e3)])
def test_units_spanning_1e_minus6_to_1e9_give_the_same_solution(L, M, T):
    """Tolerances are relative: the same physics in other units gives the same scaled answer."""
    base = dynsens.run_case(sdof_in_units(1.0, 1.0, 1.0))
    other = dynsens.run_case(sdof_in_units(L, M, T))
    k_scale = M / T ** 2
    for name in ("q_end", "q_ks"):
        assert other.responses[name].value / L == pytest.approx(base.responses[name].value, rel=1e-9)
        g_other = other.responses[name].gradient * k_scale / L
        assert rel_err(g_other, base.responses[name].gradient) < 1e-8
    assert abs(other.counters["newton_iterations"] - base.counters["newton_iterations"]) \
        <= 0.01 * base.counters["steps"]


def test_newton_failure_is_recovered_by_step_cutting_with_consistent_sensitivities():
    with pytest.raises(ConvergenceError, match="did not converge"):
        dynsens.run_case(hard_step_case(0))
    case = hard_step_case(8)
    res = dynsens.run_case(case)
    assert res.counters["step_cuts"] > 0 and res.status == "completed"
    ref = complex_step_gradients(case)
    assert rel_err(res.responses["q_ks"].gradient, ref["q_ks"]) < 1e-9


def test_step_cutting_gives_up_with_an_explanation():
    case = hard_step_case(1)
    with pytest.raises(ConvergenceError, match=r"after 1 step cuts down to Δt = 0.01"):
        dynsens.run_case(case)
