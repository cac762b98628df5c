"""``dynsens optimize``: SLSQP on the direct sensitivities, history in HDF5.

Contract: converges on the truss lightweight case to a feasible design with an active
stress constraint and a lower mass than x0; the history has one row per iteration and is
on disk after every iteration (an interrupted run is readable and ``--resume`` finishes
it); a simulation failing inside the optimization is recorded and the run continues; a
start outside the bounds is a clean error; several starts run in worker processes (or on
a Dask cluster) and give a table of optima.
"""
from __future__ import annotations

import os
import re
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import dynsens.cli.optimize as cli_opt
import dynsens.optimize as opt
import dynsens.optimize.problem as opt_problem
from dynsens.case.load import load_case, load_case_dict
from dynsens.cli.main import cli
from dynsens.errors import ConvergenceError, ModelError
from dynsens.io.paths import OutputPathError
from dynsens.postcheck import check_members
from dynsens.responses.base import ResponseValue
from helpers import SDOF_DESIGN, ctrl_c_after_rows

REPO = Path(__file__).resolve().parents[1]
TRUSS = REPO / "cases" / "truss_lightweight.yaml"

SDOF = SDOF_DESIGN


@pytest.fixture
def sdof_file(tmp_path: Path) -> Path:
    p = tmp_path / "sdof_design.yaml"
    p.write_text(yaml.safe_dump(SDOF, sort_keys=False))
    return p


def invoke(*args: str):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


def history(path: Path, k: int = 0) -> dict[str, np.ndarray]:
    return opt.read_history(path, k)


