"""The second hostile campaign (issue 37): one test per defect class, each failing before its fix.

Bad input gets one clear error naming the key path, what was expected and what was found;
never a traceback or a silently wrong result.
"""
from __future__ import annotations

import copy

import numpy as np
import pytest

import dynsens
from dynsens import CaseError
from dynsens.case.load import load_case_dict
from dynsens.errors import DesignError
from test_beams import cantilever, portal_frame


def _problems(raw: dict) -> list[tuple[str, str]]:
    with pytest.raises(CaseError) as err:
        load_case_dict(copy.deepcopy(raw))
    return [(p.path, p.message) for p in err.value.problems]


@pytest.mark.parametrize("section, dim", [
    ({"shape": "tube", "D": 60.0, "t": 31.0}, 2),
    ({"shape": "box", "b": 20.0, "h": 50.0, "t": 10.5}, 2),
    ({"shape": "box", "b": 80.0, "h": 20.0, "t": 10.5}, 2),
    ({"shape": "tube", "D": 60.0, "t": 31.0}, 3),
    ({"shape": "box", "b": 20.0, "h": 50.0, "t": 10.5}, 3),
])
def test_sections_that_cannot_exist(section: dict, dim: int) -> None:
    raw = cantilever(2, section=section)
    if dim == 3:
        raw["model"]["dim"] = 3
        for el in raw["model"]["elements"]:
            el["G"] = 80000.0
        raw["model"]["nodes"] = {n: {"coords": v["coords"] + [0.0], **({"fixed": "all"} if "fixed" in v else {})}
                                 for n, v in raw["model"]["nodes"].items()}
    found = _problems(raw)
    msgs = [m for p, m in found if p == "model.elements[0].section.t"]
    assert msgs and "expected a wall t <=" in msgs[0] and f"found t = {section['t']:g}" in msgs[0], found
    # a solid section (walls that just meet) exists
    solid = dict(section, t=min(v for k, v in section.items() if k in ("D", "b", "h")) / 2)
    ok = copy.deepcopy(raw)
    for el in ok["model"]["elements"]:
        el["section"] = dict(solid)
    load_case_dict(ok)


def test_sections_that_cannot_exist_during_optimization() -> None:
    """A design the optimizer reaches where a tube's wall passes its radius is a failed evaluation."""
    case = load_case_dict(portal_frame())
    x = case.x0.copy()
    x[case.design_names.index("D")] = 9.0                     # t = 5 > D/2
    with pytest.raises(DesignError, match=r"model\.elements\[0\]\.section\.t: expected a wall t <= D/2"):
        dynsens.run_case(case, x)
