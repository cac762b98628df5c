"""The verification of an optimum beyond the run that computed it (dynsens.optimize.verify).

Contract (issue 34): after ``dynsens optimize`` the optimum is run again at half the step and on a
window extended until the constrained peaks settle; every constraint and every member is checked
there; a violation or a peak in the last part of the window is reported, in the summary and in
the file; ``optimization.verification.rounds`` tightens failing bounds by the measured excess
until the optimum passes; ``dynsens verify`` does the same for any design.
"""
from __future__ import annotations

import copy
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import dynsens.cli.optimize  # noqa: F401  (registers the command)
import dynsens.cli.verify  # noqa: F401
from dynsens.case.load import load_case, load_case_dict
from dynsens.cli.main import cli
from dynsens.errors import CaseError
from dynsens.optimize.verify import verify_design
from dynsens.postcheck import check_members
from helpers import SDOF_DESIGN

REPO = Path(__file__).resolve().parents[1]
TRUSS = REPO / "cases" / "truss_lightweight.yaml"
TOWER_TEXT = (REPO / "cases" / "tower_sizing.yaml").read_text()

def invoke(*args: object):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


def old_tower():  # type: ignore[no-untyped-def]
    """The tower as it was formulated before: a 0.1 s window, no tightening rounds."""
    raw = yaml.safe_load(TOWER_TEXT)
    raw["integrator"]["t_end"] = 0.1
    raw["optimization"].pop("verification", None)
    return load_case_dict(raw, "tower_sizing.yaml")


def test_the_old_tower_optimum_fails_beyond_its_window() -> None:
    """The regression the verification exists for: the tower, sized on 0.1 s, rings on; run to
    the settled horizon a lower diagonal buckles (ratio > 1.1) though every constraint held."""
    record = yaml.safe_load((REPO / "tests" / "data" / "tower_optimum_0.1s.yaml").read_text())
    case = old_tower()
    x = np.array([record[n] for n in case.design_names])
    v = verify_design(case, x)
    assert not v.passed
    assert v.members["case"].largest <= 1.0 + 1e-3                 # it passed the old post-check
    assert v.members["horizon"].largest > 1.1                       # and fails after the window
    member, kind, _ = v.members["horizon"].worst()
    assert kind == "buckling" and member.startswith("diag1")
    horizon = [r for r in v.runs if r.name == "horizon"][0]
    assert 0.2 <= horizon.t_end <= 0.5                              # extended until the peaks settled
    bad = {c.response for c in v.constraints if c.status == "violated"}
    assert "buckling_diag1" in bad
    assert v.members["refined"].largest > 1.0 + 1e-3                # and at half the step, too


def sdof_late_peak(t_end: float) -> dict:
    """SDOF under a slow ramp: the displacement still rises when the window ends."""
    raw = copy.deepcopy(SDOF_DESIGN)
    raw["model"]["loads"] = [{"dof": "u", "value": 10.0, "function": {"type": "ramp", "t0": 0.0, "t1": 2.0}}]
    raw["integrator"]["t_end"] = t_end
    raw["responses"][0] = {"name": "q_max", "type": "max", "quantity": {"dof": "u", "kind": "displacement"}}
    raw["optimization"]["constraints"] = [{"response": "q_max", "upper": 0.09}]
    return raw


def test_a_peak_at_the_end_of_the_window_is_reported_and_judged_on_the_longer_window() -> None:
    case = load_case_dict(sdof_late_peak(1.0))                     # the ramp ends after the window
    v = verify_design(case, case.x0, horizon=None)
    (c,) = v.constraints
    assert c.status == "late peak" and "last 10 %" in c.note
    assert v.passed                                                 # a warning: nothing shows it fails
    v = verify_design(case, case.x0)                                # auto: the window is extended
    (c,) = v.constraints
    assert c.values["case"] < 0.09 < c.values["horizon"] and c.status == "violated"
    assert not v.passed


def test_a_constraint_that_moves_at_half_the_step_fails_and_a_ks_is_judged_by_its_peak() -> None:
    case = load_case_dict(SDOF_DESIGN)
    v = verify_design(case, case.x0)
    (c,) = v.constraints
    # the KS at dt/2 sums twice the samples and would rise by up to ln(2)/rho with no larger peak:
    # the refined run is judged by its sampled maximum
    run = load_case_dict(SDOF_DESIGN, overrides=["integrator.dt=0.005"])
    from dynsens.simulation import run_case
    refined = run_case(run, sensitivities=False, history=())
    assert c.values["refined"] == pytest.approx(refined.responses["q_ks"].extra["sampled_max"], rel=1e-12)
    assert c.values["refined"] < float(refined.responses["q_ks"].value)


