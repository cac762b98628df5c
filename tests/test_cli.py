"""The command line: ``dynsens simulate`` and ``dynsens check-gradients``.

Contract: simulate writes an HDF5 file (root attributes dynsens_version, created, case,
status; /time; /state/q|qd|qdd; /sensitivity/... with output.sensitivity_history;
/design/names|values; /responses/<name>/value|gradient; /stats attributes) atomically
and never overwrites without --overwrite.  check-gradients prints a Table-1 layout,
writes REPORT.md and REPORT.json and exits 1 when --rtol is given and not met.  Bad
input gives one clean "Error:" message, a non-zero exit, no traceback and no file.
"""
from __future__ import annotations

import datetime as dt
import json
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import dynsens
import dynsens.cli.check_gradients  # noqa: F401  (registers the command)
import dynsens.cli.simulate  # noqa: F401  (registers the command)
from dynsens.cli.main import cli, main  # noqa: F401
from conftest import CASES
from helpers import SDOF_RUN
from dynsens.errors import ModelError

REPO = Path(__file__).resolve().parents[1]
SDOF = REPO / "cases" / "sdof_step.yaml"

CASE = SDOF_RUN
N_STEPS = 250  # t_end / dt


@pytest.fixture
def runner() -> CliRunner:
    return CliRunner()


def write_case(folder: Path, raw: dict | None = None, name: str = "case.yaml") -> Path:
    p = folder / name
    p.write_text(yaml.safe_dump(raw if raw is not None else CASE, sort_keys=False), encoding="utf-8")
    return p


@pytest.fixture
def case_file(tmp_path: Path) -> Path:
    return write_case(tmp_path)


def invoke(runner: CliRunner, *args: str):
    return runner.invoke(cli, [str(a) for a in args])


def assert_ok(result) -> None:
    assert result.exit_code == 0, f"exit {result.exit_code}\n{result.output}\n{result.exception!r}"


def assert_clean_failure(result, *fragments: str, code: int | None = None) -> str:
    """Non-zero exit, one 'Error:' message on stderr, no Python traceback."""
    assert result.exit_code != 0, result.output
    if code is not None:
        assert result.exit_code == code, result.output
    # only SystemExit may escape the command: anything else is a bug with a traceback
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    err = result.stderr
    assert "Traceback" not in result.output
    assert err.lstrip().startswith("Error:"), err
    for f in fragments:
        assert f in err, f"{f!r} not in:\n{err}"
    return err


def leftovers(folder: Path) -> list[str]:
    """Files in ``folder`` other than case files (outputs, temporary files)."""
    if not folder.exists():
        return []
    return sorted(p.name for p in folder.iterdir() if p.suffix != ".yaml")


