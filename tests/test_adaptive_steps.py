"""Adaptive time steps (``integrator.adaptive``): accuracy against closed forms, responses on
non-uniform steps, and gradients that are exact along the accepted step sequence.

What is compared, with what tolerance:
* the SDOF step response against its closed form at three rtols: the error falls like
  rtol^(2/3) (a second-order scheme under local error control), factor 3..7 per decade;
* the trapezoid ∫q̇ dt over the accepted steps against q(T) − q(0): equal to round-off for
  average-acceleration Newmark (an identity of the scheme that holds only with the actual step
  sizes), values and gradients;
* an event time against the closed-form crossing (1e-4 s) and inside its accepted step; KS
  against the formula over the stored samples (1e-13);
* gradients: direct against complex step of the whole adaptive run (the controller reads real
  parts, so the complex run takes the same steps) and against complex step and central
  differences of a run replaying the accepted times (1e-9, 1e-6); adjoint against direct
  (1e-10), checkpointing bit-identical; finite differences that re-run the adaptivity agree
  only to the size of the step-selection effect.
"""
from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest
from scipy.optimize import brentq

import dynsens
from dynsens.errors import CaseError, StepSizeError
from dynsens.timeloop.step_sequence import replaying
from helpers import complex_step_gradients, rel_err

CASES = Path(__file__).resolve().parent.parent / "cases"
M, C, K, F = 2.0, 0.8, 50.0, 10.0


def exact_u(t, m=M, c=C, k=K):
    """Closed-form step response of the SDOF case (at rest at t = 0)."""
    w = np.sqrt(k / m)
    z = c / (2 * m * w)
    wd = w * np.sqrt(1 - z * z)
    return F / k * (1 - np.exp(-z * w * t) * (np.cos(wd * t) + z * w / wd * np.sin(wd * t)))


def sdof(rtol=1e-6, *more, t_end=3.0):
    return dynsens.load_case(CASES / "sdof_step.yaml", [
        f"integrator.t_end={t_end}", f"integrator.adaptive={{rtol: {rtol}, atol: {rtol * 1e-3}}}",
        "sensitivity.partials=complex", *more])


def with_plan(case, **changes):
    return dataclasses.replace(case, plan=dataclasses.replace(case.plan, **changes))


def test_error_estimate_constants_of_the_family():
    # Newmark average acceleration: Zienkiewicz–Xie's 1/12; second-order α-members 1/12 + (γ − ½)²/4
    assert dynsens.integrators.newmark.make_scheme("newmark").error_constants()[0] == pytest.approx(1 / 12)
    for sc in (dynsens.integrators.newmark.make_scheme("hht", alpha=0.1),
               dynsens.integrators.newmark.make_scheme("generalized_alpha", rho_inf=0.6)):
        assert sc.error_constants()[0] == pytest.approx(1 / 12 + (sc.gamma - 0.5) ** 2 / 4, rel=1e-14)


def test_error_falls_with_rtol_against_the_closed_form():
    errs, steps = [], []
    for rtol in (1e-4, 1e-5, 1e-6):
        res = dynsens.run_case(sdof(rtol, t_end=10.0), sensitivities=False)
        assert res.status == "completed" and res.time[-1] == pytest.approx(10.0, abs=1e-12)
        errs.append(np.max(np.abs(res.history["q"][:, 0] - exact_u(res.time))))
        steps.append(len(res.time) - 1)
        assert np.all(np.diff(res.time) > 0)
    ratios = [errs[k] / errs[k + 1] for k in range(2)]
    assert all(3.0 < r < 7.0 for r in ratios), (errs, ratios)       # rtol^(2/3): 4.6 per decade
    # (over 8 periods the phase error accumulates: 0.1 % of the static deflection at rtol 1e-6)
    assert errs[-1] < 2e-3 * F / K and steps[0] < steps[1] < steps[2]
    # the steps follow the motion: the spread of step sizes is wide
    dt = np.diff(dynsens.run_case(sdof(1e-6, t_end=10.0), sensitivities=False).time)
    assert dt.max() > 10 * dt.min()


