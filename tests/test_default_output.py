"""``-o`` left out: the commands that always write write to ``results/`` in the working directory.

Contract (CHANGELOG.d/docs36.md): ``simulate`` -> results/<case name>.h5, ``optimize`` ->
results/<case name>_opt.h5, ``study`` -> results/<case name>_study.h5, ``convergence`` ->
results/convergence/; the case name is the case's ``name:`` (its file's stem without one), kept
to letters, digits and ``. _ -``; an existing file is never replaced without --overwrite.
``check-gradients`` and ``modes`` write only when -o is given.
"""
from __future__ import annotations

from pathlib import Path

import h5py
import pytest
import yaml
from click.testing import CliRunner

import dynsens.cli.check_gradients  # noqa: F401  (registers the commands)
import dynsens.cli.convergence  # noqa: F401
import dynsens.cli.optimize  # noqa: F401
import dynsens.cli.simulate  # noqa: F401
import dynsens.cli.study  # noqa: F401
from dynsens.cli.main import cli
from helpers import SDOF_DESIGN

SHORT = ["--set", "integrator.t_end=0.1"]


@pytest.fixture
def work(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A working directory holding the SDOF design case (named sdof_design) as case.yaml."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "case.yaml").write_text(yaml.safe_dump(SDOF_DESIGN, sort_keys=False), encoding="utf-8")
    return tmp_path


def invoke(*args: str):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(cli, list(args))


def test_simulate_writes_results_case_name_and_never_overwrites(work: Path) -> None:
    r = invoke("simulate", "case.yaml", *SHORT)
    assert r.exit_code == 0, r.output
    out = work / "results" / "sdof_design.h5"
    assert "written: results/sdof_design.h5" in r.output
    with h5py.File(out, "r") as f:
        assert f["time"].shape == (11,)
    before = out.read_bytes()
    r = invoke("simulate", "case.yaml", "--set", "integrator.t_end=0.2")
    assert r.exit_code == 2 and "results/sdof_design.h5 exists: pass --overwrite" in r.output
    assert "Traceback" not in r.output and out.read_bytes() == before
    r = invoke("simulate", "case.yaml", "--set", "integrator.t_end=0.2", "--overwrite")
    assert r.exit_code == 0, r.output
    with h5py.File(out, "r") as f:
        assert f["time"].shape == (21,)


def test_without_a_name_the_file_stem_names_the_output_and_a_hostile_name_stays_in_results(work: Path) -> None:
    case = dict(SDOF_DESIGN)
    del case["name"]
    (work / "my model.yaml").write_text(yaml.safe_dump(case, sort_keys=False), encoding="utf-8")
    r = invoke("simulate", "my model.yaml", *SHORT)
    assert r.exit_code == 0, r.output
    assert (work / "results" / "my_model.h5").is_file()
    r = invoke("simulate", "case.yaml", *SHORT, "--set", "name=../../escaped")
    assert r.exit_code == 0, r.output
    assert (work / "results" / "escaped.h5").is_file()
    assert sorted(p.name for p in work.parent.iterdir() if p.suffix == ".h5") == []


@pytest.mark.parametrize("empty", [None, "", "  "], ids=["null", "empty", "blank"])
def test_an_empty_name_falls_back_to_the_file_stem(work: Path, empty: object) -> None:
    # 'name:' left empty wrote results/None.h5 (null) or results/case.h5 (""), not the stem
    case = dict(SDOF_DESIGN, name=empty)
    (work / "mycase.yaml").write_text(yaml.safe_dump(case, sort_keys=False), encoding="utf-8")
    r = invoke("simulate", "mycase.yaml", *SHORT)
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in (work / "results").iterdir()) == ["mycase.h5"]


def test_optimize_writes_results_case_name_opt_and_never_overwrites(work: Path) -> None:
    r = invoke("optimize", "case.yaml", *SHORT, "--maxiter", "2", "--no-verify")
    assert r.exit_code in (0, 1), r.output        # 1: not converged in two iterations
    out = work / "results" / "sdof_design_opt.h5"
    assert f"written: results/{out.name}" in r.output
    with h5py.File(out, "r") as f:
        assert "optimization/start_0" in f
    before = out.read_bytes()
    r = invoke("optimize", "case.yaml", *SHORT, "--maxiter", "2", "--no-verify")
    assert r.exit_code == 2 and f"results/{out.name} exists: pass --overwrite" in r.output
    assert out.read_bytes() == before


def test_study_writes_results_case_name_study_and_never_overwrites(work: Path) -> None:
    r = invoke("study", "case.yaml", *SHORT, "--sample", "grid:2x1", "--workers", "1")
    assert r.exit_code == 0, r.output
    out = work / "results" / "sdof_design_study.h5"
    assert f"written: results/{out.name}" in r.output
    before = out.read_bytes()
    r = invoke("study", "case.yaml", *SHORT, "--sample", "grid:2x1", "--workers", "1")
    assert r.exit_code == 2 and f"results/{out.name} exists: pass --overwrite" in r.output
    assert out.read_bytes() == before


def test_convergence_writes_into_results_convergence_and_never_overwrites(work: Path) -> None:
    args = ("convergence", "case.yaml", *SHORT, "--dt", "0.02,0.01", "--methods", "ddm-forward")
    r = invoke(*args)
    assert r.exit_code == 0, r.output
    written = sorted(p.name for p in (work / "results" / "convergence").iterdir())
    assert written and all(name.startswith("sdof_design") for name in written)
    r = invoke(*args)
    assert r.exit_code == 2 and "--overwrite" in r.output


def test_check_gradients_writes_nothing_without_o(work: Path) -> None:
    r = invoke("check-gradients", "case.yaml", *SHORT, "--steps", "1e-6", "--workers", "1")
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in work.iterdir()) == ["case.yaml"]