# =============================================================================== simulate
def test_simulate_hdf5_layout(runner, case_file, tmp_path):
    out = tmp_path / "res" / "sdof.h5"
    result = invoke(runner, "simulate", case_file, "-o", out, "--set", "output.sensitivity_history=true")
    assert_ok(result)
    assert f"written: {out}" in result.stdout
    assert "q_end" in result.stdout and "q_ks" in result.stdout
    assert leftovers(out.parent) == ["sdof.h5"]  # no temporary file left next to it
    n, m, N = 1, 3, N_STEPS + 1
    with h5py.File(out, "r") as f:
        # root attributes
        assert f.attrs["dynsens_version"] == dynsens.__version__
        created = dt.datetime.fromisoformat(str(f.attrs["created"]))
        assert abs((dt.datetime.now(dt.timezone.utc) - created).total_seconds()) < 600
        case_text = f.attrs["case"]
        assert isinstance(case_text, str)
        stored = yaml.safe_load(case_text)
        assert stored["name"] == "sdof_cli"
        assert stored["output"]["sensitivity_history"] is True  # the override is recorded
        assert f.attrs["status"] == "completed"
        # time and state histories
        t = f["time"][()]
        assert t.shape == (N,)
        assert t[0] == 0.0 and t[-1] == pytest.approx(0.5)
        assert np.all(np.diff(t) > 0)
        for k in ("q", "qd", "qdd"):
            assert f[f"state/{k}"].shape == (N, n)
        # sensitivity histories
        for k in ("q", "qd", "qdd"):
            assert f[f"sensitivity/{k}"].shape == (N, n, m)
        # design
        names = [v.decode() if isinstance(v, bytes) else v for v in f["design/names"][()]]
        assert names == ["m", "c", "k"]
        np.testing.assert_allclose(f["design/values"][()], [2.0, 0.8, 50.0])
        # responses
        for r in ("q_end", "q_ks"):
            assert f[f"responses/{r}/value"].shape == ()
            assert f[f"responses/{r}/gradient"].shape == (m,)
        # the end value and its gradient are the last state and sensitivity rows
        q = f["state/q"][()]
        assert f["responses/q_end/value"][()] == pytest.approx(q[-1, 0], rel=1e-12)
        np.testing.assert_allclose(f["responses/q_end/gradient"][()], f["sensitivity/q"][-1, 0, :], rtol=1e-10)
        # static check of the physics: q -> F/k = 0.2 m, first overshoot below 2 F/k
        assert 0.0 < q[-1, 0] < 0.4
        # statistics
        st = f["stats"].attrs
        for key in ("steps", "newton_iterations", "factorizations", "residual_evaluations", "wall_time_s"):
            assert key in st, key
        assert st["steps"] == N_STEPS
        assert st["newton_iterations"] >= N_STEPS
        assert st["factorizations"] >= 1
        assert st["residual_evaluations"] >= N_STEPS
        assert st["wall_time_s"] > 0
        assert st["sensitivity_residual_evaluations"] > 0


def test_simulate_repository_case_with_short_t_end(runner, tmp_path):
    out = tmp_path / "sdof_step.h5"
    result = invoke(runner, "simulate", SDOF, "-o", out, "--set", "integrator.t_end=0.5")
    assert_ok(result)
    with h5py.File(out, "r") as f:
        assert f["time"][-1] == pytest.approx(0.5)
        assert f["time"].shape == (501,)
        assert "sensitivity" not in f  # no sensitivity histories unless asked for
        assert f["responses/q_end/gradient"].shape == (3,)
        assert yaml.safe_load(f.attrs["case"])["integrator"]["t_end"] == pytest.approx(0.5)


def test_simulate_without_history(runner, case_file, tmp_path):
    out = tmp_path / "nohist.h5"
    assert_ok(invoke(runner, "simulate", case_file, "-o", out, "--set", "output.history=none"))
    with h5py.File(out, "r") as f:
        assert "state" not in f
        assert f["time"].shape == (N_STEPS + 1,)
        assert "value" in f["responses/q_end"]


def test_simulate_partial_history(runner, case_file, tmp_path):
    out = tmp_path / "q_only.h5"
    assert_ok(invoke(runner, "simulate", case_file, "-o", out, "--set", "output.history=[q]"))
    with h5py.File(out, "r") as f:
        assert sorted(f["state"]) == ["q"]


def test_no_clobber(runner, case_file, tmp_path):
    out = tmp_path / "exists.h5"
    out.write_bytes(b"precious")
    result = invoke(runner, "simulate", case_file, "-o", out)
    assert_clean_failure(result, "exists", "--overwrite")
    assert out.read_bytes() == b"precious"
    assert leftovers(tmp_path) == ["exists.h5"]


def test_overwrite_replaces(runner, case_file, tmp_path):
    out = tmp_path / "exists.h5"
    out.write_bytes(b"old junk")
    assert_ok(invoke(runner, "simulate", case_file, "-o", out, "--overwrite"))
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "completed"
    assert leftovers(tmp_path) == ["exists.h5"]


def test_failed_overwrite_keeps_the_old_file(runner, case_file, tmp_path):
    out = tmp_path / "exists.h5"
    out.write_bytes(b"precious")
    result = invoke(runner, "simulate", case_file, "-o", out, "--overwrite", "--set", "integrator.dt=-1")
    assert_clean_failure(result, "integrator.dt")
    assert out.read_bytes() == b"precious"
    assert leftovers(tmp_path) == ["exists.h5"]