def test_integral_uses_the_accepted_step_sizes():
    """Trapezoid ∫q̇ dt over the accepted steps = q(T) − q(0) exactly for average acceleration
    (q_{n+1} − q_n = h/2 (q̇_n + q̇_{n+1}) is the scheme's own update); with equal weights
    it would be off by the spread of the steps."""
    case = sdof(1e-5, "responses=[{name: vint, type: integral, quantity: {dof: u, kind: velocity}},"
                      " {name: q_end, type: value, quantity: {dof: u, kind: displacement}}]")
    res = dynsens.run_case(case)
    assert np.ptp(np.diff(res.time)) > 1e-3
    v, q = res.responses["vint"], res.responses["q_end"]
    assert v.value == pytest.approx(q.value, rel=1e-12)
    np.testing.assert_allclose(v.gradient, q.gradient, rtol=1e-9, atol=1e-12)
    qd = res.history["qd"][:, 0]
    uniform = np.mean(qd[:-1] + qd[1:]) / 2 * (res.time[-1] - res.time[0])
    assert abs(uniform - q.value) > 1e3 * abs(v.value - q.value)


def test_event_is_located_inside_an_accepted_step():
    case = sdof(1e-7, "events=[{name: up, quantity: {dof: u, kind: displacement}, value: 0.3, direction: rising}]",
                "responses=[{name: t_up, type: event_time, event: up}]")
    res = dynsens.run_case(case)
    t_ev = res.responses["t_up"].value
    exact = brentq(lambda t: exact_u(t) - 0.3, 0.3, 0.7)
    assert res.status == "terminated" and t_ev == pytest.approx(exact, abs=1e-4)
    assert res.time[-2] < t_ev <= res.time[-1]
    # its gradient against complex step of the whole run (the same accepted steps)
    cs = complex_step_gradients(case)["t_up"]
    assert rel_err(res.responses["t_up"].gradient, cs) < 1e-9


def test_ks_is_over_the_accepted_samples():
    res = dynsens.run_case(sdof(1e-5))
    q = res.history["q"][:, 0]
    best = q.max()
    ks = best + np.log(np.sum(np.exp(100.0 * (q - best)))) / 100.0
    assert res.responses["q_ks"].value == pytest.approx(ks, rel=1e-13)
    assert res.responses["q_ks"].extra["samples"] == len(res.time)


def test_result_file_stores_the_accepted_times(tmp_path):
    case = sdof(1e-5)
    res = dynsens.run_case(case)
    out = tmp_path / "adaptive.h5"
    dynsens.io.hdf5.write_result(out, res, case)
    with h5py.File(out) as f:
        t = f["time"][()]
        np.testing.assert_array_equal(t, res.time)
        assert f["state/q"].shape == (len(t), 1) and f["displacement"].shape == (len(t),)
        assert t[0] == 0.0 and t[-1] == pytest.approx(3.0, abs=1e-12)
        assert np.ptp(np.diff(t)) > 1e-3
        assert f["stats"].attrs["rejected_steps"] >= 0 and f["stats"].attrs["steps"] == len(t) - 1


def test_gradient_is_exact_along_the_accepted_steps():
    case = sdof(1e-5)
    res = dynsens.run_case(case)
    # complex step of the whole adaptive run: the controller reads real parts, so it takes the
    # steps of the real run
    cs = complex_step_gradients(case)
    for name in ("q_end", "q_ks"):
        assert rel_err(res.responses[name].gradient, cs[name]) < 1e-9, name
    # a run replaying the accepted times takes the very same steps, bit for bit
    replay = dataclasses.replace(case, plan=replaying(case.plan, res.time))
    again = dynsens.run_case(replay)
    np.testing.assert_array_equal(again.time, res.time)
    for name in ("q_end", "q_ks"):
        assert again.responses[name].value == res.responses[name].value
        np.testing.assert_allclose(again.responses[name].gradient, res.responses[name].gradient, rtol=1e-14)
    # central differences of the replaying run (its step sizes are data)
    x0, fd = case.x0, {n: np.zeros(3) for n in ("q_end", "q_ks")}
    for j in range(3):
        d = 1e-5 * abs(x0[j])
        hi, lo = x0.copy(), x0.copy()
        hi[j] += d
        lo[j] -= d
        rh, rl = (dynsens.run_case(replay, x, sensitivities=False) for x in (hi, lo))
        for n in fd:
            fd[n][j] = (rh.responses[n].value - rl.responses[n].value) / (2 * d)
    for n in fd:
        assert rel_err(fd[n], res.responses[n].gradient) < 1e-6, n


