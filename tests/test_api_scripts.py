"""The API from a plain script, and the data view of a result (issue 36's smaller points)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from click.testing import CliRunner

import dynsens
import dynsens.cli.simulate  # noqa: F401  (registers the command)
from dynsens.cli.main import cli

REPO = Path(__file__).resolve().parents[1]
CASES = REPO / "cases"


def test_api_runs_from_a_plain_script_without_main_guard(tmp_path: Path) -> None:
    """check_gradients and optimize with their default workers, called at import level of a
    script (no ``if __name__ == "__main__"``): the spawn workers must not re-run the script
    (before: the spawn "bootstrapping phase" RuntimeError)."""
    script = tmp_path / "plain.py"
    script.write_text(f"""
import dynsens
case = dynsens.load_case({str(CASES / 'sdof_step.yaml')!r}, ["integrator.t_end=0.05"])
r = dynsens.simulate(case)
dynsens.check_gradients(case)
dynsens.optimize({str(CASES / 'truss_lightweight.yaml')!r}, maxiter=2, verify=False)
print("DONE")
""")
    env = {**os.environ, "PYTHONPATH": str(Path(dynsens.__file__).parents[1])}
    p = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600,
                       cwd=tmp_path, env=env)
    assert p.returncode == 0, p.stderr[-2000:]
    assert p.stdout.count("DONE") == 1


def test_to_xarray_labels_every_dimension(tmp_path: Path) -> None:
    """Multiplier and pressure dimensions get coordinates, like time, dof and design_variable."""
    out = tmp_path / "lever.h5"
    result = CliRunner().invoke(cli, ["simulate", str(CASES / "hydraulic_lever.yaml"), "-o", str(out),
                                      "--set", "integrator.t_end=0.02", "--set", "output.history=all"])
    assert result.exit_code == 0, result.output
    ds = dynsens.read_result(out).to_xarray()
    assert {"multiplier", "pressure"} <= set(ds.dims)
    for dim, size in ds.sizes.items():
        assert dim in ds.coords, f"dimension {dim} has no coordinate"
        assert len(ds.coords[dim]) == size