# ---------------------------------------------------------------------------- --set
def test_set_overrides(runner, case_file, tmp_path):
    out = tmp_path / "set.h5"
    result = invoke(runner, "simulate", case_file, "-o", out, "--set", "integrator.t_end=0.25",
                    "--set", "design.variables[0].value=3", "--set", "integrator.dt=5e-3")
    assert_ok(result)
    with h5py.File(out, "r") as f:
        assert f["time"].shape == (51,)
        assert f["time"][-1] == pytest.approx(0.25)
        np.testing.assert_allclose(f["design/values"][()], [3.0, 0.8, 50.0])
        stored = yaml.safe_load(f.attrs["case"])
        assert stored["design"]["variables"][0]["value"] == 3
        assert stored["integrator"]["t_end"] == pytest.approx(0.25)


@pytest.mark.parametrize("override, fragments", [
    ("design.variables[9].value=1", ("--set design.variables[9].value", "does not exist")),
    ("integrator.tend=1", ("integrator.tend", "did you mean 't_end'")),
    ("integrator", ("--set integrator", "KEY=VALUE")),
    ("integrator.dt=fast", ("integrator.dt", "fast")),
], ids=["bad_index", "unknown_key", "no_equals", "bad_value"])
def test_set_invalid(runner, case_file, tmp_path, override, fragments):
    out = tmp_path / "out" / "set.h5"
    result = invoke(runner, "simulate", case_file, "-o", out, "--set", override)
    assert_clean_failure(result, *fragments)
    assert not out.exists()
    assert leftovers(out.parent) == []


# ---------------------------------------------------------------------------- --no-sensitivities
def test_no_sensitivities(runner, case_file, tmp_path):
    with_s, without = tmp_path / "with.h5", tmp_path / "without.h5"
    assert_ok(invoke(runner, "simulate", case_file, "-o", with_s))
    result = invoke(runner, "simulate", case_file, "-o", without, "--no-sensitivities",
                    "--set", "output.sensitivity_history=true")
    assert_ok(result)
    with h5py.File(with_s, "r") as a, h5py.File(without, "r") as b:
        assert a["stats"].attrs["sensitivity_residual_evaluations"] > 0
        assert b["stats"].attrs["sensitivity_residual_evaluations"] == 0
        # no sensitivity work at all: one solve column per Newton iteration
        assert b["stats"].attrs["solve_columns"] < a["stats"].attrs["solve_columns"]
        assert "sensitivity" not in b
        for r in ("q_end", "q_ks"):
            assert "gradient" not in b[f"responses/{r}"]
            assert b[f"responses/{r}/value"][()] == pytest.approx(a[f"responses/{r}/value"][()], rel=1e-12)
        np.testing.assert_array_equal(a["state/q"][()], b["state/q"][()])


# ---------------------------------------------------------------------------- failures
def test_bad_case_one_clean_error_and_no_output(runner, tmp_path):
    raw = yaml.safe_load(yaml.safe_dump(CASE))
    raw["integrator"]["tend"] = 1.0                               # unknown key
    raw["model"]["elements"][0]["mass"] = "mm"                     # unknown symbol
    raw["responses"][0]["quantity"]["dof"] = "uu"                  # missing DOF
    raw["responses"][1]["rho"] = -1.0                              # out of range
    case = write_case(tmp_path, raw, "bad.yaml")
    out = tmp_path / "out" / "bad.h5"
    result = invoke(runner, "simulate", case, "-o", out)
    err = assert_clean_failure(result, "bad.yaml", "integrator.tend", "did you mean 't_end'",
                               "model.elements[0].mass", "did you mean 'm'",
                               "responses[0].quantity.dof", "did you mean 'u'", "responses[1].rho")
    assert err.count("Error:") == 1
    assert "(4 problems)" in err
    assert result.stdout == ""
    assert not out.exists() and leftovers(out.parent) == []


