"""An optimum over load cases you can trust (issue 34): each load case is verified at its own
refined step and on its own longer window, every constraint RESPONSE@CASE in its own load case;
``optimize --plots`` draws the load cases; ``--resume`` reaches the same optimum.

Before this, ``optimize`` skipped the verification of a case with load cases (exit 0 with an
unverified optimum), refused ``--plots`` (exit 2), and its ``--resume`` was untested.
"""
from __future__ import annotations

import copy
import json
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import dynsens.cli.optimize as cli_opt
import dynsens.cli.verify  # noqa: F401  (registers the command)
from dynsens.case.load import load_case_dict
from dynsens.case.load_cases import load_case_set, load_case_set_file
from dynsens.cli.main import cli
from dynsens.optimize.verify_cases import format_any_verification, store_any_verification, verify_load_cases
from dynsens.postcheck import check_members
from dynsens.simulation import run_case
from helpers import SDOF_DESIGN, ctrl_c_after_rows

REPO = Path(__file__).resolve().parents[1]
TWO_LOADS = REPO / "cases" / "truss_two_loads.yaml"


def invoke(*args: object):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def two_loads_optimum(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    """truss_two_loads optimized, verified and plotted once (the file, the plot folder, the command's
    result): the reference of the tests below."""
    folder = tmp_path_factory.mktemp("two_loads")
    out = folder / "opt.h5"
    return out, folder / "plots", invoke("optimize", TWO_LOADS, "-o", out, "--plots", folder / "plots")


def test_the_two_load_truss_optimum_is_verified_in_each_load_case(two_loads_optimum) -> None:  # type: ignore[no-untyped-def]
    out, _, r = two_loads_optimum
    assert r.exit_code == 0, r.output
    # round 0 sits on every active bound and fails at dt/4 (the case's refine), in both load cases; the bounds are
    # tightened in the load case that failed, by its own shortfall, and the optimum then passes
    assert "load case impact: does NOT pass" in r.output and "load case gust: does NOT pass" in r.output
    assert "stress_ks@gust <= 1" in r.output and "VIOLATED" in r.output
    assert "The design PASSES the verification in every load case." in r.output
    assert "verified: the optimum passes the verification" in r.output
    assert "not verified at a refined step" not in r.output
    with h5py.File(out, "r") as f:
        g = f["verification"]
        assert bool(g.attrs["passed"]) and json.loads(g.attrs["failing"]) == []
        assert json.loads(g.attrs["load_cases"]) == ["impact", "gust"]
        labels = list(g["constraints/label"].asstr()[()])
        assert labels == ["stress_ks@impact <= 1", "stress_ks@gust <= 1", "buckling_ks@impact <= 1",
                          "buckling_ks@gust <= 1"]
        assert list(g["constraints/load_case"].asstr()[()]) == ["impact", "gust", "impact", "gust"]
        assert set(g["constraints/status"].asstr()[()]) <= {"ok", "late peak"}
        for name in ("impact", "gust"):
            runs = g[f"load_cases/{name}/runs"]
            assert list(runs["name"].asstr()[()]) == ["case", "refined", "horizon", "tail"]
            dt, t_end = runs["dt"][()], runs["t_end"][()]
            assert dt[1] == dt[0] / 4 and t_end[2] > t_end[0]        # its own dt/4 and a longer window
            assert bool(g[f"load_cases/{name}"].attrs["passed"])
            assert g[f"load_cases/{name}/members/refined/tension"].shape == (16,)
        bounds = g["rounds/bounds"][()]
        x = np.asarray(g.attrs["x"])
        np.testing.assert_array_equal(x, f["optimization/summary/x"][0])
    # the stress bound is tightened in each load case by that load case's own shortfall
    assert bounds.shape == (2, 4) and np.all(bounds[0] == 1.0)
    assert bounds[1, 0] < 1.0 and bounds[1, 1] < 1.0 and bounds[1, 0] != bounds[1, 1] and bounds[1, 3] == 1.0
    # an independent check, finer than the verification itself: every member in every load case at
    # dt/16 (where the peaks have converged to 2e-4)
    for name, case in load_case_set_file(TWO_LOADS).cases.items():
        fine = load_case_dict(yaml.safe_load(case.text), name, [f"integrator.dt={case.plan.dt / 16}"])
        chk = check_members(fine, x)
        assert chk.passes(1e-3), (name, chk.worst())
        assert chk.largest > 0.98, name                                 # and not over-sized


def test_optimize_plots_a_case_with_load_cases(two_loads_optimum) -> None:  # type: ignore[no-untyped-def]
    _, plots, r = two_loads_optimum
    assert r.exit_code == 0, r.output
    written = sorted(p.name for p in plots.iterdir())
    assert written == ["opt_constraints.png", "opt_design.png", "opt_history.png", "opt_optimum_gust.png",
                       "opt_optimum_impact.png"]
    for name in written:
        assert f"plot: {plots / name}" in r.output
        assert (plots / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and (plots / name).stat().st_size > 5000


def sdof_three_loads() -> dict:
    """The SDOF design case under three load cases, each with its own step:
    ``step`` (a constant force, dt 2 ms) holds everywhere; ``knock`` (a 15 ms pulse on a 20 ms
    grid) is never sampled on its own grid and holds there, but not at dt/2; ``ramp`` (a force
    rising for 2 s, a 1 s window) holds in its window but not on the longer one."""
    raw = copy.deepcopy(SDOF_DESIGN)
    raw["model"]["loads"] = [{"dof": "u", "value": 4.0, "function": "constant"}]
    raw["integrator"]["t_end"] = 1.0
    raw["responses"][0] = {"name": "q_max", "type": "max", "quantity": {"dof": "u", "kind": "displacement"}}
    raw["optimization"]["objective"] = "cost@step"
    raw["optimization"]["constraints"] = [{"response": "q_max@all", "upper": 0.09}]
    raw["load_cases"] = {
        "step": {"integrator.dt": 0.002},
        "knock": {"model.loads[0].value": 200.0, "integrator.dt": 0.02,
                  "model.loads[0].function": {"type": "pulse", "t0": 0.0, "duration": 0.015}},
        "ramp": {"model.loads[0].value": 10.0, "model.loads[0].function": {"type": "ramp", "t0": 0.0, "t1": 2.0}},
    }
    return raw


def test_each_constraint_is_checked_in_its_own_load_case_at_its_own_step_and_window(tmp_path: Path) -> None:
    cases = load_case_set(sdof_three_loads(), "three.yaml")
    v = verify_load_cases(cases)                                       # at x0 (c = 2, k = 100)
    assert not v.passed and v.failing == ["knock", "ramp"]
    by_case = {n: {c.label: c for c in cv.constraints} for n, cv in v.cases.items()}
    step, knock, ramp = (by_case[n][f"q_max@{n} <= 0.09"] for n in ("step", "knock", "ramp"))
    assert [c.label for c in v.constraints] == ["q_max@step <= 0.09", "q_max@knock <= 0.09", "q_max@ramp <= 0.09"]
    assert step.status == "ok" and knock.status == "violated" and ramp.status == "violated"
    # each holds where the optimizer sees it; the knock fails only at dt/2, the ramp only on the longer window
    assert knock.values["case"] == 0.0 and knock.values["refined"] > 0.09 >= knock.values["horizon"]
    assert ramp.values["case"] < 0.09 and ramp.values["refined"] < 0.09 < ramp.values["horizon"]
    assert "refined run" in knock.note and "horizon run" in ramp.note
    # each load case's runs are its own: its step halved, its window extended from its own end
    dts = {n: {r.name: r.dt for r in cv.runs} for n, cv in v.cases.items()}
    assert dts["step"]["refined"] == 0.001 and dts["knock"]["refined"] == 0.01 and dts["ramp"]["refined"] == 0.005
    assert {r.name: r.t_end for r in v.cases["ramp"].runs}["horizon"] > 1.0
    # the knock's refined value is the knock run by hand at 10 ms (an independent run of the overridden case)
    base = sdof_three_loads()
    del base["load_cases"]
    base["optimization"] = {"objective": "cost", "constraints": [{"response": "q_max", "upper": 0.09}]}
    by_hand = load_case_dict(base, "by hand", ["model.loads[0].value=200.0", "integrator.dt=0.01",
                                               'model.loads[0].function={"type": "pulse", "t0": 0.0, '
                                               '"duration": 0.015}'])
    assert run_case(by_hand, sensitivities=False, history=()).responses["q_max"].value == knock.values["refined"]
    text = format_any_verification(v)
    assert "load case step: passes" in text and "load case knock: does NOT pass" in text
    assert "does NOT pass the verification in load case knock, ramp" in text
    # the file: a flat table in the optimizer's order naming each constraint's load case, and
    # each load case's verification in the one-case layout
    out = tmp_path / "v.h5"
    store_any_verification(out, v)
    with h5py.File(out, "r") as f:
        g = f["verification"]
        assert not bool(g.attrs["passed"]) and json.loads(g.attrs["failing"]) == ["knock", "ramp"]
        assert json.loads(g.attrs["load_cases"]) == ["step", "knock", "ramp"]
        assert list(g["constraints/load_case"].asstr()[()]) == ["step", "knock", "ramp"]
        assert list(g["constraints/status"].asstr()[()]) == ["ok", "violated", "violated"]
        assert g["constraints/margin_refined"][1] < -0.05 and g["constraints/margin_horizon"][2] < -0.1
        assert g["constraints/value_refined"][1] == knock.values["refined"]
        assert list(g["load_cases/knock/runs/dt"][()]) == [0.02, 0.01, 0.02, 0.02]
        assert not bool(g["load_cases/knock"].attrs["passed"]) and bool(g["load_cases/step"].attrs["passed"])


def test_an_optimum_failing_in_one_load_case_is_not_verified(tmp_path: Path) -> None:
    path = tmp_path / "three.yaml"
    path.write_text(yaml.safe_dump(sdof_three_loads(), sort_keys=False))
    out = tmp_path / "opt.h5"
    r = invoke("optimize", path, "-o", out)
    # the optimizer converges to a feasible design (the step active), which fails in the knock at
    # dt/2 and in the ramp on the longer window: not verified, exit 1, as for one case
    assert r.exit_code == 1, r.output
    assert "The optimizer converged" in r.output and "The result is feasible" in r.output
    assert "load case step: passes" in r.output
    assert "load case knock: does NOT pass" in r.output and "load case ramp: does NOT pass" in r.output
    assert "does NOT pass the verification in load case knock, ramp" in r.output and "NOT VERIFIED" in r.output
    with h5py.File(out, "r") as f:
        g = f["verification"]
        assert not bool(g.attrs["passed"]) and json.loads(g.attrs["failing"]) == ["knock", "ramp"]
        assert min(g["constraints/margin_case"][()]) > -1e-4               # it held on the optimizer's grid
    r = invoke("verify", path, "--from", out)                               # dynsens verify says the same
    assert r.exit_code == 1 and "does NOT pass the verification in load case knock, ramp" in r.output, r.output


def test_resume_of_an_interrupted_two_load_optimization_reaches_the_same_optimum(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, two_loads_optimum) -> None:  # type: ignore[no-untyped-def]
    ref, _, r_ref = two_loads_optimum
    assert r_ref.exit_code == 0, r_ref.output
    with h5py.File(ref, "r") as f:
        x_ref, f_ref = f["verification"].attrs["x"], float(f["optimization/summary/f"][0])
        x_round0 = f["verification/rounds/x"][0]
    out = tmp_path / "opt.h5"
    real = ctrl_c_after_rows(monkeypatch)
    r = invoke("optimize", TWO_LOADS, "-o", out)
    assert r.exit_code == 130 and "--resume" in r.output, r.output
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "interrupted" and "verification" not in f
        assert f["optimization/start_0/history/x"].shape == (3, 3)
        assert "load_cases" not in f["optimization"]            # no optimum stored yet
    monkeypatch.setattr(cli_opt, "progress_line", real)
    r = invoke("optimize", TWO_LOADS, "-o", out, "--resume")
    assert r.exit_code == 0, r.output
    resumed = r.output.split("verification of the optimum:")[0]
    assert "[start 0] it   3" in resumed and "[start 0] it   0" not in resumed
    assert "The design PASSES the verification in every load case." in r.output
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "converged"
        rounds_x = f["verification/rounds/x"][()]
        x, fx = f["verification"].attrs["x"], float(f["optimization/summary/f"][0])
        assert set(f["optimization/load_cases"]) == {"impact", "gust"}
    # SLSQP restarts its Hessian at the resumed iterate: the same optimum to its tolerance (ftol 1e-6),
    # and after the tightening round the same verified design
    np.testing.assert_allclose(rounds_x[0], x_round0, rtol=1e-4)
    np.testing.assert_allclose(x, x_ref, rtol=1e-4)
    assert fx == pytest.approx(f_ref, rel=1e-5)
