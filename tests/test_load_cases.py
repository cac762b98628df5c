"""Named load cases (issue 34): each load case is the base case with its overrides; the KS over
load cases has the gradient of the complex step of the whole runs."""
from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml

import dynsens

from dynsens.case.load import load_case_dict
from dynsens.case.load_cases import aggregate_over_cases, evaluate_load_cases, load_case_set
from dynsens.errors import CaseError
from dynsens.simulation import run_case

ROOT = Path(__file__).resolve().parents[1]


def _raw(method: str = "adjoint") -> dict:
    raw = yaml.safe_load((ROOT / "cases" / "sdof_step.yaml").read_text())
    raw["integrator"]["t_end"] = 1.0
    raw["sensitivity"]["method"] = method
    raw["load_cases"] = {
        "impact": {"model.loads[0].value": 40.0, "integrator.t_end": 0.6},
        "gust": {"model.loads[0].value": 10.0, "model.initial.velocity": {"u": 0.3}},
    }
    return raw


def test_each_load_case_equals_the_overridden_case_by_hand():
    raw = _raw()
    cases = load_case_set(raw, "lc")
    values, grads = evaluate_load_cases(cases, np.array([d.value for d in cases.case("impact").design]))
    base = copy.deepcopy(raw)
    del base["load_cases"]
    by_hand = load_case_dict(base, "by hand", ["model.loads[0].value=40.0", "integrator.t_end=0.6"])
    res = run_case(by_hand, history=())
    assert values["q_ks@impact"] == res.responses["q_ks"].value            # bit-identical
    assert np.array_equal(grads["q_ks@impact"], res.responses["q_ks"].gradient)
    assert values["q_ks@impact"] != values["q_ks@gust"]


def test_ks_over_load_cases_against_complex_step_and_direct():
    cases = load_case_set(_raw("adjoint"), "lc")
    x = np.array([d.value for d in cases.case("gust").design])
    names = list(cases.cases)
    values, grads = evaluate_load_cases(cases, x)
    ks, g = aggregate_over_cases(values, grads, "q_ks", names, rho=20.0)
    h = 1e-30
    cs = np.empty(x.size)
    for j in range(x.size):
        xc = x.astype(complex)
        xc[j] += 1j * h
        vc, _ = evaluate_load_cases(cases, xc, sensitivities=False)
        cs[j] = np.imag(aggregate_over_cases(vc, {}, "q_ks", names, rho=20.0)[0]) / h
    assert np.allclose(g, cs, rtol=1e-7, atol=1e-12)                 # stated tolerance: 1e-7 relative
    direct = load_case_set(_raw("direct"), "lc")
    vd, gd = evaluate_load_cases(direct, x)
    _, g_direct = aggregate_over_cases(vd, gd, "q_ks", names, rho=20.0)
    assert np.allclose(g, g_direct, rtol=1e-11, atol=1e-14)          # adjoint = direct to round-off
    m, gm = aggregate_over_cases(values, grads, "q_ks", names, how="max")
    assert m <= ks <= m + np.log(2) / 20.0


def test_bad_load_cases_are_named():
    raw = _raw()
    raw["load_cases"]["impact"]["model.elements[0].mass"] = 3.0
    with pytest.raises(CaseError) as err:
        load_case_set(raw, "lc.yaml")
    assert "load_cases.impact.model.elements[0].mass" in str(err.value)
    assert "not overridable" in str(err.value) and "lc.yaml" in str(err.value)
    with pytest.raises(CaseError, match="unknown load case 'wind'"):
        load_case_set(_raw(), "lc.yaml").case("wind")
    raw = _raw()
    raw["load_cases"] = []
    with pytest.raises(CaseError, match="non-empty mapping"):
        load_case_set(raw, "lc.yaml")
    raw = _raw()
    raw["load_cases"]["gust"]["integrator.dt"] = -1.0
    with pytest.raises(CaseError, match="load_cases.gust"):
        load_case_set(raw, "lc.yaml")


def test_a_case_without_load_cases_is_one_load_case():
    raw = _raw()
    del raw["load_cases"]
    cases = load_case_set(raw, "plain")
    assert list(cases.cases) == ["sdof_step"]


def test_load_cases_run_in_parallel_on_the_executor_with_the_same_numbers():
    from dynsens.executor import ProcessExecutor
    cases = load_case_set(_raw(), "lc")
    x = np.array([d.value for d in cases.case("gust").design])
    serial = evaluate_load_cases(cases, x)
    with ProcessExecutor(2) as ex:
        parallel = evaluate_load_cases(cases, x, executor=ex)
    assert serial[0] == parallel[0]
    assert all(np.array_equal(serial[1][k], parallel[1][k]) for k in serial[1])


def test_a_single_case_loader_refuses_load_cases_by_name():
    with pytest.raises(CaseError, match="load_cases.*load_case_set"):
        load_case_dict(_raw(), "lc.yaml")


def _cli(args: list[str]):  # type: ignore[no-untyped-def]
    from click.testing import CliRunner

    from dynsens.cli import check_gradients, optimize, simulate  # noqa: F401  (registers the commands)
    from dynsens.cli.main import cli
    return CliRunner().invoke(cli, args)