def test_missing_case_file(runner, tmp_path):
    out = tmp_path / "x.h5"
    result = invoke(runner, "simulate", tmp_path / "nope.yaml", "-o", out)
    assert_clean_failure(result, "file not found", "nope.yaml")
    assert leftovers(tmp_path) == []


def test_invalid_yaml_file(runner, tmp_path):
    p = tmp_path / "broken.yaml"
    p.write_text("model: {type: structural\nintegrator: [\n", encoding="utf-8")
    result = invoke(runner, "simulate", p, "-o", tmp_path / "x.h5")
    assert_clean_failure(result, "not valid YAML", "line")
    assert leftovers(tmp_path) == []


def test_nan_stops_the_run_cleanly(runner, tmp_path):
    raw = yaml.safe_load(yaml.safe_dump(CASE))
    raw["design"]["variables"][2].update(value=-1e6, lower=-1e7)   # negative stiffness: blows up
    raw["integrator"].update(dt=1e-3, t_end=1.0)
    case = write_case(tmp_path, raw, "blowup.yaml")
    out = tmp_path / "blowup.h5"
    result = invoke(runner, "simulate", case, "-o", out)
    err = assert_clean_failure(result, "NaN")
    assert "t = " in err and "step" in err
    assert leftovers(tmp_path) == []


def test_write_failure_leaves_no_file_and_no_temp_file(runner, case_file, tmp_path, monkeypatch):
    import dynsens.io.hdf5 as hdf5

    def broken(*args, **kwargs):
        raise ModelError("simulated failure while writing")
    monkeypatch.setattr(hdf5, "write_responses", broken)
    out = tmp_path / "out" / "res.h5"
    result = invoke(runner, "simulate", case_file, "-o", out)
    assert_clean_failure(result, "simulated failure while writing")
    assert not out.exists()
    assert leftovers(out.parent) == []


def test_console_entry_point_has_no_traceback(tmp_path):
    out = tmp_path / "x.h5"
    proc = subprocess.run(
        [sys.executable, "-c", "from dynsens.cli.main import main; main()", "simulate",
         str(tmp_path / "missing.yaml"), "-o", str(out)],
        capture_output=True, text=True, timeout=60)
    assert proc.returncode != 0
    assert proc.stderr.startswith("Error:"), proc.stderr
    assert "file not found" in proc.stderr
    assert "Traceback" not in proc.stderr + proc.stdout
    assert not out.exists()


