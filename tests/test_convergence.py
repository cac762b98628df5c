"""The work-precision study reports the schemes' orders and writes its tables and plots."""
import pytest
from click.testing import CliRunner

import dynsens
from dynsens.cli.main import cli
from dynsens.cli import convergence  # noqa: F401  (registers the command)
from dynsens.analysis.convergence import observed_order, work_precision
from conftest import CASES


@pytest.mark.parametrize("over,order", [([], 2.0),
                                        (["integrator.scheme=generalized_alpha", "integrator.rho_inf=0.8"], 2.0),
                                        (["integrator.gamma=0.6", "integrator.beta=0.3025"], 1.0)])
def test_observed_order_matches_scheme(over, order):
    case = dynsens.load_case(CASES / "sdof_step.yaml", ["integrator.t_end=2"] + over)
    rows, _, _ = work_precision(case, [0.02, 0.01, 0.005, 0.0025], ["ddm-complex"])
    assert observed_order(rows, "q_end") == pytest.approx(order, abs=0.15)
    assert observed_order(rows, "q_end", what="gradient") == pytest.approx(order, abs=0.15)


def test_command_writes_tables_and_plots(tmp_path):
    res = CliRunner().invoke(cli, ["convergence", str(CASES / "sdof_step.yaml"), "--set", "integrator.t_end=1",
                                   "--dt", "0.02,0.01,0.005", "--methods", "ddm-forward,fd-central,cs",
                                   "-o", str(tmp_path)])
    assert res.exit_code == 0, res.output
    names = {p.name for p in tmp_path.iterdir()}
    assert {"sdof_step_work_precision.md", "sdof_step_work_precision.csv",
            "sdof_step_q_end_work_precision.png"} <= names
    text = (tmp_path / "sdof_step_work_precision.md").read_text()
    assert "| 0.01 | fd-central |" in text
    bad = CliRunner().invoke(cli, ["convergence", str(CASES / "sdof_step.yaml"), "--methods", "magic",
                                   "-o", str(tmp_path)])
    assert bad.exit_code != 0 and "unknown methods" in bad.output


def test_a_ladder_without_ratio_two_says_its_reference_is_not_extrapolated(tmp_path):
    """--dt 0.03,0.02: the reference is the finest run itself (not Richardson-extrapolated). Its
    errors were reported as 0 and the orders as nan and 32.7, with the report claiming an
    extrapolated reference; now the command warns, the errors at the reference step are not
    shown, and no order is claimed from a single error."""
    res = CliRunner().invoke(cli, ["convergence", str(CASES / "sdof_step.yaml"), "--set", "integrator.t_end=0.05",
                                   "--dt", "0.03,0.02", "--methods", "ddm-forward", "-o", str(tmp_path)])
    assert res.exit_code == 0, res.output
    assert "warning: the reference is the finest run itself (Δt = 0.02 s" in res.output
    assert "observed order n/a (needs errors at two steps)" in res.output and "nan" not in res.output
    text = (tmp_path / "sdof_step_work_precision.md").read_text()
    assert "not extrapolated" in text and "Richardson-extrapolated from" not in text
    assert "| 0.02 | ddm-forward |" in text and "(reference)" in text
    ok = CliRunner().invoke(cli, ["convergence", str(CASES / "sdof_step.yaml"), "--set", "integrator.t_end=0.05",
                                  "--dt", "0.02,0.01", "--methods", "ddm-forward", "-o", str(tmp_path / "b")])
    assert ok.exit_code == 0 and "warning" not in ok.output
    report = (tmp_path / "b" / "sdof_step_work_precision.md").read_text()
    assert "Richardson-extrapolated from the two finest steps" in report
