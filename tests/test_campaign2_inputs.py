"""Defects of the second hostile campaign (issue 37) in inputs, the API and messages, each with the
check that failed before its fix."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def test_every_test_file_a_docstring_cites_exists() -> None:
    """Docstrings cited tests/test_adjoint_checkpoints.py and tests/test_tridiagonal.py, which
    never existed."""
    cited: dict[str, set[str]] = {}
    for path in sorted((REPO / "dynsens").rglob("*.py")):
        for name in re.findall(r"tests/(test_\w+\.py)", path.read_text(encoding="utf-8")):
            cited.setdefault(name, set()).add(str(path.relative_to(REPO)))
    assert cited, "the scan found no citation at all"
    missing = {name: sorted(where) for name, where in cited.items() if not (REPO / "tests" / name).exists()}
    assert not missing, missing


def test_a_family_named_like_an_expression_constant_is_refused() -> None:
    from dynsens.case.load import load_case_dict
    from dynsens.errors import CaseError
    raw = {"name": "t",
           "design": {"families": [{"name": "pi", "type": "spring", "value": 100.0, "lower": 10.0, "upper": 400.0,
                                    "assign": {"k": "2*pi"}}]},
           "model": {"type": "structural", "dofs": ["u"],
                     "elements": [{"type": "mass", "name": "m", "dof": "u", "mass": 2.0},
                                  {"type": "spring", "name": "s", "dofs": ["u", "ground"], "k": 1.0}],
                     "loads": [{"dof": "u", "value": 1.0, "function": "constant"}]},
           "integrator": {"dt": 0.01, "t_end": 0.1},
           "responses": [{"name": "u", "type": "value", "quantity": {"dof": "u"}}]}
    with pytest.raises(CaseError, match=r"design.families\[0\].name: .*constant pi"):
        load_case_dict(raw)


@pytest.mark.parametrize("budget", [".inf", "1e300", "1e400"])
def test_an_infinite_or_overflowing_memory_budget_is_one_error(budget: str) -> None:
    from dynsens.case.load import load_case
    from dynsens.errors import CaseError
    with pytest.raises(CaseError, match="sensitivity.memory_budget: expected a positive, finite size"):
        load_case(REPO / "cases" / "sdof_step.yaml", [f"sensitivity.memory_budget={budget}",
                                                     "sensitivity.method=adjoint"])


@pytest.mark.parametrize("kwargs, error, needle", [
    ({"history": "q"}, TypeError, "history: expected a sequence"),
    ({"history": ["q", "velocity"]}, ValueError, "unknown field"),
    ({"sensitivities": "no"}, TypeError, "sensitivities: expected True, False or None"),
])
def test_the_api_refuses_arguments_it_would_misread(kwargs: dict, error: type, needle: str) -> None:
    import dynsens
    with pytest.raises(error, match=needle):
        dynsens.simulate(REPO / "cases" / "sdof_step.yaml", **kwargs)


@pytest.mark.parametrize("rtol", [float("nan"), float("inf"), -1e-6, 0.0])
def test_a_gradient_report_refuses_a_tolerance_that_is_not_a_positive_number(rtol: float) -> None:
    import dynsens
    report = dynsens.check_gradients(REPO / "cases" / "sdof_step.yaml", steps=(1e-6,), workers=1,
                                     integrator__t_end=0.2)
    assert report.passes(1e-4)
    with pytest.raises(ValueError, match="rtol: expected a finite number > 0"):
        report.passes(rtol)


def test_a_dimensionless_bound_prints_without_a_dash() -> None:
    from dynsens.optimize.summary import _u
    assert _u("-") == "" and _u("1") == "" and _u("MPa") == " MPa"


def test_convergence_keeps_a_case_name_with_a_path_inside_its_folder(tmp_path: Path) -> None:
    from click.testing import CliRunner

    import dynsens.cli.convergence  # noqa: F401
    from dynsens.cli.main import cli
    out = tmp_path / "deep" / "out"
    r = CliRunner().invoke(cli, ["convergence", str(REPO / "cases" / "sdof_step.yaml"), "--set", "name=../../evil",
                                 "--set", "integrator.t_end=0.5", "--dt", "0.04,0.02", "--methods", "ddm-forward",
                                 "-o", str(out)])
    assert r.exit_code == 0, r.output
    written = [p for p in tmp_path.rglob("*") if p.is_file()]
    assert written and all(out in p.parents for p in written)
    r = CliRunner().invoke(cli, ["convergence", str(REPO / "cases" / "sdof_step.yaml"), "--set",
                                 "integrator.t_end=0.5", "--dt", "1", "-o", str(tmp_path / "b")])
    assert r.exit_code == 2 and "integrator.dt" in r.output


def test_the_dropped_redundant_equations_are_named_in_the_summary_and_the_file(tmp_path: Path) -> None:
    """Reversing model.joints in cases/bricard.yaml moved J1_force_ks from 36.23 N to 47.21 N and
    nothing said which equation had been dropped."""
    import json

    import h5py
    from click.testing import CliRunner

    import dynsens.cli.simulate  # noqa: F401
    from dynsens.cli.main import cli
    out = tmp_path / "b.h5"
    r = CliRunner().invoke(cli, ["simulate", str(REPO / "cases" / "bricard.yaml"), "-o", str(out),
                                 "--set", "integrator.t_end=0.02", "--no-sensitivities"])
    assert r.exit_code == 0, r.output
    assert "redundant joint equations left out of Phi:" in r.output and "order in the file" in r.output
    with h5py.File(out, "r") as f:
        dropped = json.loads(f.attrs["redundant_equations"])
    assert dropped and all("." in d for d in dropped)
    assert any(d in r.output for d in dropped)