def test_finite_differences_that_re_adapt_see_the_step_selection():
    """Finite differences whose runs choose their own steps differentiate the piecewise-smooth
    map x → J(x, steps(x)): they differ from the gradient along the accepted sequence by the
    step-selection effect, (J(x ± δ, own steps) − J(x ± δ, replayed steps))/δ, which is of the
    size of the solution's error (∝ rtol^(2/3)) over δ."""
    base = sdof(1e-6)
    res = dynsens.run_case(base)
    g = res.responses["q_end"].gradient
    replay = dataclasses.replace(base, plan=replaying(base.plan, res.time))
    j, x0 = 2, base.x0                      # the stiffness k
    d = 1e-3 * x0[j]
    own, same = [], []
    for sign in (1, -1):
        x = x0.copy()
        x[j] += sign * d
        own.append(dynsens.run_case(base, x, sensitivities=False).responses["q_end"].value)
        same.append(dynsens.run_case(replay, x, sensitivities=False).responses["q_end"].value)
    fd_own = (own[0] - own[1]) / (2 * d)
    fd_same = (same[0] - same[1]) / (2 * d)
    effect = (abs(own[0] - same[0]) + abs(own[1] - same[1])) / (2 * d)
    # along the sequence: the central difference's own O(δ²) error only
    assert abs(fd_same - g[j]) < 1e-5 * abs(g[j])
    # re-adapted: the perturbed runs take other steps (an effect that is there) ...
    assert effect > 0.0
    # ... of the size of the solution's error over δ: |q_end − exact| ≈ 2e-5 here
    err = abs(res.responses["q_end"].value - exact_u(3.0))
    assert abs(fd_own - g[j]) <= effect + 1e-5 * abs(g[j]) and effect < 2 * err / d


@pytest.mark.parametrize("scheme", [[], ["integrator.scheme=hht", "integrator.alpha=0.1"],
                                    ["integrator.scheme=generalized_alpha", "integrator.rho_inf=0.7"]])
def test_adjoint_equals_direct_on_adaptive_runs(scheme):
    case = dynsens.load_case(CASES / "duffing_chain.yaml", [
        "integrator.t_end=0.3", "integrator.adaptive={rtol: 1e-4, atol: 1e-9}", "sensitivity.partials=complex",
        *scheme])
    direct = dynsens.run_case(with_plan(case, method="direct"))
    adjoint = dynsens.run_case(with_plan(case, method="adjoint"))
    assert direct.counters["rejected_steps"] > 0 and np.ptp(np.diff(direct.time)) > 0
    np.testing.assert_array_equal(direct.time, adjoint.time)
    for name, r in direct.responses.items():
        assert rel_err(adjoint.responses[name].gradient, r.gradient) < 1e-10, name
    # checkpoints and recomputed segments: the accepted steps again, bit for bit
    small = dynsens.run_case(with_plan(case, method="adjoint", memory_budget=20e3))
    assert small.counters["recomputed_steps"] > 0
    for name, r in adjoint.responses.items():
        np.testing.assert_array_equal(small.responses[name].gradient, r.gradient)


def test_adjoint_equals_direct_with_first_order_states_and_an_event():
    # the hydraulic lever: cylinder pressures are first-order states (their own error estimate)
    case = dynsens.load_case(CASES / "hydraulic_lever.yaml", [
        "integrator.adaptive={rtol: 1e-5, atol: 1e-6}", "sensitivity.partials=complex"])
    direct = dynsens.run_case(with_plan(case, method="direct"))
    adjoint = dynsens.run_case(with_plan(case, method="adjoint", memory_budget=50e3))
    assert direct.status == "terminated" and np.ptp(np.diff(direct.time)) > 0
    for name, r in direct.responses.items():
        if r.gradient is not None:
            assert rel_err(adjoint.responses[name].gradient, r.gradient) < 1e-10, name


def test_dt_min_reached_is_an_error_not_a_completed_run():
    case = sdof(1e-12, "integrator.adaptive.dt_min=1e-3", "integrator.adaptive.atol=1e-15")
    with pytest.raises(StepSizeError, match=r"integrator.adaptive.dt_min = 0.001 s.*not completed"):
        dynsens.run_case(case)
    from click.testing import CliRunner

    from dynsens.cli.main import cli
    from dynsens.cli.simulate import simulate  # noqa: F401  (registers the command)
    out = CliRunner().invoke(cli, ["simulate", str(CASES / "sdof_step.yaml"), "-o", "/dev/null", "--overwrite",
                                   "--set", "integrator.adaptive={rtol: 1e-12, atol: 1e-15, dt_min: 1e-3}"])
    assert out.exit_code != 0 and "dt_min" in out.output and "Traceback" not in out.output


