"""``dynsens examples DIR``: the shipped example cases, copied into a folder of the user's.

Contract: every file of the repository's cases/ (the case files and what they use, e.g.
records/) is copied byte for byte, and every copied case loads; an existing file is never
replaced without --overwrite (nothing is written then); a DIR that is a file is refused with one
error and exit status 2.  The cases ship in the wheel (setup.py copies cases/ into
dynsens/example_cases/): a wheel built from this tree, unpacked and run on its own, copies them.
"""
from __future__ import annotations

import os
import subprocess
import sys
import shutil
import zipfile
from pathlib import Path

from click.testing import CliRunner

import dynsens.cli.examples  # noqa: F401  (registers the command)
import dynsens.cli.simulate  # noqa: F401
from conftest import CASES, ROOT
from dynsens.case.load_cases import load_any_case
from dynsens.cli.main import cli

SHIPPED = sorted(p.relative_to(CASES) for p in CASES.rglob("*") if p.is_file() and "__pycache__" not in p.parts)


def run(*args: str) -> object:
    return CliRunner().invoke(cli, ["examples", *args])


def test_every_case_file_and_record_is_copied_and_the_cases_load(tmp_path: Path) -> None:
    out = tmp_path / "my cases"          # made, with a space in its name
    res = run(str(out))
    assert res.exit_code == 0, res.output
    copied = sorted(p.relative_to(out) for p in out.rglob("*") if p.is_file())
    assert copied == SHIPPED
    assert Path("records/tower_sizing_optimum.yaml") in copied
    for f in SHIPPED:
        assert (out / f).read_bytes() == (CASES / f).read_bytes(), f
    yamls = sorted(out.glob("*.yaml"))
    assert len(yamls) == len(list(CASES.glob("*.yaml"))) >= 10
    for y in yamls:
        case = load_any_case(y)          # a case with load_cases loads as its LoadCaseSet
        assert case.name, y
    assert f"copied {len(SHIPPED)} files ({len(yamls)} cases)" in res.output
    assert f"dynsens simulate {out / 'sdof_step.yaml'}" in res.output


def test_existing_files_are_kept_without_overwrite_and_replaced_with_it(tmp_path: Path) -> None:
    assert run(str(tmp_path)).exit_code == 0
    mine = tmp_path / "sdof_step.yaml"
    mine.write_text("name: edited by the user\n", encoding="utf-8")
    (tmp_path / "truss_impact.yaml").unlink()        # a missing one is not copied either: nothing is written
    res = run(str(tmp_path))
    assert res.exit_code == 2
    assert f"{len(SHIPPED) - 1} of the {len(SHIPPED)} example files exist in {tmp_path}" in res.output
    assert "bricard.yaml" in res.output and "--overwrite" in res.output and "nothing was copied" in res.output
    assert "Traceback" not in res.output
    assert mine.read_text(encoding="utf-8") == "name: edited by the user\n"
    assert not (tmp_path / "truss_impact.yaml").exists()
    res = run(str(tmp_path), "--overwrite")
    assert res.exit_code == 0, res.output
    assert mine.read_bytes() == (CASES / "sdof_step.yaml").read_bytes()
    assert (tmp_path / "truss_impact.yaml").exists()
    assert not [p for p in tmp_path.rglob("*.tmp")], "a temporary file was left behind"


def test_a_folder_that_is_a_file_is_refused(tmp_path: Path) -> None:
    f = tmp_path / "cases"
    f.write_text("a file\n", encoding="utf-8")
    res = run(str(f))
    assert res.exit_code == 2
    assert res.output.startswith("Error: ") and "expected a folder, found the file" in res.output
    assert f.read_text(encoding="utf-8") == "a file\n"
    # a sub-folder the copy needs is a file: refused before anything is written
    out = tmp_path / "out"
    out.mkdir()
    (out / "records").write_text("x\n", encoding="utf-8")
    res = run(str(out))
    assert res.exit_code == 2 and "records" in res.output and "is a file" in res.output
    assert sorted(p.name for p in out.iterdir()) == ["records"]


def test_the_wheel_ships_the_cases_and_its_command_copies_them(tmp_path: Path) -> None:
    """Build a wheel of this tree (pip, isolated build as `pip install .` does), unpack it, and run
    its `dynsens examples` without the checkout on the path."""
    src = tmp_path / "src"
    src.mkdir()
    for name in ("pyproject.toml", "setup.py", "MANIFEST.in", "README.md", "LICENSE"):
        shutil.copy2(ROOT / name, src / name)
    for folder in ("dynsens", "cases"):
        shutil.copytree(ROOT / folder, src / folder, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "-q", "-w",
                            str(tmp_path / "wheel")], capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stderr[-3000:]
    (wheel,) = (tmp_path / "wheel").glob("dynsens-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    for f in SHIPPED:
        assert f"dynsens/example_cases/{f.as_posix()}" in names, f
    site = tmp_path / "site"
    zipfile.ZipFile(wheel).extractall(site)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"} | {"PYTHONPATH": str(site)}
    out = tmp_path / "copied"
    res = subprocess.run([sys.executable, "-c", "import dynsens.io.examples as e; print(e.examples_folder())"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    assert Path(res.stdout.strip()) == site / "dynsens" / "example_cases"
    res = subprocess.run([sys.executable, "-m", "dynsens", "examples", str(out)], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    assert sorted(p.relative_to(out) for p in out.rglob("*") if p.is_file()) == SHIPPED


def test_a_copied_case_runs(tmp_path: Path) -> None:
    assert run(str(tmp_path)).exit_code == 0
    res = CliRunner().invoke(cli, ["simulate", str(tmp_path / "sdof_step.yaml"), "--set", "integrator.t_end=0.05",
                                   "-o", str(tmp_path / "sdof.h5")])
    assert res.exit_code == 0, res.output
