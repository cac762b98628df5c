"""Bad input, faults and silent wrong answers: one test per class.

Every refusal is checked through the command line: exit status 2, one "Error:" message that
names the file, the YAML key path, what was expected and what was found, no traceback, and
nothing written (no output file, no temporary file) in the output folder.
"""
from __future__ import annotations

import copy
import math
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import dynsens.cli.check_gradients  # noqa: F401  (registers the commands)
import dynsens.cli.convergence  # noqa: F401
import dynsens.cli.optimize  # noqa: F401
import dynsens.cli.simulate  # noqa: F401
from dynsens.case.load import load_case, load_case_text
from dynsens.cli.main import cli
from dynsens.errors import CaseError, DesignError, NonFiniteError
from dynsens.timeloop.runchecks import check_result
from dynsens.simulation import run_case
from helpers import SDOF_RUN

REPO = Path(__file__).resolve().parents[1]
CASES = REPO / "cases"

BASE = {**copy.deepcopy(SDOF_RUN), "name": "sdof_rel",
        "integrator": {"scheme": "newmark", "beta": 0.25, "gamma": 0.5, "dt": 5.0e-3, "t_end": 0.2},
        "events": [{"name": "crossing", "quantity": {"dof": "u", "kind": "displacement"}, "value": 10.0}]}


def make(mutate=None) -> dict:
    raw = copy.deepcopy(BASE)
    if mutate is not None:
        mutate(raw)
    return raw


@pytest.fixture
def runner() -> CliRunner:
    return CliRunner()


def write_case(folder: Path, raw_or_text, name: str = "case.yaml") -> Path:
    p = folder / name
    text = raw_or_text if isinstance(raw_or_text, str) else yaml.safe_dump(raw_or_text, sort_keys=False)
    p.write_text(text, encoding="utf-8")
    return p


def refused(runner: CliRunner, args: list[str], *fragments: str) -> str:
    """Run the CLI; assert exit 2, one clean message with every fragment, no traceback."""
    res = runner.invoke(cli, args)
    out = res.output
    assert res.exit_code == 2, (res.exit_code, out, res.exception)
    assert "Traceback" not in out and out.count("Error:") == 1, out
    for frag in fragments:
        assert frag in out, (frag, out)
    return out


def nothing_written(out_dir: Path) -> None:
    """No file at all (output or temporary) in the output folder."""
    assert not out_dir.exists() or list(out_dir.iterdir()) == [], list(out_dir.iterdir())


def simulate_refused(runner: CliRunner, tmp_path: Path, case, *fragments: str) -> str:
    case_path = case if isinstance(case, Path) else write_case(tmp_path, case)
    out_dir = tmp_path / "out"
    out_dir.mkdir(exist_ok=True)
    msg = refused(runner, ["simulate", str(case_path), "-o", str(out_dir / "r.h5")], *fragments)
    nothing_written(out_dir)
    return msg


# ---------------------------------------------------------------- silently wrong, exit 0 before
def test_duplicate_yaml_key_is_refused(runner, tmp_path):
    text = yaml.safe_dump(make(), sort_keys=False)
    text += "model:\n  type: structural\n  dofs: [v]\n"
    msg = simulate_refused(runner, tmp_path, text, "case.yaml", "model:", "expected each key once",
                           "found it again at line")
    assert "silently replace" in msg


@pytest.mark.parametrize("mutate, path, found", [
    (lambda r: r["design"]["variables"][1].__setitem__("name", "m"), "design.variables[1].name", "'m'"),
    (lambda r: r["events"].append(dict(r["events"][0])), "events[1].name", "'crossing'"),
    (lambda r: r["responses"][1].__setitem__("name", "q_end"), "responses[1].name", "'q_end'"),
    (lambda r: r["model"]["elements"][2].__setitem__("name", "spring"), "model.elements[2].name", "'spring'"),
])
def test_duplicate_names_of_every_kind(runner, tmp_path, mutate, path, found):
    simulate_refused(runner, tmp_path, make(mutate), "case.yaml", path, found)


