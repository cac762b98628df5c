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