@pytest.mark.parametrize("setting, path, words", [
    ("{rtol: -1}", "integrator.adaptive.rtol", "positive"),
    ("{atol: 0}", "integrator.adaptive.atol", "positive"),
    ("{dt_min: 0.1, dt_max: 0.01}", "integrator.adaptive.dt_min", "less than dt_max"),
    ("{rtl: 1e-3}", "integrator.adaptive.rtl", "unknown key"),
])
def test_bad_adaptive_settings_are_named(setting, path, words):
    with pytest.raises(CaseError, match=rf"{path}: .*{words}"):
        dynsens.load_case(CASES / "sdof_step.yaml", [f"integrator.adaptive={setting}"])


@pytest.mark.parametrize("scheme, words", [
    (["integrator.gamma=0.6", "integrator.beta=0.3025"], "first-order"),
    (["integrator.beta=0.16666666666666666"], "vanish"),
])
def test_schemes_the_estimate_does_not_measure_are_refused(scheme, words):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")        # γ > ½ also warns (first order, damping)
        with pytest.raises(CaseError, match=rf"integrator.adaptive: .*{words}"):
            dynsens.load_case(CASES / "sdof_step.yaml", ["integrator.adaptive={rtol: 1e-4}", *scheme])


def test_fixed_step_runs_take_the_grid_of_dt():
    """Without ``integrator.adaptive`` the run takes steps of dt and counts no rejections."""
    case = dynsens.load_case(CASES / "sdof_step.yaml", ["integrator.t_end=1.0"])
    res = dynsens.run_case(case)
    assert len(res.time) == 1001 and "rejected_steps" not in res.counters
    np.testing.assert_allclose(np.diff(res.time), 1e-3, rtol=1e-9)


def test_simulate_summary_counts_accepted_and_rejected_steps(tmp_path):
    from click.testing import CliRunner

    from dynsens.cli.main import cli
    from dynsens.cli.simulate import simulate  # noqa: F401  (registers the command)
    out = CliRunner().invoke(cli, ["simulate", str(CASES / "sdof_step.yaml"), "-o", str(tmp_path / "a.h5"),
                                   "--set", "integrator.adaptive={rtol: 1e-5}", "--set", "integrator.t_end=2"])
    assert out.exit_code == 0, out.output
    with h5py.File(tmp_path / "a.h5") as f:
        n, rejected = len(f["time"]) - 1, f["stats"].attrs["rejected_steps"]
    assert f"adaptive steps: {n} accepted, {rejected} rejected, step sizes" in out.output


def test_storage_grows_with_the_steps_and_a_tiny_first_step_is_no_huge_run():
    # dt = 1e-9 s is only the first trial: no 3e9-step run is sized or refused
    res = dynsens.run_case(sdof(1e-9, "integrator.dt=1e-9", "integrator.adaptive.dt_min=1e-12"), sensitivities=False)
    assert len(res.time) > 4097                      # past the first room of the histories
    assert res.history["q"].shape[0] == len(res.time) == res.quantities["displacement"].value.shape[0]
    assert np.all(np.diff(res.time) > 0) and np.diff(res.time)[0] == pytest.approx(1e-9)
    assert np.max(np.abs(res.history["q"][:, 0] - exact_u(res.time))) < 5e-5


def test_convergence_study_refuses_adaptive_steps():
    from dynsens.analysis.convergence import work_precision
    with pytest.raises(CaseError, match=r"integrator.adaptive: the convergence study varies integrator.dt"):
        work_precision(sdof(1e-5), [1e-3, 5e-4], ["ddm-forward"])


def test_check_gradients_replays_the_accepted_steps():
    from dynsens.derivatives.gradcheck import check_gradients, to_markdown
    rep = check_gradients(sdof(1e-6, t_end=2.0), [1e-5], "central", workers=1)
    assert rep.replayed and rep.passes(1e-8), {n: rep.best_rel_diff(n) for n in rep.responses}
    assert "replay the accepted steps" in to_markdown(rep)