def test_python_dash_m_dynsens_is_the_command(runner):
    """``python -m dynsens`` (dynsens/__main__.py) is the ``dynsens`` command: the same entry point
    in process, and in a fresh interpreter the same help text as the click group."""
    import dynsens.__main__ as entry
    assert entry.main is main
    proc = subprocess.run([sys.executable, "-m", "dynsens", "--help"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    for command in ("simulate", "check-gradients", "optimize", "verify"):
        assert command in proc.stdout


# =============================================================================== check-gradients
def run_check(runner, case_file, *args):
    return invoke(runner, "check-gradients", case_file, "--workers", "1", *args)


def test_check_gradients_table_and_report_files(runner, case_file, tmp_path):
    report = tmp_path / "reports" / "grad"
    result = run_check(runner, case_file, "--steps", "1e-3,1e-4,1e-5,1e-6", "-o", report)
    assert_ok(result)
    out = result.stdout
    # Table 1 layout: a semi-analytical column and one column per step, wall times and
    # relative differences for every response
    header = next(line for line in out.splitlines() if "semi-analytical" in line)
    for h in ("0.001", "0.0001", "1e-05", "1e-06"):
        assert f"forward h = {h}" in header
    assert "| wall time [s] |" in out
    for r in ("q_end", "q_ks"):
        assert f"| ∇{r} |" in out
        assert f"| rel. diff. ∇{r} |" in out
    md, js = report.with_suffix(".md"), report.with_suffix(".json")
    assert md.exists() and js.exists()
    assert "semi-analytical" in md.read_text(encoding="utf-8")
    data = json.loads(js.read_text(encoding="utf-8"))
    assert data["design_names"] == ["m", "c", "k"]
    assert [c["step"] for c in data["columns"]] == [1e-3, 1e-4, 1e-5, 1e-6]
    assert data["semi_analytical_wall_time_s"] > 0
    for col in data["columns"]:
        assert col["scheme"] == "forward"
        assert col["wall_time_s"] > 0
        for r in ("q_end", "q_ks"):
            sa = np.array(data["semi_analytical"][r])
            fd = np.array(col["gradients"][r])
            assert sa.shape == fd.shape == (3,)
            # the reported relative difference is ||fd - sa|| / ||sa||
            assert col["rel_diff"][r] == pytest.approx(np.linalg.norm(fd - sa) / np.linalg.norm(sa), rel=1e-9)
    # forward differences converge towards the semi-analytical gradient as h shrinks
    diffs = [c["rel_diff"]["q_end"] for c in data["columns"]]
    assert diffs[-1] < diffs[0] < 1e-2


def test_check_gradients_agrees_with_simulate(runner, case_file, tmp_path):
    h5 = tmp_path / "sim.h5"
    assert_ok(invoke(runner, "simulate", case_file, "-o", h5))
    report = tmp_path / "grad"
    assert_ok(run_check(runner, case_file, "--steps", "1e-6", "-o", report))
    data = json.loads(report.with_suffix(".json").read_text(encoding="utf-8"))
    with h5py.File(h5, "r") as f:
        for r in ("q_end", "q_ks"):
            np.testing.assert_allclose(data["semi_analytical"][r], f[f"responses/{r}/gradient"][()], rtol=1e-10)
            assert data["values"][r] == pytest.approx(f[f"responses/{r}/value"][()], rel=1e-12)


def test_check_gradients_md_suffix_writes_both_files(runner, case_file, tmp_path):
    assert_ok(run_check(runner, case_file, "--steps", "1e-6", "-o", tmp_path / "rep.md"))
    assert (tmp_path / "rep.md").exists() and (tmp_path / "rep.json").exists()


def test_check_gradients_tight_rtol_fails_with_exit_1(runner, case_file, tmp_path):
    report = tmp_path / "tight"
    result = run_check(runner, case_file, "--scheme", "forward", "--steps", "1e-3,1e-6",
                       "--rtol", "1e-12", "-o", report)
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    assert "FAILED" in result.stderr and "1e-12" in result.stderr
    # the report is still written, so the failure can be inspected
    assert report.with_suffix(".md").exists() and report.with_suffix(".json").exists()


def test_check_gradients_loose_rtol_passes(runner, case_file):
    result = run_check(runner, case_file, "--steps", "1e-3,1e-6", "--rtol", "1e-3")
    assert_ok(result)
    assert "FAILED" not in result.output


def test_check_gradients_without_rtol_never_fails(runner, case_file):
    # h = 0.1 is far too large, but without --rtol the command only reports
    assert_ok(run_check(runner, case_file, "--steps", "0.1"))


@pytest.mark.parametrize("scheme, steps, rtol", [("central", "1e-5", "1e-6"), ("complex", "1e-20", "1e-6")])
def test_check_gradients_accurate_schemes(runner, case_file, scheme, steps, rtol):
    result = run_check(runner, case_file, "--scheme", scheme, "--steps", steps, "--rtol", rtol)
    assert_ok(result)
    assert f"{scheme} h = {float(steps):g}" in result.stdout


def test_check_gradients_default_workers(runner, case_file):
    # the default spreads the finite-difference runs over worker processes
    result = invoke(runner, "check-gradients", case_file, "--steps", "1e-4,1e-6", "--rtol", "1e-3")
    assert_ok(result)


@pytest.mark.parametrize("args", [("--steps", "a,b"), ("--steps", "-1e-3"), ("--scheme", "backward")],
                         ids=["steps_text", "steps_negative", "scheme"])
def test_check_gradients_bad_options(runner, case_file, args):
    result = run_check(runner, case_file, *args)
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert "Error:" in result.stderr


@pytest.mark.parametrize("args, fragment", [
    (("--rtol", "nan"), "Invalid value for '--rtol': expected a finite number > 0, found 'nan'"),
    (("--rtol", "-1e-3"), "Invalid value for '--rtol': expected a finite number > 0, found '-1e-3'"),
    (("--rtol", "inf"), "found 'inf'"),
    (("--steps", "1e-300"), "Invalid value for '--steps': expected relative steps in [1e-15, 1) for the "
                            "forward scheme, found 1e-300"),
    (("--steps", "1e-300", "--scheme", "complex"), "in [1e-100, 1) for the complex scheme, found 1e-300"),
    (("--steps", "2"), "in [1e-15, 1) for the forward scheme, found 2.0"),
    (("--steps", "1e-6,,1e-4"), "Invalid value for '--steps': expected comma-separated positive finite "
                                "numbers, found an empty entry in '1e-6,,1e-4'"),
    (("--steps", "1e-4,nan"), "found 'nan' in '1e-4,nan'"),
], ids=["rtol_nan", "rtol_negative", "rtol_inf", "steps_underflow", "steps_complex_underflow", "steps_large",
        "steps_empty_entry", "steps_nan"])
def test_check_gradients_meaningless_numbers_are_usage_errors(runner, case_file, args, fragment):
    """These were accepted: nan or a negative rtol made every check fail, 1e-300 gave a column of
    round-off, an empty entry was skipped silently."""
    result = run_check(runner, case_file, *args)
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and fragment in result.stderr, result.stderr


@pytest.mark.parametrize("args, fragment", [
    (("optimize", "--ftol", "nan"), "Invalid value for '--ftol': expected a finite number > 0, found 'nan'"),
    (("optimize", "--ftol", "inf"), "'--ftol': expected a finite number > 0, found 'inf'"),
    (("optimize", "-x", "m=nan"), "'-x' / '--x0': expected NAME=VALUE with a finite number VALUE, found 'm=nan'"),
    (("optimize", "--seed", "-1"), "'--seed': -1 is not in the range 0<=x<=9223372036854775807"),
    (("study", "--seed", "-1"), "'--seed': -1 is not in the range"),
    (("convergence", "--dt", "nan"), "'--dt': expected comma-separated positive finite numbers, found 'nan'"),
], ids=["ftol_nan", "ftol_inf", "x0_nan", "optimize_seed", "study_seed", "convergence_dt"])
def test_other_numeric_options_refuse_meaningless_values(runner, case_file, tmp_path, args, fragment):
    """--ftol nan/inf ran SLSQP with it, --seed -1 ended in a numpy traceback, --dt nan was
    reported as a problem of the case's integrator.dt."""
    import dynsens.cli.convergence, dynsens.cli.optimize, dynsens.cli.study  # noqa: F401,E401
    result = invoke(runner, args[0], case_file, "-o", tmp_path / "out", *args[1:])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and fragment in result.stderr, result.stderr
    assert leftovers(tmp_path) == []


def test_check_gradients_bad_case_is_clean(runner, tmp_path):
    raw = yaml.safe_load(yaml.safe_dump(CASE))
    raw["responses"][0]["quantity"]["dof"] = "uu"
    case = write_case(tmp_path, raw, "bad.yaml")
    report = tmp_path / "rep"
    result = run_check(runner, case, "-o", report, "--rtol", "1e-3")
    assert_clean_failure(result, "responses[0].quantity.dof", "did you mean 'u'")
    assert result.exit_code != 1  # an invalid case is not a failed gradient check
    assert leftovers(tmp_path) == []


def test_unknown_kernel_in_the_environment_is_a_clean_error(runner, tmp_path, monkeypatch):
    """DYNSENS_KERNEL with a typo stops with a message naming the variable and its choices,
    instead of silently taking the compiled kernel."""
    monkeypatch.setenv("DYNSENS_KERNEL", "nmpy")
    out = tmp_path / "pendulum.h5"
    res = invoke(runner, "simulate", CASES / "pendulum_3d.yaml", "-o", out, "--set", "integrator.t_end=0.01")
    assert_clean_failure(res, "DYNSENS_KERNEL", "'nmpy'", "compiled, numpy", code=2)
    assert not out.exists() and leftovers(tmp_path) == []