@pytest.fixture(scope="module")
def truss_optimum(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    """The truss optimized without interruption (its file and the command's result), made once:
    checked by test_truss_converges_feasible_with_active_stress_constraint and the reference the
    interrupted and resumed run must reach."""
    out = tmp_path_factory.mktemp("truss_optimum") / "opt.h5"
    return out, invoke("optimize", TRUSS, "-o", out, "--no-verify")


def test_truss_converges_feasible_with_active_stress_constraint(truss_optimum) -> None:  # type: ignore[no-untyped-def]
    # the optimizer alone (tests/test_verification.py: the same case verified and tightened)
    out, r = truss_optimum
    assert r.exit_code == 0, r.output
    assert "The optimizer converged" in r.output and "The result is feasible" in r.output
    assert len(re.findall(r"^\[start 0\] it +\d+ ", r.output, re.M)) >= 3      # a progress line per iteration
    h = history(out)
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "converged"
        s = f["optimization/start_0"].attrs
        names = list(f["design/names"].asstr()[()])
        np.testing.assert_allclose(f["design/x0"][()], load_case(TRUSS).x0)
        nit = int(s["nit"])
        x_opt, g_opt = s["x_opt"], s["g_opt"]
        resp = dict(zip(__import__("json").loads(f["optimization"].attrs["response_names"]), s["responses_opt"]))
        assert bool(f["optimization/summary/feasible"][0]) and bool(f["optimization/summary/success"][0])
    # one row per iteration (row 0 = x0), every dataset alike
    assert nit >= 2 and all(v.shape[0] == nit + 1 for v in h.values())
    np.testing.assert_array_equal(h["iteration"], np.arange(nit + 1))
    assert h["grad_f"].shape == (nit + 1, 3) and h["grad_g"].shape == (nit + 1, 2, 3)
    assert h["f"][-1] < 0.92 * h["f"][0]                        # lighter than x0 (0.0720 t -> 0.0646 t)
    # both the stress (tension and compression) and the buckling constraint are active
    assert resp["stress_ks"] == pytest.approx(1.0, rel=1e-4) and resp["buckling_ks"] == pytest.approx(1.0, rel=1e-4)
    assert resp["stress_max"] <= resp["stress_ks"]              # KS bounds the sampled maximum
    assert np.all(np.abs(g_opt) < 1e-4) and h["kkt"][-1] < 1e-2
    assert np.all(x_opt > load_case(TRUSS).lower) and names[1] == "A_chord_top"
    # the post-check: every member's stress and buckling ratio at every stored step
    check = check_members(load_case(TRUSS), x_opt)
    assert check.steps == 31 and np.isfinite(check.buckling).all()
    assert check.passes(1e-3), check.worst()
    assert check.largest > 0.99                                 # and the design is not over-sized


def test_interrupted_run_keeps_history_and_resume_finishes(tmp_path: Path, monkeypatch,  # type: ignore[no-untyped-def]
                                                           truss_optimum) -> None:
    out = tmp_path / "opt.h5"
    ref, r_ref = truss_optimum
    assert r_ref.exit_code == 0
    f_ref = history(ref)["f"][-1]
    real = ctrl_c_after_rows(monkeypatch)
    r = invoke("optimize", TRUSS, "-o", out, "--no-verify")
    assert r.exit_code == 130 and "--resume" in r.output
    with h5py.File(out, "r") as f:                # readable, nothing lost
        assert f.attrs["status"] == "interrupted"
        assert f["optimization/start_0/history/x"].shape == (3, 3)
        assert not f["optimization/start_0"].attrs["finished"]
        n_eval = f["optimization/start_0/evaluations/x"].shape[0]
    assert n_eval >= 3
    monkeypatch.setattr(cli_opt, "progress_line", real)
    r = invoke("optimize", TRUSS, "-o", out, "--resume", "--no-verify")
    assert r.exit_code == 0, r.output
    assert "[start 0] it   3" in r.output and "[start 0] it   0" not in r.output
    h = history(out)
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "converged"
        nit = int(f["optimization/start_0"].attrs["nit"])
        assert f["optimization/start_0/evaluations/x"].shape[0] > n_eval
    np.testing.assert_array_equal(h["iteration"], np.arange(nit + 1))
    assert list(h["segment"][:3]) == [0, 0, 0] and set(h["segment"][3:]) == {1}
    assert h["f"][-1] == pytest.approx(f_ref, rel=1e-5)


def _failing_run_case(monkeypatch, fail_calls: set[int], how: str):  # type: ignore[no-untyped-def]
    real = opt_problem.run_case
    calls = [0]

    def run_case(case, x, **kw):  # type: ignore[no-untyped-def]
        calls[0] += 1
        if calls[0] in fail_calls:
            if how == "diverge":
                raise ConvergenceError("Newton-Raphson did not converge", t=0.05, step=5, iterations=25,
                                       residual_history=[1.0, 10.0], hint="reduce integrator.dt")
            if how == "assemble":
                raise ModelError("mechanism cannot assemble: loop closure has no solution")
            res = real(case, x, **kw)
            res.responses["q_ks"] = ResponseValue(np.nan, None, "m", missing="event 'E1' never fired")
            return res
        return real(case, x, **kw)
    monkeypatch.setattr(opt_problem, "run_case", run_case)
    return calls


@pytest.mark.parametrize("how, needle", [("diverge", "ConvergenceError"), ("missing", "never fired")])
def test_failed_simulation_is_recorded_and_run_continues(tmp_path, sdof_file, monkeypatch, how, needle) -> None:
    out = tmp_path / "opt.h5"
    calls = _failing_run_case(monkeypatch, {3}, how)        # the 2nd iteration's trial point
    r = invoke("optimize", sdof_file, "-o", out)
    assert r.exit_code == 0, r.output
    assert "simulation failed" in r.output and needle in r.output
    assert calls[0] > 4                                       # it went on after the failure
    with h5py.File(out, "r") as f:
        ev = f["optimization/start_0/evaluations"]
        failed = ev["failed"][()]
        assert failed.tolist().count(True) == 1 and failed[2]
        assert needle in ev["message"].asstr()[2] and np.isnan(ev["f"][2])
        assert f.attrs["status"] == "converged" and f["optimization/start_0"].attrs["feasible"]
        assert int(f["optimization/start_0"].attrs["n_failed"]) == 1
    h = history(out)
    assert h["failed"].sum() == 1 and any(needle in m for m in h["message"])
    assert np.all(np.isfinite(h["f"]))
    assert h["f"][-1] > h["f"][0]          # x0 violates q_ks <= 0.2: feasibility costs stiffness
    assert h["max_violation"][-1] < 1e-4


def test_start_that_cannot_be_simulated_is_a_clean_error(tmp_path, sdof_file, monkeypatch) -> None:
    out = tmp_path / "opt.h5"
    _failing_run_case(monkeypatch, {1}, "assemble")
    r = CliRunner().invoke(cli, ["optimize", str(sdof_file), "-o", str(out)])
    assert r.exit_code == 2 and "Traceback" not in r.output
    assert "Error:" in r.output and "cannot be simulated" in r.output and "cannot assemble" in r.output
    with h5py.File(out, "r") as f:                       # recorded, not lost
        assert f.attrs["status"] == "failed"
        assert f["optimization/start_0/evaluations/failed"][()].tolist() == [True]


@pytest.mark.parametrize("arg, needle", [("k=1000", "outside the bounds of design variable 'k': [10, 400]"),
                                         ("kk=50", "unknown design variable 'kk'"),
                                         ("k", "expected NAME=VALUE")])
def test_x0_outside_bounds_is_a_clean_error(tmp_path, sdof_file, arg, needle) -> None:
    out = tmp_path / "opt.h5"
    r = CliRunner().invoke(cli, ["optimize", str(sdof_file), "-o", str(out), "-x", arg])
    assert r.exit_code == 2 and needle in r.output and "Traceback" not in r.output
    assert not out.exists()


def test_x0_option_moves_the_start(tmp_path, sdof_file) -> None:
    out = tmp_path / "opt.h5"
    r = invoke("optimize", sdof_file, "-o", out, "-x", "k=300", "--maxiter", "2")
    assert r.exit_code == 1                          # 2 iterations: not converged, said plainly
    assert "did NOT converge" in r.output
    h = history(out)
    np.testing.assert_allclose(h["x"][0], [2.0, 300.0])
    assert h["x"].shape[0] == 3


def test_existing_output_needs_overwrite(tmp_path, sdof_file) -> None:
    out = tmp_path / "opt.h5"
    out.write_bytes(b"keep")
    r = CliRunner().invoke(cli, ["optimize", str(sdof_file), "-o", str(out)])
    assert r.exit_code == 2 and "--overwrite" in r.output and out.read_bytes() == b"keep"


@pytest.mark.parametrize("extra", [None, -3])
def test_too_long_output_name_is_a_clean_error(tmp_path, sdof_file, extra) -> None:
    # 297 characters + ".h5" is past any file system's limit on names; NAME_MAX - 3 bytes fits,
    # but its lock file ".NAME.lock" and the temporary file do not: refused before any lookup
    # of the path (which failed with "OSError: File name too long" and a traceback)
    name_max = os.pathconf(tmp_path, "PC_NAME_MAX")
    name = "a" * 297 + ".h5" if extra is None else "a" * (name_max + extra - 3) + ".h5"
    r = CliRunner().invoke(cli, ["optimize", str(sdof_file), "-o", str(tmp_path / name), "--maxiter", "1"])
    assert r.exit_code == 2 and "Traceback" not in r.output and r.exception is not None, r.output
    assert r.output.count("Error:") == 1 and "-o/--output: expected" in r.output, r.output
    assert f"at most {name_max} bytes" in r.output, r.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sdof_design.yaml"]      # nothing written
    if extra is not None:       # the library call: its lock file's name is past the limit
        with pytest.raises(OutputPathError, match=f"at most {name_max - 6} bytes .*its lock file adds 6"):
            opt.optimize_case(load_case(sdof_file), tmp_path / name, maxiter=1)
        assert sorted(p.name for p in tmp_path.iterdir()) == ["sdof_design.yaml"]


def test_multistart_with_two_workers_prints_a_table(tmp_path: Path) -> None:
    out = tmp_path / "opt.h5"
    # without the verification: its tightening rounds go on from the best start alone
    r = invoke("optimize", TRUSS, "-o", out, "--starts", "2", "--workers", "2", "--seed", "7", "--no-verify")
    assert r.exit_code == 0, r.output
    rows = re.findall(r"^ +([01])\*? +([0-9.]+) +\S+ +(yes|no) +(yes|no) ", r.output, re.M)
    assert [row[0] for row in rows] == ["0", "1"]
    from scipy.stats import qmc
    case = load_case(TRUSS)
    try:   # SciPy >= 1.15 (rng= as an integer draws the same as a default_rng of it)
        lhs = qmc.LatinHypercube(d=3, rng=7)
    except TypeError:   # SciPy < 1.15: seed=, with a generator; the sample differs from the newer one
        lhs = qmc.LatinHypercube(d=3, seed=np.random.default_rng(7))
    x1 = case.lower + lhs.random(1)[0] * (case.upper - case.lower)
    with h5py.File(out, "r") as f:
        np.testing.assert_allclose(f["optimization/start_1"].attrs["x_start"], x1)
        assert f["optimization/summary/f"].shape == (2,)
        for k in (0, 1):
            h = f[f"optimization/start_{k}/history"]
            assert h["x"].shape[0] == int(f[f"optimization/start_{k}"].attrs["nit"]) + 1 >= 3
        np.testing.assert_allclose(f["optimization/start_1/history/x"][0], x1)
        fs = f["optimization/summary/f"][()]
    assert fs[0] == pytest.approx(fs[1], rel=1e-4)               # the same optimum from both starts


def test_dask_local_cluster(tmp_path: Path) -> None:
    pytest.importorskip("distributed", reason="dask.distributed is not installed (pip install 'dynsens[dask]')")
    from distributed import LocalCluster
    out = tmp_path / "opt.h5"
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        r = invoke("optimize", TRUSS, "-o", out, "--starts", "2", "--seed", "7", "--no-verify",
                   "--scheduler", cluster.scheduler_address)
    assert r.exit_code == 0, r.output
    assert re.search(r"^\[start 1\] it +1 ", r.output, re.M)
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "converged"
        for k in (0, 1):
            h = f[f"optimization/start_{k}/history"]
            assert h["x"].shape[0] == int(f[f"optimization/start_{k}"].attrs["nit"]) + 1 >= 3
            np.testing.assert_array_equal(h["iteration"][()], np.arange(h["x"].shape[0]))


def test_plots_are_png(tmp_path, sdof_file) -> None:
    pytest.importorskip("matplotlib")
    out = tmp_path / "opt.h5"
    r = invoke("optimize", sdof_file, "-o", out, "--plots", tmp_path / "plots")
    assert r.exit_code == 0, r.output
    for name in ("opt_history.png", "opt_optimum.png"):
        p = tmp_path / "plots" / name
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 5000


def test_scaling_and_constraint_terms() -> None:
    raw = dict(SDOF, optimization={"objective": "cost", "constraints": [
        {"response": "q_ks", "upper": 0.2, "lower": 0.05}, {"response": "cost", "lower": 0.0, "upper": 0.0}]})
    case = load_case_dict(raw)
    p = opt.build_problem(case, {"q_ks": 0.25, "cost": 120.0})
    assert p.f_ref == 120.0
    assert [(c.kind, c.divisor) for c in p.constraints] == [("upper", 0.2), ("lower", 0.05), ("eq", 120.0)]
    x = np.array([2.0, 100.0])
    u = p.to_u(x)
    np.testing.assert_allclose(u, [(2.0 - 0.1) / 19.9, 90.0 / 390.0])
    np.testing.assert_allclose(p.to_x(u), x)
    ev = opt.evaluate(case, p, x)
    r = ev.responses[0]
    np.testing.assert_allclose(ev.g[:2], [(0.2 - r) / 0.2, (r - 0.05) / 0.05])
    np.testing.assert_allclose(ev.grad_f, np.array([10.0, 1.0]) * [19.9, 390.0] / 120.0)


def test_failed_point_gives_the_optimizer_a_finite_penalty(monkeypatch) -> None:
    case = load_case_dict(SDOF)
    p = opt.build_problem(case, {"q_ks": 0.25, "cost": 120.0})
    _failing_run_case(monkeypatch, {2}, "diverge")
    seen: list[opt.Evaluation] = []
    ev = opt.Evaluator(case, p, seen.append)
    u0, u1 = p.to_u(case.x0), p.to_u(case.x0 * 1.1)
    f0, g0, j0 = ev.fun(u0), ev.cons(u0, [0]), ev.jac(u0)
    f1, g1, j1 = ev.fun(u1), ev.cons(u1, [0]), ev.jac(u1)        # one (failed) simulation serves all
    assert np.isfinite(f1) and f1 >= f0 + opt.FAIL_PENALTY
    assert np.all(np.isfinite(g1)) and g1[0] <= min(g0[0], 0.0) - opt.FAIL_PENALTY + 1e-12
    np.testing.assert_array_equal(j1, j0)
    assert np.all(np.isfinite(ev.cons_jac(u1, [0])))
    assert ev.n_sim == 2 and ev.n_failed == 1
    assert [e.failed for e in seen] == [False, True] and "ConvergenceError" in seen[1].message
