"""The documented Python API: dynsens.simulate / optimize / check_gradients, and the entry points."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import dynsens
from dynsens.case.load import load_case
from helpers import SDOF_DESIGN

REPO = Path(__file__).resolve().parents[1]
SDOF_FILE = REPO / "cases" / "sdof_step.yaml"

DESIGN = SDOF_DESIGN   # cost = k + 10 c subject to max displacement (KS) <= 0.2 m


def test_public_names_are_exported() -> None:
    for name in ("simulate", "optimize", "check_gradients", "Simulation", "OptimizeResult", "load_case",
                 "load_case_dict", "run_case", "Case", "CaseError"):
        assert name in dynsens.__all__ and hasattr(dynsens, name)
    assert callable(dynsens.optimize)


def test_simulate_path_dict_and_case_agree_with_run_case() -> None:
    over = ["integrator.t_end=1"]
    ref = dynsens.run_case(load_case(SDOF_FILE, over))
    by_path = dynsens.simulate(SDOF_FILE, **{"integrator.t_end": 1})
    by_case = dynsens.simulate(load_case(SDOF_FILE), integrator__t_end=1)
    import yaml
    by_dict = dynsens.simulate(yaml.safe_load(SDOF_FILE.read_text()), **{"integrator.t_end": 1.0})
    for sim in (by_path, by_case, by_dict):
        assert sim.status == "completed" and sim.design_names == ("m", "c", "k")
        for n, r in ref.responses.items():
            assert sim.values[n] == pytest.approx(float(r.value), rel=1e-14)
            np.testing.assert_allclose(sim.gradients[n], r.gradient, rtol=1e-12)
        assert sim.units["q_end"] == "m" and sim.time[-1] == pytest.approx(1.0)
        assert sim.history["q"].shape[0] == sim.time.size


def test_simulate_at_a_design_and_without_sensitivities(tmp_path: Path) -> None:
    case = load_case(SDOF_FILE, ["integrator.t_end=0.5"])
    x = case.x0 * np.array([1.1, 1.0, 0.9])
    sim = dynsens.simulate(case, x, sensitivities=False, history=())
    ref = dynsens.run_case(case, x, sensitivities=False)
    assert sim.values["q_end"] == pytest.approx(float(ref.responses["q_end"].value), rel=1e-14)
    assert np.all(np.isnan(sim.gradients["q_end"])) and sim.history == {}
    out = sim.save(tmp_path / "r.h5")
    assert out.exists()
    with pytest.raises(ValueError, match="expected 3 values"):
        dynsens.simulate(case, [1.0, 2.0])


def test_simulate_bad_override_is_a_case_error() -> None:
    with pytest.raises(dynsens.CaseError, match="integrator"):
        dynsens.simulate(SDOF_FILE, **{"integrator.dtt": 1e-3})


def test_optimize_in_memory_returns_scipy_names(tmp_path: Path) -> None:
    res = dynsens.optimize(DESIGN, maxiter=50)
    for name in ("x", "fun", "jac", "nit", "nfev", "success", "status", "message"):
        assert name in res
    assert res.success and res.feasible and res.path is None
    assert res.x.shape == (2,) and res.fun == pytest.approx(res.x[1] + 10 * res.x[0], rel=1e-12)
    # cost = k + 10 c: its gradient in design units is exactly [10, 1]
    np.testing.assert_allclose(res.jac, [10.0, 1.0], rtol=1e-8)
    assert res.constraints["q_ks"] <= 0.2 * (1 + 1e-6)
    assert res.nfev >= res.nit >= 1 and len(res.history["x"]) == res.nit + 1
    # the same run written to a file gives the same optimum
    on_disk = dynsens.optimize(DESIGN, tmp_path / "opt.h5", maxiter=50)
    assert on_disk.path == tmp_path / "opt.h5" and on_disk.path.exists()
    np.testing.assert_allclose(on_disk.x, res.x, rtol=1e-12)


def test_check_gradients_api() -> None:
    rep = dynsens.check_gradients(SDOF_FILE, [1e-6], workers=1, **{"integrator.t_end": 1.0})
    assert rep.passes(1e-4) and rep.columns[0].rel_diff["q_end"] < 1e-4


@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_python_m_dynsens_help(flag: str) -> None:
    out = subprocess.run([sys.executable, "-m", "dynsens", flag], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "Usage: dynsens" in out.stdout and "simulate" in out.stdout and "optimize" in out.stdout


def test_subcommand_short_help() -> None:
    out = subprocess.run([sys.executable, "-m", "dynsens", "simulate", "-h"], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0 and "--output" in out.stdout


def test_optimize_subpackage_still_importable() -> None:
    # dynsens.optimize is both the API function (called) and the subpackage (imported from)
    code = ("import dynsens, dynsens.optimize.problem as p; import dynsens.optimize.jobs as j; "
            "from dynsens.optimize import optimize_case; assert callable(dynsens.optimize) and p.FEAS_TOL > 0")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr


def test_warmup_runs_each_arithmetic_mode_of_a_mechanism(capsys) -> None:
    from dynsens import warmup
    assert warmup.warm([REPO / "cases" / "pendulum_3d.yaml", SDOF_FILE], steps=3) >= 0.0
    out = capsys.readouterr().out
    assert "warmed pendulum_3d.yaml" in out and "warmed sdof_step.yaml: 0.0 s" in out   # structural: nothing
