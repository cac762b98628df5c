"""``dynsens study``: a case evaluated at many designs.

Contract: the designs come from scipy.stats.qmc (lhs, sobol), a grid or a CSV file, in the
case's bounds; every row equals a single ``simulate`` run at its design (values and
gradients); rows are on disk as designs finish, so a study killed mid-way resumes without
computing any finished row again; a Dask LocalCluster gives the same rows as local
processes; a design that cannot be simulated is a recorded row with its reason, not an
error of the study; bad input is one clean error.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from scipy.stats import qmc

import dynsens
import dynsens.cli.simulate  # noqa: F401  (registers the command)
import dynsens.cli.study  # noqa: F401  (registers the command)
from dynsens.case.load import load_case
from dynsens.cli.main import cli
from dynsens.io.hdf5 import read_result_dict as read_result
from dynsens.io.paths import OutputLockedError, OutputPathError, lock_path, writer_lock
from dynsens.study import StudyError, read_study, run_study, sample_designs

REPO = Path(__file__).resolve().parents[1]
SDOF = REPO / "cases" / "sdof_step.yaml"
SHORT = ("--set", "integrator.t_end=1")


def invoke(*args) -> object:
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture
def sdof_m0(tmp_path: Path) -> Path:
    """The SDOF case with m allowed down to 0 (m = 0: out of the mass range, a failed design) and t_end = 1 s."""
    raw = yaml.safe_load(SDOF.read_text())
    raw["design"]["variables"][0]["lower"] = 0.0
    raw["integrator"]["t_end"] = 1.0
    p = tmp_path / "sdof_m0.yaml"
    p.write_text(yaml.safe_dump(raw))
    return p


# --------------------------------------------------------------------------------------
# sampling
# --------------------------------------------------------------------------------------
def test_lhs_and_sobol_are_scipy_samples_in_the_bounds() -> None:
    case = load_case(SDOF)
    lo, up = case.lower, case.upper
    x = sample_designs(case, "lhs:7", 5)
    np.testing.assert_array_equal(x, lo + qmc.LatinHypercube(d=3, rng=5).random(7) * (up - lo))
    s = sample_designs(case, "sobol:8", 5)
    np.testing.assert_array_equal(s, lo + qmc.Sobol(d=3, scramble=True, rng=5).random_base2(3) * (up - lo))
    for pts in (x, s):
        assert np.all((pts >= lo) & (pts <= up))
    with pytest.raises(StudyError, match="powers of 2.*found 6 .*e.g. 4 or 8"):
        sample_designs(case, "sobol:6", 1)


def test_grid_and_csv_designs(tmp_path: Path) -> None:
    case = load_case(SDOF)
    g = sample_designs(case, "grid:3x1x2", None)
    assert g.shape == (6, 3)
    assert sorted(set(g[:, 0])) == [0.5, 5.25, 10.0] and set(g[:, 1]) == {0.8} and set(g[:, 2]) == {10.0, 200.0}
    assert sample_designs(case, "grid:2", None).shape == (8, 3)
    csv = tmp_path / "d.csv"
    csv.write_text("k,m\n60,3\n70.5,4\n")
    np.testing.assert_array_equal(sample_designs(case, str(csv), None), [[3, 0.8, 60], [4, 0.8, 70.5]])


@pytest.mark.parametrize("text, needle", [
    ("k,mass\n60,3\n", r"header: unknown design variable\(s\) 'mass'"),
    ("k,m\n60,3\n70,abc\n", r"line 3, column 'm': expected a finite number, found 'abc'"),
    ("k,m\n600,3\n", r"line 2, column 'k': 600 is outside the case's bounds \[10, 200\]"),
    ("k,m\n60\n", r"line 2: expected 2 values, found 1"),
    ("k,m\n", "at least one design"),
], ids=["unknown", "not_a_number", "out_of_bounds", "short_row", "no_rows"])
def test_bad_csv_is_one_clean_error(tmp_path: Path, text: str, needle: str) -> None:
    csv = tmp_path / "d.csv"
    csv.write_text(text)
    r = CliRunner().invoke(cli, ["study", str(SDOF), "-o", str(tmp_path / "s.h5"), "--sample", str(csv)])
    assert r.exit_code == 2 and "Traceback" not in r.output
    assert str(csv) in r.output
    import re
    assert re.search(needle, r.output), r.output
    assert not (tmp_path / "s.h5").exists()


@pytest.mark.parametrize("spec, needle", [("lhs:0", "positive whole number"), ("lhs:x", "positive whole number"),
                                          ("grid:2x2", "expected 3 counts"), ("nope.csv", "expected lhs:N")])
def test_bad_sample_spec(tmp_path: Path, spec: str, needle: str) -> None:
    r = CliRunner().invoke(cli, ["study", str(SDOF), "-o", str(tmp_path / "s.h5"), "--sample", spec])
    assert r.exit_code == 2 and needle in r.output and "Traceback" not in r.output


def test_unbounded_variable_needs_a_csv(tmp_path: Path) -> None:
    raw = yaml.safe_load(SDOF.read_text())
    del raw["design"]["variables"][2]["upper"]
    p = tmp_path / "open.yaml"
    p.write_text(yaml.safe_dump(raw))
    r = CliRunner().invoke(cli, ["study", str(p), "-o", str(tmp_path / "s.h5"), "--sample", "lhs:4"])
    assert r.exit_code == 2 and "unbounded in the case: k" in r.output, r.output


# --------------------------------------------------------------------------------------
# rows
# --------------------------------------------------------------------------------------
def test_rows_equal_single_simulate_runs(tmp_path: Path) -> None:
    out = tmp_path / "s.h5"
    r = invoke("study", SDOF, "-o", out, "--sample", "lhs:4", "--seed", "11", "--gradients", "--workers", "2",
               *SHORT)
    assert r.exit_code == 0, r.output
    t = read_study(out)
    assert t.status == "completed" and list(t.index) == [0, 1, 2, 3] and not t.failed.any()
    assert len(set(t.worker)) >= 1 and all(":" in w for w in t.worker)
    for i in (0, 3):
        one = tmp_path / f"sim{i}.h5"
        sets = [f"design.variables[{j}].value={v!r}" for j, v in enumerate(t.x[i].tolist())]
        r = invoke("simulate", SDOF, "-o", one, *SHORT, *sum((["--set", s] for s in sets), []))
        assert r.exit_code == 0, r.output
        ref = read_result(one)
        np.testing.assert_array_equal(ref["design"]["values"], t.x[i])
        for k, name in enumerate(t.response_names):
            assert t.values[i, k] == pytest.approx(float(ref["responses"][name]["value"]), rel=1e-14, abs=0)
            np.testing.assert_allclose(t.gradients[i, k], ref["responses"][name]["gradient"], rtol=1e-13, atol=0)
    assert t.response_units == {"q_end": "m", "q_ks": "m"}


def test_values_only_study_and_dataframe(tmp_path: Path) -> None:
    pd = pytest.importorskip("pandas", reason="pandas is in the test extra (dynsens[study])")
    out = tmp_path / "s.h5"
    r = invoke("study", SDOF, "-o", out, "--sample", "grid:2x1x2", "--workers", "1", *SHORT)
    assert r.exit_code == 0, r.output
    df = dynsens.read_study(out).to_dataframe()
    assert isinstance(df, pd.DataFrame) and list(df.index) == [0, 1, 2, 3]
    assert {"m", "c", "k", "q_end", "q_ks", "failed", "message"} <= set(df.columns)
    assert not any(c.startswith("d") and "/" in c for c in df.columns)          # no gradients asked
    case = load_case(SDOF, ["integrator.t_end=1"])
    res = dynsens.run_case(case, df.loc[3, ["m", "c", "k"]].to_numpy(float), sensitivities=False)
    assert df.loc[3, "q_ks"] == pytest.approx(float(res.responses["q_ks"].value), rel=1e-14)


def test_failed_design_is_recorded_not_fatal(tmp_path: Path, sdof_m0: Path) -> None:
    csv = tmp_path / "d.csv"
    csv.write_text("m\n2\n0\n3\n")
    out = tmp_path / "s.h5"
    r = invoke("study", sdof_m0, "-o", out, "--sample", csv, "--gradients", "--workers", "1")
    assert r.exit_code == 0, r.output
    # a zero mass is out of the element's range: refused before its run, recorded with the reason
    assert "design 1: m=0, c=0.8, k=50: FAILED: DesignError" in r.output
    assert "3 designs (" in r.output and "1 failed" in r.output
    # the user's umask decides the permissions, as for every result file (each row rewrote it 0600)
    from dynsens.io.paths import current_umask
    assert out.stat().st_mode & 0o777 == 0o666 & ~current_umask()
    t = dynsens.read_study(out)          # the public entry point (dynsens/__init__.py)
    assert t.failed.tolist() == [False, True, False]
    assert "DesignError" in t.message[1] and t.message[0] == "" and t.message[2] == ""
    assert np.isnan(t.values[1]).all() and np.isnan(t.gradients[1]).all()
    assert np.isfinite(t.values[[0, 2]]).all() and np.isfinite(t.gradients[[0, 2]]).all()
    with h5py.File(out) as f:
        assert f.attrs["status"] == "completed" and "1 failed" in f.attrs["message"]


def test_missing_response_is_noted(tmp_path: Path) -> None:
    raw = yaml.safe_load(SDOF.read_text())
    raw["integrator"]["t_end"] = 0.5
    raw["events"] = [{"name": "far", "quantity": {"dof": "u", "kind": "displacement"}, "value": 0.3,
                      "direction": "rising"}]
    raw["responses"].append({"name": "t_far", "type": "event_time", "event": "far", "unit": "s"})
    case = dynsens.load_case_dict(raw, "far.yaml")
    # a stiff spring never lets u reach 0.3 m: t_far is missing, the other responses are there
    t = run_study(case, tmp_path / "s.h5", "grid:1x1x2", workers=1)
    k_soft, k_stiff = t.x[:, 2]
    assert (k_soft, k_stiff) == (10.0, 200.0)
    assert not t.failed.any()
    assert np.isnan(t.values[1, 2]) and "t_far missing" in t.message[1]
    assert np.isfinite(t.values[1, :2]).all()


# --------------------------------------------------------------------------------------
# interruption and resume
# --------------------------------------------------------------------------------------
def test_killed_study_resumes_without_recomputing_a_row(tmp_path: Path) -> None:
    out = tmp_path / "s.h5"
    args = ["study", str(SDOF), "-o", str(out), "--sample", "lhs:8", "--seed", "4", "--gradients",
            "--workers", "1", "--set", "integrator.t_end=4"]
    code = "import sys; from dynsens.cli.main import main; sys.argv = ['dynsens'] + sys.argv[1:]; main()"
    proc = subprocess.Popen([sys.executable, "-c", code, *args], stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    printed = []
    assert proc.stdout is not None
    for line in proc.stdout:                       # kill -9 once two rows are on disk
        if line.startswith("["):
            printed.append(int(line.split("design ")[1].split(":")[0]))
        if len(printed) == 2:
            proc.send_signal(signal.SIGKILL)
            break
    proc.wait(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    before = read_study(out)
    assert before.status == "running"             # nobody marked it finished
    done = set(before.index.tolist())
    assert set(printed) <= done and len(done) < 8
    r = invoke("study", SDOF, "-o", out, "--gradients", "--resume", "--workers", "1", "--set", "integrator.t_end=4")
    assert r.exit_code == 0, r.output
    resumed = [int(line.split("design ")[1].split(":")[0]) for line in r.output.splitlines() if line.startswith("[")]
    assert sorted(resumed) == sorted(set(range(8)) - done)       # only the missing ones, each once
    t = read_study(out)
    assert t.status == "completed" and t.index.tolist() == list(range(8))
    assert set(t.index[t.run == 0]) == done and set(t.index[t.run == 1]) == set(resumed)
    # the resumed rows equal an uninterrupted study
    ref = run_study(load_case(SDOF, ["integrator.t_end=4"]), tmp_path / "ref.h5", "lhs:8", seed=4, gradients=True,
                    workers=1)
    np.testing.assert_array_equal(t.x, ref.x)
    np.testing.assert_array_equal(t.values, ref.values)
    np.testing.assert_array_equal(t.gradients, ref.gradients)


def test_the_file_on_disk_is_always_complete(tmp_path: Path, monkeypatch) -> None:
    # a failure in the middle of writing a row (as a kill would leave it) leaves the file as
    # it was before that row: every change is made to a copy that then replaces the file
    import dynsens.study.store as store
    out = tmp_path / "s.h5"
    case = load_case(SDOF, ["integrator.t_end=1"])
    run_study(case, out, "lhs:3", seed=1, workers=1)
    # index and x of a 4th row are written, then the third dataset cannot be
    with pytest.raises(TypeError):
        store.append_row(out, {"index": 9, "x": np.zeros(3), "unwritable": object()})
    t = read_study(out)
    assert t.index.tolist() == [0, 1, 2] and t.status == "completed"
    assert [p.name for p in tmp_path.iterdir()] == ["s.h5"]          # no temporary file left


def test_resume_checks_the_case_and_options(tmp_path: Path) -> None:
    out = tmp_path / "s.h5"
    case = load_case(SDOF, ["integrator.t_end=1"])
    run_study(case, out, "lhs:2", seed=1, workers=1)
    with pytest.raises(StudyError, match="different case"):
        run_study(load_case(SDOF), out, resume=True)
    with pytest.raises(StudyError, match="without --gradients"):
        run_study(case, out, resume=True, gradients=True)
    with pytest.raises(StudyError, match="--sample lhs:2; found --sample lhs:3"):
        run_study(case, out, "lhs:3", resume=True)
    with pytest.raises(StudyError, match="give one of them"):
        run_study(case, out, resume=True, overwrite=True)
    r = CliRunner().invoke(cli, ["study", str(SDOF), "-o", str(out), "--sample", "lhs:2", *SHORT])
    assert r.exit_code == 2 and "--overwrite" in r.output
    t = run_study(case, out, resume=True)                      # nothing left to do
    assert t.index.tolist() == [0, 1] and t.run.tolist() == [0, 0]


# --------------------------------------------------------------------------------------
# one writer per study file; output names the file system cannot hold
# --------------------------------------------------------------------------------------
def _refused(r, *fragments: str) -> None:
    assert r.exit_code == 2 and "Traceback" not in r.output and r.output.count("Error:") == 1, r.output
    for frag in fragments:
        assert frag in r.output, (frag, r.output)


def test_second_study_writer_is_refused(tmp_path: Path) -> None:
    # two studies writing one file interleaved their rows (35 rows for 20 designs), and a
    # --resume beside a running study appended duplicates: the second is refused at once
    out = tmp_path / "s.h5"
    run_study(load_case(SDOF, ["integrator.t_end=1"]), out, "lhs:2", seed=1, workers=1)
    before = out.read_bytes()
    fresh = tmp_path / "new.h5"
    with writer_lock(out), writer_lock(fresh):          # as a running study holds it
        for extra in (["--sample", "lhs:3", "--overwrite"], ["--resume"], ["--sample", "lhs:2", "--resume"]):
            r = CliRunner().invoke(cli, ["study", str(SDOF), "-o", str(out), "--workers", "1", *extra, *SHORT])
            _refused(r, "s.h5 is being written by another dynsens process", "another -o file")
            assert out.read_bytes() == before
        r = CliRunner().invoke(cli, ["study", str(SDOF), "-o", str(fresh), "--sample", "lhs:2", *SHORT])
        _refused(r, "new.h5 is being written by another dynsens process")
        assert not fresh.exists()
        with pytest.raises(OutputLockedError):
            run_study(load_case(SDOF), out, resume=True)
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.h5"]      # the locks released and removed
    assert not lock_path(out).exists()
    t = run_study(load_case(SDOF, ["integrator.t_end=1"]), out, "lhs:3", seed=1, workers=1, overwrite=True)
    assert t.index.tolist() == [0, 1, 2]                                  # free again once released


def test_a_running_study_refuses_a_resume_of_its_file(tmp_path: Path) -> None:
    # the race as it happens: a study in another process is still writing when --resume starts
    out = tmp_path / "s.h5"
    args = ["study", str(SDOF), "-o", str(out), "--sample", "lhs:6", "--seed", "4", "--workers", "1",
            "--set", "integrator.t_end=4"]
    code = "import sys; from dynsens.cli.main import main; sys.argv = ['dynsens'] + sys.argv[1:]; main()"
    proc = subprocess.Popen([sys.executable, "-c", code, *args], stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    assert proc.stdout is not None
    try:
        for line in proc.stdout:                   # the first row is on disk: the study is running
            if line.startswith("["):
                break
        r = CliRunner().invoke(cli, ["study", str(SDOF), "-o", str(out), "--resume", "--workers", "1",
                                     "--set", "integrator.t_end=4"])
        _refused(r, "s.h5 is being written by another dynsens process")
        r = CliRunner().invoke(cli, [*args, "--overwrite"])
        _refused(r, "s.h5 is being written by another dynsens process")
    finally:
        proc.stdout.read()
        proc.wait(timeout=120)
    assert proc.returncode == 0
    t = read_study(out)
    assert t.status == "completed" and sorted(t.index.tolist()) == list(range(6))     # each design once


@pytest.mark.parametrize("extra", [None, -3])
def test_too_long_output_name_is_a_clean_error(tmp_path: Path, extra: int | None) -> None:
    # a lookup of a name past NAME_MAX failed with "OSError: File name too long" and a traceback;
    # NAME_MAX - 3 bytes fits, its lock file ".NAME.lock" (and the temporary file) do not
    name_max = os.pathconf(tmp_path, "PC_NAME_MAX")
    name = "a" * 297 + ".h5" if extra is None else "a" * (name_max + extra - 3) + ".h5"
    out = tmp_path / "d" / name
    r = CliRunner().invoke(cli, ["study", str(SDOF), "-o", str(out), "--sample", "lhs:2", *SHORT])
    _refused(r, "-o/--output: expected", f"at most {name_max} bytes")
    assert not (tmp_path / "d").exists()
    with pytest.raises(OutputPathError, match=f"at most {name_max} bytes"):
        run_study(load_case(SDOF), out, "lhs:2")
    assert list(tmp_path.iterdir()) == []


def test_lock_file_name_past_the_limit_is_a_clean_error(tmp_path: Path) -> None:
    name_max = os.pathconf(tmp_path, "PC_NAME_MAX")
    out = tmp_path / ("a" * (name_max - 3))
    with pytest.raises(OutputPathError, match=f"at most {name_max - 6} bytes .*its lock file adds 6"):
        with writer_lock(out):
            pass
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------------------
# Dask
# --------------------------------------------------------------------------------------
def test_dask_local_cluster_equals_local_processes(tmp_path: Path) -> None:
    pytest.importorskip("distributed", reason="dask.distributed is in the test extra")
    from distributed import LocalCluster
    case = load_case(SDOF, ["integrator.t_end=1"])
    local = run_study(case, tmp_path / "local.h5", "lhs:5", seed=2, gradients=True, workers=2)
    # worker threads in this process (processes=False) for speed; the executor runs one
    # simulation at a time per process
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0") as cluster:
        r = invoke("study", SDOF, "-o", tmp_path / "dask.h5", "--sample", "lhs:5", "--seed", "2", "--gradients",
                   "--scheduler", cluster.scheduler_address, *SHORT)
    assert r.exit_code == 0, r.output
    remote = read_study(tmp_path / "dask.h5")
    assert remote.index.tolist() == local.index.tolist() == list(range(5))
    np.testing.assert_array_equal(remote.x, local.x)
    np.testing.assert_array_equal(remote.values, local.values)
    np.testing.assert_array_equal(remote.gradients, local.gradients)
    assert set(remote.worker) != set(local.worker)


def test_plots(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    out = tmp_path / "s.h5"
    r = invoke("study", SDOF, "-o", out, "--sample", "lhs:6", "--seed", "3", "--gradients", "--workers", "1",
               "--plots", tmp_path / "plots", *SHORT)
    assert r.exit_code == 0, r.output
    for name in ("study_responses.png", "study_sensitivity.png", "study_pairs.png"):
        assert (tmp_path / "plots" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the stiffness dominates the displacement of the SDOF oscillator under a step load
    assert "sensitivity (gradient shares" in r.output
    line = next(ln for ln in r.output.splitlines() if ln.startswith("q_ks"))
    assert line.split()[3].endswith("*")
