"""Feedback: progress only on a terminal, -v/-q on every command, how a run ended, step cuts and
drift in the summary, check-gradients naming the failing responses and every fixed-time
response, simulate --plots."""
from __future__ import annotations

import io
import logging

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import dynsens
import dynsens.cli.check_gradients  # noqa: F401  (registers the command)
import dynsens.cli.convergence  # noqa: F401
import dynsens.cli.optimize  # noqa: F401
import dynsens.cli.simulate  # noqa: F401
from conftest import CASES
from dynsens.cli.main import cli
from dynsens.cli.options import configure_logging
from dynsens.derivatives.gradcheck import check_gradients
from dynsens.timeloop.progress import Progress, progress_enabled


class Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.fixture(autouse=True)
def default_logging():
    yield
    configure_logging(0, False)


def test_progress_is_quiet_without_a_terminal():
    pipe = io.StringIO()
    with Progress(100, "work", stream=pipe) as bar:
        for i in range(100):
            bar.update(i, force=True)
    assert pipe.getvalue() == ""


def test_progress_on_a_terminal_shows_an_estimate_and_clears_its_line():
    tty = Tty()
    with Progress(100, "work", stream=tty) as bar:
        bar.update(50, "half", force=True)
        shown = tty.getvalue()
    assert "work" in shown and "50 %" in shown and "left" in shown and "half" in shown
    assert tty.getvalue().endswith("\r")                        # cleared for the output that follows
    assert "left" not in Progress(None, "open-ended", stream=tty).line(3, "iteration 3")


def test_quiet_silences_progress_even_on_a_terminal():
    configure_logging(0, True)
    assert not progress_enabled(Tty())
    configure_logging(0, False)
    assert progress_enabled(Tty())


def test_cli_output_has_no_progress_lines(tmp_path):
    runner = CliRunner()
    r = runner.invoke(cli, ["simulate", str(CASES / "sdof_step.yaml"), "-o", str(tmp_path / "a.h5"),
                            "--set", "integrator.t_end=5"])
    assert r.exit_code == 0, r.output
    assert "\r" not in r.output and "simulating" not in r.output


@pytest.mark.parametrize("command", ["simulate", "check-gradients", "convergence", "optimize"])
def test_every_command_takes_verbose_and_quiet(command):
    r = CliRunner().invoke(cli, [command, "--help"])
    assert r.exit_code == 0 and "-v, --verbose" in r.output and "-q, --quiet" in r.output


def test_verbose_logs_through_the_logging_module(tmp_path, caplog):
    logger = logging.getLogger("dynsens")
    r = CliRunner().invoke(cli, ["simulate", str(CASES / "sdof_step.yaml"), "-o", str(tmp_path / "a.h5"),
                                 "--set", "integrator.t_end=1", "-vv"])
    assert r.exit_code == 0, r.output
    assert logger.level == logging.DEBUG
    assert "INFO: case sdof_step: 1000 steps" in r.stderr
    r = CliRunner().invoke(cli, ["-q", "simulate", str(CASES / "sdof_step.yaml"), "-o", str(tmp_path / "b.h5"),
                                 "--set", "integrator.t_end=1"])
    assert r.exit_code == 0 and logger.level == logging.ERROR and "INFO" not in r.stderr


def test_summary_says_which_event_ended_the_run_and_reports_cuts_and_drift(tmp_path):
    out = tmp_path / "pend.h5"
    r = CliRunner().invoke(cli, ["simulate", str(CASES / "pendulum_3d.yaml"), "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert r.output.startswith("status: ended by event far_side at t = ")
    assert dynsens.read_result(out).status == "terminated"                  # the file's contract
    assert "step cuts: 0" in r.output
    assert "constraint position drift: max " in r.output


def sdof_with_event() -> dynsens.Case:
    raw = yaml.safe_load((CASES / "sdof_step.yaml").read_text())
    raw["integrator"]["t_end"] = 1.0
    raw["events"] = [{"name": "E1", "quantity": {"dof": "u"}, "value": 0.3, "direction": "rising"}]
    raw["responses"] = [
        {"name": "v_end", "type": "value", "quantity": {"dof": "u", "kind": "velocity"}},
        {"name": "v_fixed", "type": "value", "quantity": {"dof": "u", "kind": "velocity"},
         "derivative": "fixed_time"},
        {"name": "g_fixed", "type": "expression", "expression": "v_fixed/2 - 1"},
        {"name": "t_E", "type": "event_time", "event": "E1"},
        {"name": "g_total", "type": "expression", "expression": "v_end + t_E"}]
    return dynsens.load_case_dict(raw, "sdof_event")


def test_check_gradients_treats_expressions_of_fixed_time_responses_as_fixed_time():
    rep = check_gradients(sdof_with_event(), [1e-6], workers=1)
    assert set(rep.fixed_time) == {"v_fixed", "g_fixed"}
    assert rep.best_rel_diff("g_fixed") > 1e-2                   # FD measure the total derivative
    assert rep.failing(1e-4) == [] and rep.passes(1e-4)
    assert rep.failing(1e-12) and "g_fixed" not in rep.failing(1e-12)
    assert rep.best_step("v_end") == 1e-6


def test_check_gradients_failure_names_the_responses(tmp_path):
    case = tmp_path / "sdof.yaml"
    raw = yaml.safe_load((CASES / "sdof_step.yaml").read_text())
    raw["integrator"]["t_end"] = 1.0
    case.write_text(yaml.safe_dump(raw))
    r = CliRunner().invoke(cli, ["check-gradients", str(case), "--steps", "1e-3", "--rtol", "1e-9",
                                 "--workers", "1"])
    assert r.exit_code == 1
    assert "gradient check FAILED at rtol = 1e-09: q_end (best relative difference" in r.stderr
    assert "q_ks (best relative difference" in r.stderr and "{" not in r.stderr


def test_progress_callbacks_count_every_simulation():
    seen = []
    check_gradients(sdof_with_event(), [1e-5, 1e-6], workers=1, progress=lambda d, n: seen.append((d, n)))
    assert seen == [(k, 8) for k in range(1, 9)]                # SA, primal, 2 steps × 3 variables


def test_simulate_plots_recorded_quantities(tmp_path):
    pytest.importorskip("matplotlib")
    r = CliRunner().invoke(cli, ["simulate", str(CASES / "tyrolean_weir.yaml"), "-o", str(tmp_path / "w.h5"),
                                 "--set", "integrator.t_end=0.05", "--no-sensitivities",
                                 "--plots", str(tmp_path / "plots")])
    assert r.exit_code == 0, r.output
    png = tmp_path / "plots" / "w.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20000
    from dynsens.plots import panels
    res = dynsens.read_result(tmp_path / "w.h5")
    assert [u for u, _ in panels({k: type("Q", (), {"unit": v})() for k, v in res.units.items()})] == \
        ["N", "mm", "MPa", "rad"]
    assert np.isfinite(res.quantities["cylinder_force"]).all()


def test_plot_markers_show_a_ks_of_a_recorded_quantity_as_a_level():
    from dynsens.plots import response_markers
    case = dynsens.load_case(CASES / "sdof_step.yaml", ["integrator.t_end=1.0"])
    result = dynsens.run_case(case)
    markers = {m.name: m for m in response_markers(case, result)}
    assert markers["q_ks"].t is None                                   # a level over the run
    assert markers["q_ks"].value == pytest.approx(float(result.responses["q_ks"].value))
    assert markers["q_end"].t == pytest.approx(1.0)                    # a point at the end
