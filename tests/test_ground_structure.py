"""The ground-structure case (scripts/make_ground_structure.py, cases/ground_structure.yaml).

* the generator's bar set: every node pair within reach, none overlapping another;
* a small ground structure from the same generator optimized end to end by MMA for a few
  iterations: mass falls, the members at the lower bound are reported as removed in the file;
* the adjoint gradient of the constraints (stress KS, buckling KS, tip KS) against central
  differences of the whole run in random directions, on the small case and on the shipped
  2,252-member case over a few steps;
* the same under two load cases (``--two-loads``, cases/ground_structure_two_loads.yaml): the
  shipped file is the generator's, each load case's adjoint gradient against central
  differences, and MMA over both load cases on the small one.
"""
from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

import dynsens
from dynsens.api import as_case
from dynsens.case.load import Case
from dynsens.case.load_cases import load_case_set
from dynsens.optimize.summary import removed_members

from scripts_path import ground_structure, two_load_cases

CASE = Path(__file__).resolve().parent.parent / "cases" / "ground_structure.yaml"
TWO_LOADS = CASE.with_name("ground_structure_two_loads.yaml")
CONSTRAINTS = ("stress_ks", "buckling_ks", "tip_ks")


def bars(case: dict) -> list[dict]:
    return [e for e in case["model"]["elements"] if e["type"] == "bar"]


def test_the_generator_writes_every_non_overlapping_bar_within_reach() -> None:
    case = ground_structure(nx=4, ny=3, reach=1)
    # reach 1 on a 4 x 3 grid: 3·3 horizontal + 4·2 vertical + 2·(3·2) diagonal bars, less the two
    # vertical bars along the supported edge
    assert len(bars(case)) == 9 + 8 + 12 - 2
    case = ground_structure(nx=3, ny=3, reach=2)
    ends = {tuple(b["nodes"]) for b in bars(case)}
    assert ("n0_0", "n2_0") not in ends and ("n0_0", "n2_1") in ends    # (2, 0) overlaps two bars; (2, 1) not
    with pytest.raises(ValueError, match="reach"):
        ground_structure(nx=3, ny=3, reach=0)


def test_the_shipped_case_is_the_generator_output() -> None:
    shipped = yaml.safe_load(CASE.read_text())
    assert shipped == ground_structure()
    assert len(bars(shipped)) >= 2000


def test_the_shipped_two_load_case_is_the_generator_output() -> None:
    shipped = yaml.safe_load(TWO_LOADS.read_text())
    assert shipped == two_load_cases(ground_structure())
    assert shipped["model"] == ground_structure()["model"] and list(shipped["load_cases"]) == ["impact", "push"]


def _directional_check(raw: dict | Case, directions: int, h: float, rtol: float,
                       names: tuple[str, ...] = CONSTRAINTS) -> None:
    """Adjoint gradient of the constraints against central differences along random directions."""
    case = raw if isinstance(raw, Case) else as_case(raw)
    x0 = case.x0
    sim = dynsens.simulate(case, history=())
    rng = np.random.default_rng(34)
    for _ in range(directions):
        d = rng.uniform(-1.0, 1.0, x0.size) * x0          # a relative perturbation of every area
        plus = dynsens.simulate(case, x0 + h * d, sensitivities=False, history=()).values
        minus = dynsens.simulate(case, x0 - h * d, sensitivities=False, history=()).values
        for name in names:
            fd = (plus[name] - minus[name]) / (2 * h)
            adj = float(np.asarray(sim.gradients[name]) @ d)
            assert adj == pytest.approx(fd, rel=rtol, abs=1e-9 * abs(sim.values[name])), name


def test_adjoint_gradient_of_a_small_ground_structure() -> None:
    raw = ground_structure(nx=5, ny=3, reach=2, t_end=0.02)
    assert raw["sensitivity"]["method"] == "adjoint"
    _directional_check(raw, directions=3, h=1e-4, rtol=2e-4)


def test_adjoint_gradient_of_the_shipped_case_over_a_few_steps() -> None:
    raw = yaml.safe_load(CASE.read_text())
    raw["integrator"]["t_end"] = 3 * raw["integrator"]["dt"]
    _directional_check(raw, directions=2, h=1e-4, rtol=2e-4)


def test_adjoint_gradient_of_a_small_ground_structure_in_both_load_cases() -> None:
    cases = load_case_set(two_load_cases(ground_structure(nx=5, ny=3, reach=2, t_end=0.02)))
    impact, push = cases.case("impact"), cases.case("push")
    # the push is horizontal, towards the support: the grid is symmetric about the tip's height, so
    # the tip's vertical deflection vanishes at the uniform start design (its KS is the ln(N)/rho
    # floor and its gradient round-off, 1e-11 by differences: not checked there)
    tip = {n: dynsens.simulate(c, sensitivities=False, history=()).values["tip_ks"] for n, c in cases.cases.items()}
    assert tip["push"] < 0.2 * tip["impact"]
    _directional_check(impact, directions=2, h=1e-4, rtol=2e-4)
    _directional_check(push, directions=2, h=1e-4, rtol=2e-4, names=("stress_ks", "buckling_ks"))


def test_mma_over_two_load_cases_reduces_the_mass_and_holds_in_both(tmp_path: Path) -> None:
    raw = two_load_cases(ground_structure(nx=5, ny=3, reach=2, t_end=0.02))
    raw["optimization"]["verification"] = {"enabled": False}
    out = tmp_path / "gs2_opt.h5"
    res = dynsens.optimize(raw, out, maxiter=8)
    assert res.nit >= 5 and res.fun < 0.95 * res.history["f"][0]
    with h5py.File(out, "r") as f:
        assert {"impact", "push"} <= set(f["optimization/load_cases"])
        assert "removed" in f["optimization/summary"]


def test_mma_reduces_the_mass_and_reports_the_removed_members(tmp_path: Path) -> None:
    raw = ground_structure(nx=5, ny=3, reach=2, t_end=0.02)
    raw["optimization"]["verification"] = {"enabled": False}
    out = tmp_path / "gs_opt.h5"
    res = dynsens.optimize(raw, out, maxiter=8)
    assert res.nit >= 5
    assert res.fun < 0.95 * res.history["f"][0]
    with h5py.File(out, "r") as f:
        s = f["optimization/summary"]
        stored = sorted(m.decode() for m in s["removed/A"][()])
    case = as_case(raw)
    names, lower = list(case.design_names), case.lower
    expected = removed_members(names, np.asarray(res.x), lower, case.upper)["A"]
    assert stored == sorted(expected)
    # the removed members are exactly those at the lower bound
    at_lower = {n[2:-1] for n, x, lo in zip(names, res.x, lower) if x <= lo * (1 + 1e-6)}
    assert set(stored) == at_lower


def test_removed_members_are_the_family_members_at_the_lower_bound() -> None:
    names = ["k", "A[b1]", "A[b2]", "A[b3]", "B[c1]"]
    x = np.array([0.0, 1.0, 1.0 + 1e-9, 5.0, 2.0])
    lower, upper = np.array([0.0, 1.0, 1.0, 1.0, 1.0]), np.array([9.0, 3000.0, 3000.0, 3000.0, 3.0])
    # k is no family member; b2 lies within 1e-6 of the range above the bound: at it; B keeps its one
    assert removed_members(names, x, lower, upper) == {"A": ["b1", "b2"], "B": []}