def test_duplicate_joint_name(runner, tmp_path):
    text = (CASES / "slider_crank.yaml").read_text()
    raw = yaml.safe_load(text)
    raw["model"]["joints"][1]["name"] = raw["model"]["joints"][0]["name"]
    simulate_refused(runner, tmp_path, raw, "case.yaml", "model.joints[1].name", "duplicate joint name")


@pytest.mark.parametrize("where, name", [("design", "pi"), ("design", "e"), ("design", "sin"),
                                         ("responses", "exp")])
def test_names_shadowing_constants_and_functions(runner, tmp_path, where, name):
    def mutate(r):
        if where == "design":
            r["design"]["variables"][0]["name"] = name
            r["model"]["elements"][0]["mass"] = 2.0
        else:
            r["responses"][0]["name"] = name
    path = "design.variables[0].name" if where == "design" else "responses[0].name"
    simulate_refused(runner, tmp_path, make(mutate), path, "expected a name that is not a constant or function",
                     f"found '{name}'")


@pytest.mark.parametrize("value, found", [("-2", "found -2"), ("m - 10", "found -8"), ("0*m", "found 0")])
def test_expression_values_get_the_literal_range_checks(runner, tmp_path, value, found):
    raw = make(lambda r: r["model"]["elements"][0].__setitem__("mass", value))
    simulate_refused(runner, tmp_path, raw, "case.yaml", "model.elements[0].mass", "expected > 0", found,
                     "start design")


def test_negative_body_inertia_as_expression(runner, tmp_path):
    raw = yaml.safe_load((CASES / "pendulum_3d.yaml").read_text())
    raw["model"]["bodies"]["bob"]["inertia"] = [1e-6, "1e-6 - m", 1e-6]
    simulate_refused(runner, tmp_path, raw, "model.bodies.bob.inertia[1]", "expected > 0", "m = 1")


def test_range_checked_at_every_evaluated_design():
    # valid at x0 (mass 1), negative at m = 0.8: a failed evaluation naming the entry, never a result
    case = load_case_text(yaml.safe_dump(make(lambda r: r["model"]["elements"][0].__setitem__("mass", "m - 1"))),
                          "design.yaml")
    with pytest.raises(DesignError) as info:
        run_case(case, np.array([0.8, 0.8, 50.0]))
    msg = str(info.value)
    assert "design.yaml" in msg and "model.elements[0].mass" in msg and "expected > 0" in msg, msg
    assert "m = 0.8" in msg
    # the optimizer sees it as a failed simulation with that reason
    from dynsens.optimize.problem import simulate
    res, why, _ = simulate(case, np.array([0.8, 0.8, 50.0]))
    assert res is None and "model.elements[0].mass" in why


def test_dt_longer_than_the_interval(runner, tmp_path):
    raw = make(lambda r: r["integrator"].__setitem__("dt", 0.5))
    simulate_refused(runner, tmp_path, raw, "integrator.dt", "expected at most t_end - t0 = 0.2 s", "found 0.5 s")


@pytest.mark.parametrize("expression, fragment", [("log(-q_end)", "a value outside a function's domain"),
                                                  ("q_end/0", "division by zero")])
def test_non_finite_response_is_a_failure(runner, tmp_path, expression, fragment):
    raw = make(lambda r: r["responses"].append({"name": "bad", "type": "expression", "expression": expression}))
    simulate_refused(runner, tmp_path, raw, "response 'bad'", expression, fragment)