def test_simulate_writes_one_group_per_load_case_equal_to_the_api(tmp_path: Path):
    import h5py

    from dynsens.case.load_cases import simulate_load_cases
    from dynsens.io.reader import read_result
    path = tmp_path / "two_loads.yaml"
    path.write_text(yaml.safe_dump(_raw("direct"), sort_keys=False))
    out = tmp_path / "out.h5"
    res = _cli(["simulate", str(path), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "load case impact:" in res.output and "load case gust:" in res.output
    api = simulate_load_cases(load_case_set(_raw("direct"), "lc"))
    with h5py.File(out, "r") as f:
        assert list(f["load_cases"]) == sorted(api) and f.attrs["status"] == "completed"
        assert "load_cases" in yaml.safe_load(f.attrs["case"])
        for name, run in api.items():
            g = f["load_cases"][name]
            assert np.array_equal(g["time"][()], run.time)                       # bit for bit
            for r, v in run.responses.items():
                assert g["responses"][r]["value"][()] == v.value
                assert np.array_equal(g["responses"][r]["gradient"][()], v.gradient)
    back = read_result(str(out), group="load_cases/impact")
    assert back.responses["q_ks"]["value"] == api["impact"].responses["q_ks"].value
    from dynsens.cli import info  # noqa: F401  (registers the command)
    shown = _cli(["info", str(out)])
    assert shown.exit_code == 0 and "load case impact (/load_cases/impact): status completed" in shown.output
    assert "load case gust" in shown.output and "q_ks = " in shown.output
    again = _cli(["simulate", str(path), "-o", str(out)])                     # no clobbering
    assert again.exit_code != 0 and "--overwrite" in again.output


def test_simulate_refuses_plots_of_load_cases_and_bad_load_cases_with_exit_2(tmp_path: Path):
    path = tmp_path / "two_loads.yaml"
    path.write_text(yaml.safe_dump(_raw()))
    res = _cli(["simulate", str(path), "-o", str(tmp_path / "out.h5"), "--plots", str(tmp_path / "p")])
    assert res.exit_code == 2 and "--plots" in res.output and "load_cases" in res.output
    raw = _raw()
    raw["load_cases"]["impact"]["model.elements[0].mass"] = 3.0
    path.write_text(yaml.safe_dump(raw))
    res = _cli(["simulate", str(path), "-o", str(tmp_path / "out.h5")])
    assert res.exit_code == 2, res.output
    assert "load_cases.impact.model.elements[0].mass" in res.output and "two_loads.yaml" in res.output
    assert "Traceback" not in res.output
    assert not (tmp_path / "out.h5").exists()


def test_check_gradients_checks_every_load_case(tmp_path: Path):
    path = tmp_path / "two_loads.yaml"
    path.write_text(yaml.safe_dump(_raw("adjoint"), sort_keys=False))
    res = _cli(["check-gradients", str(path), "--scheme", "complex", "--steps", "1e-20", "--rtol", "1e-6",
                "--workers", "1", "-o", str(tmp_path / "rep")])
    assert res.exit_code == 0, res.output
    assert "## load case impact" in res.output and "## load case gust" in res.output
    for name in ("impact", "gust"):
        assert f"gradient check in load case {name} passed at rtol = 1e-06" in res.output
    import json
    data = json.loads((tmp_path / "rep.json").read_text())
    assert sorted(data) == ["gust", "impact"]
    # a gradient off in one load case fails the check, naming it (rtol below round-off)
    res = _cli(["check-gradients", str(path), "--steps", "1e-3", "--rtol", "1e-12", "--workers", "1"])
    assert res.exit_code == 1 and "in load case impact" in res.output


TWO_LOADS = ROOT / "cases" / "truss_two_loads.yaml"


def _optimum(path: Path, load_case: str) -> tuple[np.ndarray, dict]:
    import h5py
    with h5py.File(path, "r") as f:
        g = f[f"optimization/load_cases/{load_case}/optimum"]
        return g["x"][()], dict(g["responses"].attrs)


def test_optimize_the_shipped_two_load_case_truss_to_a_feasible_design_active_in_both(tmp_path: Path):
    # the optimizer alone (tests/test_load_case_verification.py: the same case verified and tightened)
    out = tmp_path / "opt.h5"
    res = _cli(["optimize", str(TWO_LOADS), "-o", str(out), "--no-verify"])
    assert res.exit_code == 0, res.output
    assert "The optimizer converged" in res.output and "The result is feasible" in res.output
    assert "stress_ks@impact <= 1; stress_ks@gust <= 1" in res.output
    x, impact = _optimum(out, "impact")
    _, gust = _optimum(out, "gust")
    # the gust sizes the chords, the impact the webs: the stress limit is active in both
    assert abs(impact["stress_ks"] - 1.0) < 1e-4 and abs(gust["stress_ks"] - 1.0) < 1e-4
    assert max(impact["buckling_ks"], gust["buckling_ks"]) < 1.0 + 1e-4
    assert impact["mass"] == gust["mass"]
    # one start with --workers: its load cases run in parallel, with the same numbers
    res = _cli(["optimize", str(TWO_LOADS), "-o", str(tmp_path / "parallel.h5"), "--workers", "2", "--no-verify"])
    assert res.exit_code == 0 and "in parallel on 2 local processes" in res.output, res.output
    assert np.array_equal(_optimum(tmp_path / "parallel.h5", "impact")[0], x)
    # the Python API optimizes the same load cases (a path; and a mapping with an override) to
    # the same design (it refused load cases before)
    api = dynsens.optimize(TWO_LOADS, verify=False)
    assert api.success and api.feasible and np.array_equal(api.x, x)
    assert abs(api.constraints["stress_ks@gust"] - gust["stress_ks"]) == 0.0
    raw = yaml.safe_load(TWO_LOADS.read_text(encoding="utf-8"))
    short = dynsens.optimize(raw, verify=False, maxiter=1)
    assert short.nit <= 1 and set(short.constraints) == set(api.constraints)


def test_a_dominated_load_case_stays_inactive_and_the_optimum_is_the_single_case_one(tmp_path: Path):
    # the second load case is the impact at half the force: never active, so the optimum is
    # truss_lightweight's (the same model under the impact alone), to the optimizer's tolerance
    raw = yaml.safe_load(TWO_LOADS.read_text())
    raw["load_cases"] = {"impact": {}, "half": {"model.loads[0].value": -30000.0}}
    path = tmp_path / "dominated.yaml"
    path.write_text(yaml.safe_dump(raw, sort_keys=False))
    res = _cli(["optimize", str(path), "-o", str(tmp_path / "two.h5"), "--no-verify"])
    assert res.exit_code == 0, res.output
    x_two, impact = _optimum(tmp_path / "two.h5", "impact")
    _, half = _optimum(tmp_path / "two.h5", "half")
    assert half["stress_ks"] < 0.7 and half["buckling_ks"] < 0.7          # inactive
    assert "stress_ks@half = " in res.output and "inactive" in res.output
    single = tmp_path / "single.yaml"
    del raw["load_cases"]
    raw["optimization"]["objective"] = "mass"
    raw["optimization"]["constraints"] = [{"response": "stress_ks", "upper": 1.0},
                                          {"response": "buckling_ks", "upper": 1.0}]
    single.write_text(yaml.safe_dump(raw, sort_keys=False))
    res = _cli(["optimize", str(single), "-o", str(tmp_path / "one.h5"), "--no-verify"])
    assert res.exit_code == 0, res.output
    import h5py
    with h5py.File(tmp_path / "one.h5", "r") as f:
        x_one = f["optimization/optimum/x"][()]
    assert np.allclose(x_two, x_one, rtol=1e-3), (x_two, x_one)     # SLSQP ftol 1e-6, different paths


def test_adjoint_equals_direct_in_each_load_case_of_the_shipped_truss():
    from dynsens.case.load_cases import load_case_set_file
    x = None
    results = {}
    for method in ("direct", "adjoint"):
        # complex partials: the two modes then agree to round-off (as tests/test_adjoint.py checks)
        cases = load_case_set_file(TWO_LOADS, [f"sensitivity.method={method}", "sensitivity.partials=complex"])
        x = np.array([d.value for d in cases.design]) * 0.9
        results[method] = evaluate_load_cases(cases, x)
    assert x is not None
    (_, gd), (_, ga) = results["direct"], results["adjoint"]
    assert sorted(gd) == sorted(ga) and "stress_ks@gust" in gd
    for k in gd:   # relative to the gradient's norm, as tests/test_adjoint.py
        assert np.linalg.norm(ga[k] - gd[k]) <= 1e-10 * np.linalg.norm(gd[k]), k


@pytest.mark.parametrize("objective, constraint, message", [
    ("mass@impact", "stress_ks@wind", "optimization.constraints[0].response"),
    ("mass@all", "stress_ks@all", "a constraint only"),
    ("mass", "stress_ks@all", "optimization.objective"),
])
def test_optimize_names_a_bad_response_over_load_cases_with_exit_2(tmp_path: Path, objective, constraint, message):
    raw = yaml.safe_load(TWO_LOADS.read_text())
    raw["optimization"]["objective"] = objective
    raw["optimization"]["constraints"] = [{"response": constraint, "upper": 1.0}]
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(raw, sort_keys=False))
    res = _cli(["optimize", str(path), "-o", str(tmp_path / "o.h5")])
    assert res.exit_code == 2, res.output
    assert message in res.output and "bad.yaml" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "o.h5").exists()


def test_a_command_that_does_not_run_load_cases_refuses_them_by_name_with_exit_2(tmp_path: Path):
    from dynsens.cli import modes  # noqa: F401  (registers the command)
    path = tmp_path / "two_loads.yaml"
    path.write_text(yaml.safe_dump(_raw()))
    res = _cli(["modes", str(path)])
    assert res.exit_code == 2, res.output
    assert "load_cases" in res.output and "this command does not yet" in res.output
    assert "two_loads.yaml" in res.output and "Traceback" not in res.output
