"""The optimizers of ``optimization.method`` (dynsens.optimize.methods) on closed-form optima.

Closed form: an undamped mass–spring under a suddenly applied constant force F peaks at twice its
static displacement, u_max = 2F/k (Newmark's average acceleration keeps the amplitude of an
undamped linear oscillator exactly; the sampled peak is within (ω·dt)²/8 of it).  Minimizing
k₁ + k₂ of two such oscillators subject to u₁,max ≤ a₁ and u₂,max ≤ a₂ gives k_i* = 2F_i/a_i.
"""
from __future__ import annotations

import builtins
import copy
from pathlib import Path

import numpy as np
import pytest

import dynsens
from dynsens.case.load import load_case_dict
from dynsens.errors import CaseError
from dynsens.optimize.problem import OptimizationError
from helpers import ctrl_c_after_rows, ipopt_missing

REPO = Path(__file__).resolve().parents[1]
F1, F2, A1, A2 = 10.0, 30.0, 0.2, 0.3

PAIR = {
    "name": "step_pair",
    "design": {"variables": [{"name": "k1", "value": 300.0, "lower": 50.0, "upper": 400.0},
                             {"name": "k2", "value": 300.0, "lower": 50.0, "upper": 400.0}]},
    "model": {"type": "structural", "dofs": ["u", "v"],
              "elements": [{"type": "mass", "name": "mu", "dof": "u", "mass": 2.0},
                           {"type": "mass", "name": "mv", "dof": "v", "mass": 2.0},
                           {"type": "spring", "name": "su", "dofs": ["u", "ground"], "k": "k1"},
                           {"type": "spring", "name": "sv", "dofs": ["v", "ground"], "k": "k2"}],
              "loads": [{"dof": "u", "value": F1, "function": "constant"},
                        {"dof": "v", "value": F2, "function": "constant"}]},
    "integrator": {"scheme": "newmark", "beta": 0.25, "gamma": 0.5, "dt": 1.0e-3, "t_end": 1.0},
    "sensitivity": {"enabled": True, "partials": "forward"},
    "responses": [{"name": "u_max", "type": "max", "quantity": {"dof": "u", "kind": "displacement"}},
                  {"name": "v_max", "type": "max", "quantity": {"dof": "v", "kind": "displacement"}},
                  {"name": "cost", "type": "expression", "expression": "k1 + k2"}],
    "optimization": {"objective": "cost", "constraints": [{"response": "u_max", "upper": A1},
                                                          {"response": "v_max", "upper": A2}],
                     "maxiter": 100, "ftol": 1e-10},
}


def pair(method: str) -> dict:
    raw = copy.deepcopy(PAIR)
    raw["optimization"]["method"] = method
    return raw


def _installed(method: str) -> list:
    """IPOPT needs the system's Ipopt library beside cyipopt (``dynsens[ipopt]``); skipped where
    it is not installed, with the reason (never in CI: :func:`helpers.ipopt_missing`)."""
    return [pytest.param(method, marks=pytest.mark.skipif(ipopt_missing(), reason="cyipopt / Ipopt not installed"))]


@pytest.mark.parametrize("method", ["SLSQP", "MMA", "CCSAQ", "trust-constr", *_installed("IPOPT")])
def test_each_method_reaches_the_closed_form_optimum(method: str) -> None:
    res = dynsens.optimize(pair(method), verify=False)
    assert res.success and res.feasible, res.message
    np.testing.assert_allclose(res.x, [2 * F1 / A1, 2 * F2 / A2], rtol=1e-4)
    assert res.message.startswith(method)
    # the history is the same for every method: one row per iteration, the KKT measure at the end
    assert res.history["x"].shape[0] == res.nit + 1 and res.history["kkt"][-1] < 1e-3


@pytest.mark.parametrize("method", ["MMA", *_installed("IPOPT")])
def test_mma_finds_the_shipped_truss_optimum_of_slsqp(method: str) -> None:
    truss = REPO / "cases" / "truss_lightweight.yaml"
    ref = dynsens.optimize(truss, verify=False)
    mma = dynsens.optimize(truss, verify=False, optimization__method=method)
    assert mma.success and mma.feasible
    assert mma.fun == pytest.approx(ref.fun, rel=1e-5)
    np.testing.assert_allclose(mma.x, ref.x, rtol=1e-3)


