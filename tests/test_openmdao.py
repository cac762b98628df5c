"""dynsens.openmdao: the case as an OpenMDAO component.

Contract: the partials agree with OpenMDAO's own central differences; one simulation serves the
values and the partials of a design point; OpenMDAO's SLSQP reaches the optimum of
``dynsens optimize`` on the lightweight truss; the two-load-case example with a cost model runs;
without OpenMDAO the import names the extra.
"""
from __future__ import annotations

import importlib
import runpy
import sys
from pathlib import Path

import numpy as np
import pytest

import openmdao.api as om    # the test extra installs it: a missing OpenMDAO fails here, not skips
from openmdao.utils.assert_utils import assert_check_partials

from dynsens.api import simulate
from dynsens.case.load import load_case
from dynsens.openmdao import CaseComponent, add_case_driver_variables, openmdao_name
from dynsens.optimize.runner import optimize_case

REPO = Path(__file__).resolve().parents[1]
TRUSS = REPO / "cases" / "truss_lightweight.yaml"
NAMES = ("A_chord_bottom", "A_chord_top", "A_web")


def truss_problem(x: tuple[float, ...] = (400.0, 400.0, 250.0), method: str = "direct"
                  ) -> tuple[om.Problem, CaseComponent]:
    prob = om.Problem()
    comp = prob.model.add_subsystem("truss", CaseComponent(case=TRUSS, overrides={"sensitivity.method": method}))
    prob.setup()
    for n, v in zip(NAMES, x):
        prob.set_val(f"truss.{n}", v)
    return prob, comp


def test_interface_follows_the_case() -> None:
    prob, comp = truss_problem()
    assert list(comp.input_names.values()) == list(NAMES)
    assert list(comp.output_names) == ["mass", "stress_ks", "buckling_ks"]   # objective, then constraints
    meta = {m["prom_name"]: m for _, m in comp.list_outputs(units=True, out_stream=None, prom_name=True)}
    assert meta["mass"]["units"] == "t" and meta["stress_ks"]["units"] is None
    assert openmdao_name("A[3]") == "A_3" and openmdao_name("a.b") == "a_b"


@pytest.mark.parametrize("method", ["direct", "adjoint"])
def test_partials_match_openmdao_finite_differences_and_one_simulation_serves_both(method: str) -> None:
    prob, comp = truss_problem((380.0, 430.0, 210.0), method)
    prob.run_model()
    assert comp.n_simulations == 1
    totals = prob.compute_totals(["truss.mass", "truss.stress_ks", "truss.buckling_ks"],
                                 [f"truss.{n}" for n in NAMES])
    assert comp.n_simulations == 1                  # compute_partials reused the run of compute
    assert (comp.counters.get("backward_solves", 0) > 0) == (method == "adjoint")   # the case's mode ran
    assert all(np.all(np.isfinite(v)) for v in totals.values())
    # OpenMDAO's central differences, step 0.1 mm² on 200-430 mm² areas: truncation ~ (h/A)² < 1e-6
    # relative, Newton's residual tolerance over h well below; agreement to 1e-5 relative
    data = prob.check_partials(method="fd", form="central", step=0.1, out_stream=None)
    assert_check_partials(data, atol=1e-10, rtol=1e-5)
    # and the check is not empty: the stress ratio depends on every area
    (_, d), = data.items()
    assert np.all(np.abs(d["stress_ks", "A_web"]["J_fwd"]) > 0)