def test_non_finite_gradient_names_response_variable_and_first_step():
    case = load_case_text(yaml.safe_dump(make(lambda r: r.__setitem__(
        "output", {"sensitivity_history": True}))), "grad.yaml")
    res = run_case(case)
    check_result(case, res)                                   # the real run passes
    r = res.responses["q_end"]
    bad_grad = r.gradient.copy()
    bad_grad[1] = np.inf
    shist = {k: v.copy() for k, v in res.sensitivity_history.items()}
    shist["q"][7:, 0, 1] = np.nan
    broken = replace(res, responses={**res.responses, "q_end": replace(r, gradient=bad_grad)},
                     sensitivity_history=shist)
    with pytest.raises(NonFiniteError) as info:
        check_result(case, broken)
    msg = str(info.value)
    assert "grad.yaml" in msg and "'q_end'" in msg and "'c'" in msg and "step 7" in msg, msg
    assert "failed, not completed" in msg


def test_check_gradients_report_not_overwritten(runner, tmp_path):
    case = write_case(tmp_path, make())
    out = tmp_path / "out"
    out.mkdir()
    (out / "rep.md").write_text("old")
    refused(runner, ["check-gradients", str(case), "-o", str(out / "rep")], "rep.md exists", "--overwrite")
    assert (out / "rep.md").read_text() == "old" and sorted(p.name for p in out.iterdir()) == ["rep.md"]


def test_convergence_report_not_overwritten_and_checked_before_the_run(runner, tmp_path):
    case = write_case(tmp_path, make())
    out = tmp_path / "out"
    out.mkdir()
    (out / "sdof_rel_work_precision.md").write_text("old")
    refused(runner, ["convergence", str(case), "-o", str(out), "--methods", "ddm-forward"],
            "sdof_rel_work_precision.md exists", "--overwrite")
    assert sorted(p.name for p in out.iterdir()) == ["sdof_rel_work_precision.md"]


def test_unused_design_variable_is_reported(runner, tmp_path):
    raw = make(lambda r: r["model"]["elements"][2].__setitem__("c", 0.8))
    with pytest.warns(UserWarning, match="design variable c used by no element"):
        load_case_text(yaml.safe_dump(raw), "unused.yaml")
    res = runner.invoke(cli, ["simulate", str(write_case(tmp_path, raw)), "-o", str(tmp_path / "r.h5")])
    assert res.exit_code == 0, res.output
    assert "gradient with respect to c is exactly zero for every response" in res.output


# ---------------------------------------------------------------- tracebacks and hangs before
def test_alias_bomb_is_refused_quickly(runner, tmp_path):
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x]"]
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 10)]
    simulate_refused(runner, tmp_path, "\n".join(lines) + "\n", "case.yaml", "aliases", "expected at most")


def test_recursive_alias_is_refused(runner, tmp_path):
    simulate_refused(runner, tmp_path, "model: &a [*a]\n", "recursive")


@pytest.mark.parametrize("encoding, fragment", [("utf-16", "found UTF-16 text"), ("binary", "found binary data"),
                                                ("latin-1", "found byte 0xe9")])
def test_encodings(runner, tmp_path, encoding, fragment):
    text = yaml.safe_dump(make(), sort_keys=False) + "description: café\n"
    p = tmp_path / "case.yaml"
    if encoding == "binary":
        p.write_bytes(b"\x89HDF\r\n\x1a\n\x00\x00\x00" + bytes(range(256)))
    else:
        p.write_bytes(text.encode(encoding))
    simulate_refused(runner, tmp_path, p, "case.yaml", "expected UTF-8 text", fragment)


@pytest.mark.parametrize("value, fragment", [
    ("1/(m - 2)", "division by zero"),
    ("9**9**9", "overflows"),
    ("(-8)**(1/3) + m", "complex value"),
    ("sqrt(-m)", "outside a function's domain"),
    ("sin(" * 150 + "m" + ")" * 150, "levels deep"),
])
def test_expression_errors_name_the_key(runner, tmp_path, value, fragment):
    raw = make(lambda r: r["model"]["elements"][0].__setitem__("mass", value))
    simulate_refused(runner, tmp_path, raw, "case.yaml", "model.elements[0].mass", fragment)