def test_what_the_methods_refuse(monkeypatch) -> None:
    raw = pair("MMA")
    raw["optimization"]["constraints"][0]["lower"] = A1          # an equality
    with pytest.raises(OptimizationError, match="inequality constraints only"):
        dynsens.optimize(raw, verify=False)
    raw = pair("Nelder-Mead")
    with pytest.raises(CaseError, match="optimization.method"):
        load_case_dict(raw)
    real_import = builtins.__import__

    def no_nlopt(name, *args, **kwargs):  # type: ignore[no-untyped-def]
        if name == "nlopt":
            raise ImportError("No module named 'nlopt'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_nlopt)
    with pytest.raises(OptimizationError, match=r"pip install 'dynsens\[mma\]'"):
        dynsens.optimize(pair("MMA"), verify=False)


def test_a_missing_ipopt_names_the_extra_and_the_library(monkeypatch) -> None:
    real_import = builtins.__import__

    def no_cyipopt(name, *args, **kwargs):  # type: ignore[no-untyped-def]
        if name == "cyipopt":
            raise ImportError("No module named 'cyipopt'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_cyipopt)
    with pytest.raises(OptimizationError, match=r"coinor-libipopt-dev.*pip install 'dynsens\[ipopt\]'"):
        dynsens.optimize(pair("IPOPT"), verify=False)


@pytest.mark.parametrize("method", _installed("IPOPT"))
def test_ipopt_takes_an_equality(method: str) -> None:
    """u₁,max = a₁ as an equality (MMA refuses it): the optimum is the same, k₁* = 2F₁/a₁."""
    raw = pair(method)
    raw["optimization"]["constraints"][0]["lower"] = A1
    res = dynsens.optimize(raw, verify=False)
    assert res.success and res.feasible, res.message
    np.testing.assert_allclose(res.x, [2 * F1 / A1, 2 * F2 / A2], rtol=1e-4)


@pytest.mark.parametrize("method", ["SLSQP", "MMA", "trust-constr", *_installed("IPOPT")])
def test_each_method_reaches_the_optimum_from_a_start_on_the_bounds(method: str) -> None:
    """A start on the upper bounds: trust-constr (an interior-point method) stopped there after
    one iteration and called the start its optimum; it now starts just inside the bounds."""
    raw = pair(method)
    for v in raw["design"]["variables"]:
        v["value"] = v["upper"]
    res = dynsens.optimize(raw, verify=False)
    assert res.success and res.feasible, res.message
    np.testing.assert_allclose(res.x, [2 * F1 / A1, 2 * F2 / A2], rtol=1e-4)


@pytest.mark.parametrize("method", _installed("IPOPT"))
def test_ipopt_is_interrupted_resumed_and_multi_started_like_the_others(tmp_path: Path, monkeypatch,
                                                                       method: str) -> None:
    """Ctrl-C inside IPOPT's iteration callback reaches the CLI (cyipopt re-raises it), the file
    keeps the history, ``--resume`` finishes from the last iterate to the closed-form optimum,
    and ``--starts 2`` runs two IPOPT starts."""
    import h5py
    import yaml
    from click.testing import CliRunner

    from dynsens.cli.main import cli as main
    from dynsens.cli import optimize as cli_opt
    case = tmp_path / "pair.yaml"
    case.write_text(yaml.safe_dump(pair(method)))
    out = tmp_path / "opt.h5"
    real = ctrl_c_after_rows(monkeypatch)
    r = CliRunner().invoke(main, ["optimize", str(case), "-o", str(out), "--no-verify"])
    assert r.exit_code == 130 and "--resume" in r.output, r.output
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "interrupted" and f["optimization/start_0/history/x"].shape[0] == 3
    monkeypatch.setattr(cli_opt, "progress_line", real)
    r = CliRunner().invoke(main, ["optimize", str(case), "-o", str(out), "--resume", "--no-verify"])
    assert r.exit_code == 0, r.output
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "converged"
        x = f["optimization/start_0/history/x"][-1]
    np.testing.assert_allclose(x, [2 * F1 / A1, 2 * F2 / A2], rtol=1e-4)
    r = CliRunner().invoke(main, ["optimize", str(case), "-o", str(tmp_path / "ms.h5"), "--starts", "2",
                                  "--no-verify"])
    assert r.exit_code == 0, r.output
    with h5py.File(tmp_path / "ms.h5", "r") as f:
        assert {"start_0", "start_1"} <= set(f["optimization"])
