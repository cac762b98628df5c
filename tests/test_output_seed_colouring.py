"""The adjoint's output seeds colour their probes (dynsens/derivatives/output_seeds.py, issue 34).

Bars declare which DOFs and parameters each row of their outputs reads; the seeds step the state
components, and the design variables, on which no row depends together in one probe.  Shown:

* the adjoint gradient equals the direct one (complex-step partials: both exact to round-off) on a
  small ground structure (one area per bar) and on two sizing cases: the 2D Warren truss (three
  areas shared by families of bars: a design colour holds many rows per variable) and the 3D
  lattice tower (204 bars, one area each);
* it equals the uncoloured seeds (no declared pattern, one probe per state component and per
  design variable, as before the colouring) to round-off;
* the probes per instant are the colours: the same on a 5 × 3 and a 9 × 5 ground structure (56
  and 240 bars), where one probe per component and per variable grows with the bars.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

import dynsens
from dynsens.api import as_case
from dynsens.derivatives import output_seeds
from dynsens.models.structural.elements.bars import Bars

from scripts_path import ground_structure

CASES = Path(__file__).resolve().parent.parent / "cases"


def _small_ground_structure(nx: int = 5, ny: int = 3) -> dict:
    raw = ground_structure(nx=nx, ny=ny, reach=2, t_end=0.01)
    raw["sensitivity"]["partials"] = "complex"
    return raw


def _shipped(name: str, steps: int) -> dict:
    raw = yaml.safe_load((CASES / name).read_text())
    raw["integrator"]["t_end"] = steps * raw["integrator"]["dt"]
    raw["sensitivity"].update(partials="complex", method="adjoint")
    raw["responses"] = [r for r in raw["responses"] if r.get("aggregate") != "max"]
    return raw


CASES_UNDER_TEST = {
    "ground_structure_5x3": _small_ground_structure,
    "truss_lightweight": lambda: _shipped("truss_lightweight.yaml", 12),
    "tower_sizing_mma": lambda: _shipped("tower_sizing_mma.yaml", 4),
}


def _gradients(raw: dict, method: str = "adjoint") -> dict[str, np.ndarray]:
    raw = dict(raw, sensitivity=dict(raw["sensitivity"], method=method))
    res = dynsens.simulate(as_case(raw), history=())
    assert res.run.method == method
    return {k: np.asarray(v) for k, v in res.gradients.items()}


def _uncoloured(monkeypatch: pytest.MonkeyPatch) -> None:
    """The seeds as before the colouring: bars declare no pattern (found by probing) and every
    state component and design variable is probed alone."""
    monkeypatch.setattr(Bars, "output_reads", lambda self, index, kind: None)
    monkeypatch.setattr(output_seeds, "colour_columns", lambda pattern, m: None)


@pytest.mark.parametrize("name", list(CASES_UNDER_TEST))
def test_coloured_adjoint_equals_direct_and_the_uncoloured_seeds(name: str, monkeypatch: pytest.MonkeyPatch
                                                                 ) -> None:
    raw = CASES_UNDER_TEST[name]()
    adjoint = _gradients(raw)
    direct = _gradients(raw, "direct")
    for key, g in direct.items():
        scale = np.max(np.abs(g))
        assert scale > 0, key
        np.testing.assert_allclose(adjoint[key], g, rtol=0, atol=1e-10 * scale, err_msg=key)
    with monkeypatch.context() as patch:
        _uncoloured(patch)
        before = _gradients(raw)
    for key, g in before.items():
        np.testing.assert_allclose(adjoint[key], g, rtol=0, atol=1e-13 * np.max(np.abs(g)), err_msg=key)


def _probes(nx: int, ny: int, monkeypatch: pytest.MonkeyPatch) -> tuple[int, dict[int, Any], int]:
    """(output evaluations of the adjoint's seeds, their dependences by output, bars); the
    evaluations are at most the probes of every output at every instant (nothing is probed to
    find the patterns: the bars declare them)."""
    seen: list[output_seeds.OutputSeeds] = []
    init = output_seeds.OutputSeeds.__init__

    def kept(self: output_seeds.OutputSeeds, *args: Any) -> None:
        init(self, *args)
        seen.append(self)
    with monkeypatch.context() as patch:
        patch.setattr(output_seeds.OutputSeeds, "__init__", kept)
        raw = ground_structure(nx=nx, ny=ny, reach=2, t_end=0.005)
        case = as_case(raw)
        res = dynsens.simulate(case, history=())
    assert res.run.method == "adjoint" and len(seen) == 1
    assert res.counters["backward_output_evaluations"] == seen[0].evaluations
    instants = case.plan.n_steps + 1
    assert seen[0].evaluations <= instants * sum(dep.probes for dep in seen[0]._deps.values())
    return seen[0].evaluations, seen[0]._deps, case.x0.size


def test_the_probes_per_instant_are_the_colours_whatever_the_number_of_bars(monkeypatch: pytest.MonkeyPatch
                                                                            ) -> None:
    small, deps_small, bars_small = _probes(5, 3, monkeypatch)
    large, deps_large, bars_large = _probes(9, 5, monkeypatch)
    assert bars_large > 4 * bars_small
    # the same probes at the same instants: the count does not grow with the bars
    assert large == small
    for deps in (deps_small, deps_large):
        for dep in deps.values():
            # the state probes are the colours, far fewer than the components they step; the
            # design probes (forward differences) the unperturbed set and one colour
            assert dep.state.n <= 8
            assert len(dep.batch) in (0, 2)
    # the buckling output reads every area: each bar's own, one colour for all
    buckling = [d for d in deps_large.values() if d.design.cols.size]
    assert len(buckling) == 1 and buckling[0].design.cols.size == bars_large and buckling[0].design.n == 1
    assert buckling[0].state.cols.size == 80 and buckling[0].state.n == 8
