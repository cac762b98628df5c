"""Case builders for the stiff and extreme checks (tests/test_stiff_extreme.py and
scripts/extreme_report.py share them)."""
from __future__ import annotations

import numpy as np

import dynsens


def two_dof(k_stiff, dt, t_end, scheme=("newmark", {})):
    """ground -k1- m1 =k_stiff= m2 (k1 = 1, m = 1): slow mode ω ≈ 0.707 rad/s, stiff mode ω ≈ √(2 k_stiff)."""
    name, kw = scheme
    integ = {"scheme": name, "dt": dt, "t_end": t_end, **kw}
    return dynsens.load_case_dict({
        "model": {"type": "structural", "dofs": ["u1", "u2"], "elements": [
            {"type": "mass", "name": "m1", "dof": "u1", "mass": 1.0},
            {"type": "mass", "name": "m2", "dof": "u2", "mass": 1.0},
            {"type": "spring", "name": "soft", "dofs": ["u1", "ground"], "k": 1.0},
            {"type": "spring", "name": "stiff", "dofs": ["u2", "u1"], "k": k_stiff}],
            "initial": {"displacement": {"u1": 1.0, "u2": 1.001}}},
        "integrator": integ, "output": {"history": ["q"]}})


def exact_two_dof(k_stiff, t):
    K = np.array([[1.0 + k_stiff, -k_stiff], [-k_stiff, k_stiff]])
    w2, V = np.linalg.eigh(K)
    a = np.linalg.solve(V, np.array([1.0, 1.001]))
    return (V * a) @ np.cos(np.sqrt(w2)[:, None] * np.atleast_1d(t)[None, :])


def sdof_in_units(scale_length, scale_mass, scale_time):
    """A Duffing oscillator written in other units: lengths ×L, masses ×M, times ×T."""
    L, M, T = scale_length, scale_mass, scale_time
    return dynsens.load_case_dict({
        "design": {"variables": [{"name": "k", "value": 50.0 * M / T ** 2, "lower": 1e-30, "upper": 1e30}]},
        "model": {"type": "structural", "dofs": ["u"], "elements": [
            {"type": "mass", "name": "m", "dof": "u", "mass": 2.0 * M},
            {"type": "spring", "name": "s", "dofs": ["u", "ground"], "k": "k", "k3": 400.0 * M / (T ** 2 * L ** 2)},
            {"type": "damper", "name": "d", "dofs": ["u", "ground"], "c": 0.8 * M / T}],
            "loads": [{"dof": "u", "value": 10.0 * M * L / T ** 2,
                       "function": {"type": "ramp", "t0": 0, "t1": 0.5 * T}}]},
        "integrator": {"dt": 1e-3 * T, "t_end": 3.0 * T},
        "sensitivity": {"partials": "complex"},
        "responses": [{"name": "q_end", "type": "value", "quantity": {"dof": "u"}},
                      {"name": "q_ks", "type": "ks", "quantity": {"dof": "u"}, "rho": 100.0 / L}]})


def hard_step_case(cuts):
    return dynsens.load_case_dict({
        "design": {"variables": [{"name": "k3", "value": 1e6, "lower": 1.0, "upper": 1e9}]},
        "model": {"type": "structural", "dofs": ["u"], "elements": [
            {"type": "mass", "name": "m", "dof": "u", "mass": 1.0},
            {"type": "spring", "name": "s", "dofs": ["u", "ground"], "k": 1.0, "k3": "k3"}],
            "loads": [{"dof": "u", "value": 1e5, "function": {"type": "step", "t0": 0.0}}]},
        "integrator": {"dt": 0.02, "t_end": 0.2, "max_step_cuts": cuts, "solver": {"max_iterations": 4}},
        "sensitivity": {"partials": "complex"},
        "responses": [{"name": "q_ks", "type": "ks", "quantity": {"dof": "u"}, "rho": 50.0}]})