def test_scipy_optimize_driver_reaches_the_dynsens_optimum(tmp_path: Path) -> None:
    case = load_case(TRUSS)
    ours = optimize_case(case, tmp_path / "opt.h5", workers=1).best_outcome
    assert ours.success and ours.feasible
    prob = om.Problem()
    comp = prob.model.add_subsystem("truss", CaseComponent(case=TRUSS))
    f0 = simulate(case).values["mass"]          # dynsens normalizes the objective by f(x0)
    add_case_driver_variables(prob.model, "truss", comp, ref={"mass": f0})
    prob.driver = om.ScipyOptimizeDriver(optimizer="SLSQP", tol=case.optimization.ftol,
                                         maxiter=case.optimization.maxiter, disp=False)
    prob.setup()
    prob.run_driver()
    assert prob.driver.result.success, prob.driver.result.message
    x_om = np.array([prob.get_val(f"truss.{n}")[0] for n in NAMES])
    # the same optimum: mass within 1e-6 (measured 1.1e-8 apart), both constraints active.  The
    # areas agree to the optimizer's tolerance, not to round-off: the two SLSQP runs scale the
    # problem with different arithmetic (OpenMDAO's ref, dynsens's bounds), their first steps
    # already differ in the last bits (one lands exactly on a bound, the other 2e-11 above it), and
    # the mass is flat along the two active constraints there: the areas end 2e-5 apart (measured;
    # 2.5e-10 apart only while a multi-threaded BLAS happened to round both alike)
    np.testing.assert_allclose(x_om, ours.x, rtol=1e-4)
    assert prob.get_val("truss.mass")[0] == pytest.approx(ours.f, rel=1e-6)
    assert prob.get_val("truss.stress_ks")[0] == pytest.approx(1.0, abs=1e-4)
    assert prob.get_val("truss.buckling_ks")[0] == pytest.approx(1.0, abs=1e-4)


def readme_openmdao_block() -> str:
    """The Python block of the docs' OpenMDAO section (docs/python-api.md; was in the README)."""
    text = (REPO / "docs" / "python-api.md").read_text(encoding="utf-8")
    section = text.split("## Using dynsens from OpenMDAO", 1)[1]
    return section.split("```python\n", 1)[1].split("```", 1)[0]


def test_example_couples_two_load_cases_with_a_cost_model(capsys, monkeypatch) -> None:
    ns = runpy.run_path(str(REPO / "scripts" / "openmdao_example.py"))
    prob = ns["main"]()
    out = capsys.readouterr().out
    assert "cost:" in out and "severe: stress_ks" in out
    x = np.array([prob.get_val(f"areas.{n}")[0] for n in NAMES])
    mass = prob.get_val("nominal.mass")[0]
    assert prob.get_val("cost.cost")[0] == pytest.approx(3000.0 * mass + 0.01 * x.sum(), rel=1e-12)
    # the severe load case governs: its limits are active, the nominal ones satisfied with margin
    for c in ("stress_ks", "buckling_ks"):
        assert prob.get_val(f"severe.{c}")[0] == pytest.approx(1.0, abs=1e-4)
        assert prob.get_val(f"nominal.{c}")[0] < 0.95
    # both components saw the same areas
    for n in NAMES:
        assert prob.get_val(f"nominal.{n}")[0] == prob.get_val(f"severe.{n}")[0]
    # the docs' block is the same model: it reaches the same design
    monkeypatch.chdir(REPO)
    readme: dict = {}
    exec(compile(readme_openmdao_block(), "docs/python-api.md", "exec"), readme)
    np.testing.assert_allclose([readme["prob"].get_val(f"areas.{n}")[0] for n in NAMES], x, rtol=1e-8)


def test_unknown_response_is_a_clear_error() -> None:
    prob = om.Problem()
    prob.model.add_subsystem("truss", CaseComponent(case=TRUSS, responses=["mass", "nope"]))
    with pytest.raises(ValueError, match=r"truss_lightweight.yaml: responses \['nope'\] are not in the case"):
        prob.setup()


def test_missing_openmdao_names_the_extra(monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "openmdao.api", None)        # import openmdao.api now fails
    monkeypatch.delitem(sys.modules, "dynsens.openmdao")
    with pytest.raises(ImportError, match=r"pip install 'dynsens\[openmdao\]'"):
        importlib.import_module("dynsens.openmdao")
    monkeypatch.undo()
    importlib.import_module("dynsens.openmdao")