def test_long_legitimate_sum_within_the_length_limit():
    # 990 terms, under the 2000-character limit: evaluated in a loop, not 990 nested calls
    expr = "(" + "+".join(["m"] * 990) + ")/990"   # = m, written the long way
    assert len(expr) < 2000
    case = load_case_text(yaml.safe_dump(make(lambda r: r["model"]["elements"][0].__setitem__("mass", expr))),
                          "sum.yaml")
    ref = load_case_text(yaml.safe_dump(make()), "ref.yaml")
    a, b = run_case(case), run_case(ref)
    assert math.isclose(a.responses["q_end"].value, b.responses["q_end"].value, rel_tol=1e-12)


def test_huge_step_count_refused_with_the_estimate(runner, tmp_path):
    simulate_refused(runner, tmp_path, make(lambda r: r["integrator"].__setitem__("dt", 1e-12)),
                     "integrator.dt", "expected at most 1e+08 steps", "increase dt")


def test_memory_estimate_refuses_a_run_that_does_not_fit(runner, tmp_path, monkeypatch):
    import dynsens.timeloop.runchecks as rc
    monkeypatch.setattr(rc, "available_memory", lambda: 2**20)      # a 1 MiB machine
    simulate_refused(runner, tmp_path, make(lambda r: r["integrator"].__setitem__("dt", 1e-5)),
                     "integrator.dt", "2.000e+04 steps storing histories [q, qd, qdd]", "MiB available",
                     "output.history: none")


@pytest.mark.parametrize("mutate, path, fragment", [
    (lambda r: r["model"]["joints"][0].__setitem__("axis", [0, 0, 0]), "model.joints[0].axis",
     "expected a nonzero joint axis, found [0.0, 0.0, 0.0]"),
    (lambda r: r["model"]["joints"][0].__setitem__("axis", ["0*L", 0, 0]), "model.joints[0].axis",
     "expected a nonzero joint axis"),
    (lambda r: r["model"]["bodies"]["bob"].__setitem__("orientation", {"euler_parameters": [0, 0, 0, 0]}),
     "model.bodies.bob.orientation.euler_parameters", "expected a nonzero set of Euler parameters"),
])
def test_zero_axis_and_euler_parameters(runner, tmp_path, mutate, path, fragment):
    raw = yaml.safe_load((CASES / "pendulum_3d.yaml").read_text())
    mutate(raw)
    simulate_refused(runner, tmp_path, raw, path, fragment)


# ---------------------------------------------------------------- outputs
def test_output_path_with_a_file_as_folder_is_refused_before_the_run(runner, tmp_path):
    case = write_case(tmp_path, make())
    (tmp_path / "afile").write_text("x")
    refused(runner, ["simulate", str(case), "-o", str(tmp_path / "afile" / "r.h5")], "afile is a file")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile", "case.yaml"]


def test_output_name_too_long_is_refused(runner, tmp_path):
    case = write_case(tmp_path, make())
    out = tmp_path / "out"
    refused(runner, ["simulate", str(case), "-o", str(out / ("r" * 300 + ".h5"))], "at most 255 bytes")
    nothing_written(out)


def test_case_name_cannot_leave_the_output_folder(runner, tmp_path):
    raw = make(lambda r: r.__setitem__("name", "../../escaped"))
    case = write_case(tmp_path, raw)
    out = tmp_path / "a" / "b"
    res = runner.invoke(cli, ["convergence", str(case), "-o", str(out), "--methods", "ddm-forward",
                              "--dt", "0.01,0.005"])
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in tmp_path.rglob("*escaped*")) == sorted(p.name for p in out.iterdir())
    assert all(p.parent == out for p in tmp_path.rglob("*escaped*"))
    assert not [p for p in out.iterdir() if p.name.startswith(".")]


