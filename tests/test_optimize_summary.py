"""The decision-ready optimize summary and the plots against bounds, in units."""
from __future__ import annotations

import copy

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import dynsens
import dynsens.cli.optimize  # noqa: F401  (registers the command)
from dynsens.cli.main import cli
from test_optimize import SDOF


def sdof_with_units() -> dict:
    raw = copy.deepcopy(SDOF)
    raw["design"]["variables"][0]["unit"] = "N s/m"
    raw["design"]["variables"][1]["unit"] = "N/m"
    raw["responses"][0]["unit"] = "m"
    raw["responses"][1]["unit"] = "EUR"
    raw["output"] = {"quantities": [{"name": "u", "quantity": {"dof": "u"}, "unit": "m"}]}
    return raw


def test_summary_names_kkt_active_constraints_bounds_and_the_objective_change(tmp_path):
    pytest.importorskip("matplotlib")
    case = tmp_path / "sdof.yaml"
    case.write_text(yaml.safe_dump(sdof_with_units(), sort_keys=False))
    out = tmp_path / "opt.h5"
    r = CliRunner().invoke(cli, ["optimize", str(case), "-o", str(out), "--plots", str(tmp_path / "plots")])
    assert r.exit_code == 0, r.output
    text = r.output
    with h5py.File(out, "r") as f:
        h = f["optimization/start_0/history"]
        f0, f1, kkt = h["f"][0], h["f"][-1], h["kkt"][-1]
        q_ks = f["optimization/start_0"].attrs["responses_opt"][0]
        assert "initial" in f["optimization"] and "u" in f["optimization/optimum"]   # start and optimum runs
        assert f["optimization/optimum/u"].attrs["units"] == "m"
    assert f"objective cost: {f0:.8g} EUR at the start -> {f1:.8g} EUR at the optimum" in text
    assert f"({100 * (f1 - f0) / f0:+.3g} %)" in text
    assert f"final KKT residual {kkt:.2e}" in text
    # the displacement limit is what stops the design: active, in metres
    assert f"q_ks = {q_ks:.6g} m  (bound <= 0.2 m): active" in text
    assert "c = " in text and "N s/m in [0.1, 20]" in text
    assert "\nactive: q_ks" in text
    best = dynsens.read_result(out, "optimization/optimum")
    start = dynsens.read_result(out, "optimization/initial")
    assert best.units["u"] == "m" and best.responses["cost"]["value"] == pytest.approx(f1, rel=1e-12)
    assert start.responses["cost"]["value"] == pytest.approx(f0, rel=1e-12)
    # the displacement limit (KS, ρ = 50) is active at the optimum: the recorded peak lies within
    # the KS bounds max u ≤ KS ≤ max u + ln(N)/ρ of 0.2 m
    peak = best.to_dataframe()["u"].max()
    assert peak <= 0.2 <= peak + np.log(len(best.time)) / 50.0
    assert not np.array_equal(best.quantities["u"], start.quantities["u"])
    for name in ("opt_history", "opt_design", "opt_constraints", "opt_optimum"):
        p = tmp_path / "plots" / f"{name}.png"
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 5000


def test_the_active_line_counts_a_family_at_its_bounds():
    """A ground structure leaves thousands of variables at their lower bound: the `active:` line
    counts them per family (it listed every one: one line of 40,000 characters for 1,747 bars)."""
    from dynsens.optimize.summary import LISTED, active_bounds
    few = [f"A[b{i}]" for i in range(LISTED)]
    assert active_bounds(few) == [f"bound of A[b{i}]" for i in range(LISTED)]
    many = [f"A[b{i}]" for i in range(1747)] + [f"t[m{i}]" for i in range(5)] + ["H", "k"]
    assert active_bounds(many) == ["bound of H", "bound of k", "bounds of 1747 variables of family A",
                                   "bounds of 5 variables of family t"]
    plain = [f"x{i}" for i in range(LISTED + 3)]
    assert active_bounds(plain) == [f"bound of x{i}" for i in range(LISTED)] + ["bounds of 3 more variables"]


def test_constraint_rows_say_violated_and_inactive_in_units():
    from dynsens.optimize.problem import ConstraintTerm, ScaledProblem
    from dynsens.optimize.summary import bound_rows, constraint_rows
    p = ScaledProblem(("a",), np.array([0.0]), np.array([1.0]), np.array([1.0]), "f", 1.0,
                      (ConstraintTerm("s", "upper", 300.0, 300.0), ConstraintTerm("d", "lower", 2.0, 2.0)),
                      ("f", "s", "d"))
    rows = constraint_rows(p, np.array([1.0, 330.0, 3.0]), np.array([-0.1, 0.5]), None, {"s": "MPa", "d": "mm"})
    assert rows[0].endswith("s = 330 MPa  (bound <= 300 MPa): VIOLATED by 30 MPa")
    assert "d = 3 mm  (bound >= 2 mm): inactive, margin 1 mm" in rows[1]
    assert "at its upper bound (active)" in bound_rows(("a",), np.array([1.0]), p.lower, p.upper, ("m",))[0]
