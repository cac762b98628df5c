"""Defects of the second hostile campaign (issue 37) in inputs, the API and messages, each with the
check that failed before its fix."""
from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("budget", [".inf", "1e300", "1e400"])
def test_an_infinite_or_overflowing_memory_budget_is_one_error(budget: str) -> None:
    from dynsens.case.load import load_case
    from dynsens.errors import CaseError
    with pytest.raises(CaseError, match="sensitivity.memory_budget: expected a positive size"):
        load_case(REPO / "cases" / "sdof_step.yaml", [f"sensitivity.memory_budget={budget}",
                                                     "sensitivity.method=adjoint"])


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