def test_truss_is_tightened_until_its_optimum_holds_at_a_quarter_of_the_step(tmp_path: Path) -> None:
    out = tmp_path / "opt.h5"
    r = invoke("optimize", TRUSS, "-o", out)
    assert r.exit_code == 0, r.output
    assert "verification of the optimum:" in r.output and "VIOLATED" in r.output     # round 0 fails
    assert "round 1" in r.output and "verified: the optimum passes the verification" in r.output
    with h5py.File(out, "r") as f:
        g = f["verification"]
        assert bool(g.attrs["passed"])
        bounds = g["rounds/bounds"][()]
        assert bounds.shape[0] >= 2 and bounds[-1, 0] < 1.0 and bounds[0, 0] == 1.0   # stress_ks tightened
        assert list(g["runs/name"].asstr()[()]) == ["case", "refined", "horizon", "tail"]
        x = np.asarray(g.attrs["x"])
    # an independent check, finer than the verification itself: every member at dt/4
    fine = load_case(TRUSS, ["integrator.dt=0.000125"])
    chk = check_members(fine, x)
    assert chk.passes(1e-3), chk.worst()
    assert chk.largest > 0.97                                       # not over-sized either


def test_verify_command_checks_a_recorded_optimum(tmp_path: Path) -> None:
    out = tmp_path / "opt.h5"
    assert invoke("optimize", TRUSS, "-o", out, "--no-verify").exit_code == 0
    with h5py.File(out, "r") as f:
        assert "verification" not in f
    r = invoke("verify", TRUSS, "--from", out)
    assert r.exit_code == 1 and "does NOT pass" in r.output and "stress_ks" in r.output
    r = invoke("verify", TRUSS)                                     # the start design holds
    assert r.exit_code == 0 and "PASSES" in r.output
    r = invoke("verify", TRUSS, "--horizon", "soon")
    assert r.exit_code == 2 and "--horizon" in r.output
    r = invoke("verify", TRUSS, "--horizon", "0.01")                # before t_end
    assert r.exit_code == 2 and "beyond t_end" in r.output


def test_verify_command_on_a_small_case(tmp_path: Path) -> None:
    """`dynsens verify` in a second or two (the truss test above is in the slow list): the two-bar
    truss (stress ratio 0.57 at the start design) passes, a design with a tenth of the area
    (ratio ~5.7) does not, an optimum recorded by `optimize` is read back with --from, and a file
    that is not an optimization is refused with exit 2."""
    shape = REPO / "cases" / "two_bar_shape.yaml"
    r = invoke("verify", shape)
    assert r.exit_code == 0 and "PASSES" in r.output and "stress_ratio <= 1" in r.output
    r = invoke("verify", shape, "-x", "A=100")
    assert r.exit_code == 1 and "does NOT pass" in r.output
    out = tmp_path / "opt.h5"
    assert invoke("optimize", shape, "-o", out, "--no-verify").exit_code == 0
    with h5py.File(out, "r") as f:
        best = int(f["optimization/summary"].attrs["best"])
        h_opt = float(f[f"optimization/start_{best}"].attrs["x_opt"][0])
    r = invoke("verify", shape, "--from", out, "-v")
    assert r.exit_code in (0, 1) and "stress_ratio <= 1" in r.output
    ratio = float(r.output.split("stress_ratio <= 1")[1].split()[0])
    assert abs(ratio - 1.0) < 1e-4 and abs(h_opt - 1000.0) < 1.0     # on its bound, at H* = B
    not_opt = tmp_path / "run.h5"
    with h5py.File(not_opt, "w") as f:          # an HDF5 file, but no optimization in it
        f["time"] = np.zeros(3)
    r = invoke("verify", shape, "--from", not_opt)
    assert r.exit_code == 2 and "not a finished dynsens optimization file" in r.output


def test_verification_keys_are_checked() -> None:
    raw = copy.deepcopy(SDOF_DESIGN)
    raw["optimization"]["verification"] = {"refine": 1, "tail": 1.5, "horizn": "auto"}
    with pytest.raises(CaseError) as exc:
        load_case_dict(raw)
    text = str(exc.value)
    assert "optimization.verification" in text and "horizn" in text
    raw["optimization"]["verification"] = {"refine": 1, "tail": 1.5, "safety": 0.5}
    with pytest.raises(CaseError) as exc:
        load_case_dict(raw)
    text = str(exc.value)
    for key in ("refine", "tail", "safety"):
        assert f"optimization.verification.{key}" in text