def test_result_files_follow_the_umask(runner, tmp_path):
    import os
    case = write_case(tmp_path, make())
    old = os.umask(0o022)
    try:
        res = runner.invoke(cli, ["simulate", str(case), "-o", str(tmp_path / "r.h5")])
        res2 = runner.invoke(cli, ["check-gradients", str(case), "-o", str(tmp_path / "rep"), "--steps", "1e-6"])
    finally:
        os.umask(old)
    assert res.exit_code == 0 and res2.exit_code == 0, res.output + res2.output
    for name in ("r.h5", "rep.md", "rep.json"):
        assert (tmp_path / name).stat().st_mode & 0o777 == 0o644, name


def test_second_optimize_writer_is_refused(runner, tmp_path):
    from dynsens.optimize.store import lock_path, writer_lock
    case = CASES / "truss_lightweight.yaml"
    out = tmp_path / "opt.h5"
    with writer_lock(out):
        refused(runner, ["optimize", str(case), "-o", str(out), "--maxiter", "1"],
                "opt.h5 is being written by another dynsens process", "another -o file")
        assert not out.exists()
    assert not lock_path(out).exists()      # released and removed


def _damaged_file(path: Path, case) -> None:
    import h5py
    with h5py.File(path, "w") as f:
        f.attrs["case"] = case.text
        g = f.create_group("optimization")
        for k, v in {"f_ref": 1.0, "starts": 1, "seed": 3, "x_starts": np.array([case.x0]), "objective": "mass",
                     "constraints": "[]", "response_names": "[]"}.items():
            g.attrs[k] = v
        h = f.create_group("optimization/start_0/history")
        h.create_dataset("x", data=np.array([case.x0, case.x0]))
        h.create_dataset("iteration", data=np.array([0]))
        h.create_dataset("segment", data=np.array([0, 0]))
        h.create_dataset("elapsed", data=np.array([0.0, 1.0]))


@pytest.mark.parametrize("damage, fragment", [("garbage", "cannot be read as HDF5"),
                                              ("columns", "columns of unequal length")])
def test_damaged_history_on_resume(runner, tmp_path, damage, fragment):
    case_path = CASES / "truss_lightweight.yaml"
    out = tmp_path / "opt.h5"
    if damage == "garbage":
        out.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\x00" * 64)
    else:
        _damaged_file(out, load_case(case_path))
    before = out.read_bytes()
    refused(runner, ["optimize", str(case_path), "-o", str(out), "--resume"], "opt.h5 is damaged", fragment,
            "without --resume")
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["opt.h5"]


def test_messages_of_the_old_checks_still_hold():
    # the file name is in every case error (CaseError lists all problems at once)
    with pytest.raises(CaseError) as info:
        load_case_text(yaml.safe_dump(make(lambda r: r["integrator"].__setitem__("dt", -1))), "neg.yaml")
    assert "neg.yaml" in str(info.value) and "integrator.dt" in str(info.value)


@pytest.fixture(autouse=True)
def _quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        yield


def test_explicit_scheme_past_its_stability_limit_is_refused(runner, tmp_path):
    # sdof: omega = sqrt(k/m) = 5 rad/s; central differences (beta = 0) are stable for dt <= 2/5 s
    raw = make(lambda r: r["integrator"].update(beta=0.0, dt=0.5, t_end=5.0))
    simulate_refused(runner, tmp_path, raw, "integrator.dt", "stability limit of newmark with beta = 0",
                     "= 0.4 s", "found 0.5 s", "beta = 1/4")


def test_runaway_growth_at_a_later_design_names_the_stability_limit():
    # within the limit at x0 (0.4 s), past it at k = 200 (omega = 10 rad/s, limit 0.2 s)
    raw = make(lambda r: r["integrator"].update(beta=0.0, dt=0.35, t_end=300.0))
    raw["responses"] = raw["responses"][:1]
    del raw["events"]                    # the crossing event would end the run first
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        case = load_case_text(yaml.safe_dump(raw), "explicit.yaml")
        with pytest.raises(NonFiniteError) as info:
            run_case(case, np.array([2.0, 0.0, 200.0]))
    msg = str(info.value)
    assert "stability limit" in msg and "= 0.2 s" in msg and "found 0.35 s" in msg, msg


# ---------------------------------------------------------------- check-gradients: the partials' step
def test_partials_audit_shows_the_plateau_and_flags_a_variable_without_one(runner, tmp_path):
    from dynsens.derivatives.partials_audit import audit_partials
    # mass = m + 1e12: a relative perturbation of m changes the entry by less than its round-off
    # at every step (no plateau; k's change of the residual drowns in the round-off of M q'' too);
    # c is well scaled and linear: a plateau over most of the sweep
    raw = make(lambda r: r["model"]["elements"][0].__setitem__("mass", "m + 1e12"))
    raw["integrator"]["t_end"] = 0.05
    del raw["events"]
    case = load_case_text(yaml.safe_dump(raw), "audit.yaml")
    a = audit_partials(case)
    assert "m" in a.flagged() and "c" not in a.flagged(), a.errors
    assert a.plateau(1)[0] == 1e-2 and a.plateau(1)[1] <= 1e-10, a.errors
    res = runner.invoke(cli, ["check-gradients", str(write_case(tmp_path, raw)), "--audit-partials",
                              "--workers", "1", "--steps", "1e-6", "-o", str(tmp_path / "rep")])
    assert res.exit_code == 0, res.output
    assert "Partials audit" in res.output and "- m: NO PLATEAU" in res.output
    import json
    assert "m" in json.loads((tmp_path / "rep.json").read_text())["partials_audit"]["flagged"]


def test_a_locking_mechanism_is_not_told_to_reduce_the_time_step():
    # the driver asks the link's COM for y = 0.6 m, out of its reach (0.5 m): the mechanism locks
    import sys
    sys.path.insert(0, str(Path(__file__).parent))
    from test_multibody_singular import CASE as LINK

    from dynsens.errors import ConvergenceError
    case = load_case_text(LINK.replace("AMP", "0.6"), "lock.yaml")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ConvergenceError) as info:
            run_case(case)
    msg = str(info.value)
    assert "the mechanism locks here" in msg and "joints O, lift" in msg, msg
    assert "reduce the time step" not in msg, msg


# ---------------------------------------------------------------- mechanisms: the sensitivities' constraints
@pytest.mark.parametrize("name", ["pendulum_3d", "slider_crank"])
def test_sensitivity_constraint_residual_is_the_derivative_of_the_drift(name):
    """J_Φ ∇q_j + ∂Φ/∂x_j per step equals d/dx_j of Φ(q_k(x), x) along the computed trajectory,
    taken here by complex step of the whole run (the run's discrete drift, differentiated)."""
    from dynsens.models.base import StepState
    sets = ["output.sensitivity_history=true", "output.history=[q,qd,qdd]", "integrator.t_end=0.2",
            "sensitivity.partials=complex"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        case = load_case(CASES / f"{name}.yaml", sets)
        res = run_case(case)
    mon = res.monitors
    assert mon["sensitivity_constraint_position"].shape == res.time.shape
    model, m = case.model, len(case.design)
    h = 1e-30
    pos = np.zeros(res.time.size)
    vel = np.zeros(res.time.size)
    for j in range(m):
        xj = case.x0 + 1j * h * np.eye(m)[j]
        rj = run_case(case, xj, history=("q", "qd", "qdd"))
        pj = model.parameters(xj)
        for k, t in enumerate(rj.time[:res.time.size]):
            z = np.zeros(0)
            s = StepState(rj.history["q"][k], rj.history["qd"][k], rj.history["qdd"][k], z, z, z)
            d = np.imag(model.constraint_levels(t, model.kinematics(s, pj))[0][0]) / h
            pos[k] = max(pos[k], np.linalg.norm(d[:, 0]))
            vel[k] = max(vel[k], np.linalg.norm(d[:, 1]))
    scale = max(pos.max(), 1e-300)
    np.testing.assert_allclose(mon["sensitivity_constraint_position"], pos, rtol=1e-6, atol=1e-9 * scale)
    np.testing.assert_allclose(mon["sensitivity_constraint_velocity"], vel, rtol=1e-6,
                               atol=1e-9 * max(vel.max(), 1e-300))
    # reported by simulate, and small: of the order of the state's own drift
    assert mon["sensitivity_constraint_position"].max() < 1e-3 * max(mon["sensitivity_constraint_scale"].max(), 1)


def test_optimize_plots_not_overwritten(runner, tmp_path):
    plots = tmp_path / "plots"
    plots.mkdir()
    (plots / "opt_history.png").write_bytes(b"old")
    refused(runner, ["optimize", str(CASES / "truss_lightweight.yaml"), "-o", str(tmp_path / "opt.h5"),
                     "--plots", str(plots)], "opt_history.png exists", "--overwrite")
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["opt_history.png", "plots"]


def test_inconsistent_redundant_joints_name_the_case_file(runner, tmp_path):
    # consistent redundant joints are accepted (tests/test_multibody_redundant.py); a loop of
    # revolutes with one axis tilted cannot close and is refused, naming the file and the joints
    raw = yaml.safe_load((CASES / "four_bar.yaml").read_text())
    raw["model"]["joints"][3]["type"] = "revolute"
    raw["model"]["joints"][3]["axis"] = [0, 0.2, 1]
    simulate_refused(runner, tmp_path, raw, "invalid case", "case.yaml", "inconsistent redundant joints")


def test_read_only_output_folder_is_refused_before_the_run(runner, tmp_path, monkeypatch):
    # (the tests may run as root, for whom every folder is writable: the permission is simulated)
    import dynsens.io.paths as paths
    ro = tmp_path / "ro"
    ro.mkdir()
    real_access = paths.os.access
    monkeypatch.setattr(paths.os, "access", lambda p, mode: False if Path(p) == ro else real_access(p, mode))
    case = write_case(tmp_path, make())
    refused(runner, ["simulate", str(case), "-o", str(ro / "r.h5")], "expected a folder you may write",
            "ro read-only for you")
    assert list(ro.iterdir()) == []


def test_infinite_derivative_at_the_design_is_refused(runner, tmp_path):
    # c = 0 at x0 (inside its bounds [0, 5]): sqrt(c) has a finite value but an infinite slope
    raw = make(lambda r: (r["design"]["variables"][1].__setitem__("value", 0.0),
                          r["model"]["elements"][2].__setitem__("c", "sqrt(c)")))
    simulate_refused(runner, tmp_path, raw, "model.elements[2].c", "expected an expression with a finite derivative",
                     "'sqrt(c)' with respect to c is not finite at c = 0", "start design")
    # at a design where it is smooth the same case runs, and the optimizer's step back to c = 0 fails
    raw["design"]["variables"][1]["value"] = 0.64
    case = load_case_text(yaml.safe_dump(raw), "sqrt.yaml")
    assert np.all(np.isfinite(run_case(case).responses["q_end"].gradient))
    with pytest.raises(DesignError, match="finite derivative"):
        run_case(case, np.array([2.0, 0.0, 50.0]))


@pytest.mark.parametrize("value, fragment", [("1" * 400, "number too large"),
                                             ("sin(m, 2)", "sin() takes 1 argument, found 2"),
                                             ("atan2(m)", "atan2() takes 2 arguments, found 1")])
def test_more_expression_errors_at_load(runner, tmp_path, value, fragment):
    raw = make(lambda r: r["model"]["elements"][0].__setitem__("mass", value))
    simulate_refused(runner, tmp_path, raw, "model.elements[0].mass", fragment)
