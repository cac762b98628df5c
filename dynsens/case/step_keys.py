"""The case keys of adaptive time steps, ``integrator.adaptive`` (kept apart from the loader so
that it stays one place to read)."""
from __future__ import annotations

from typing import Any

from ..case_keys import allowed
from ..errors import ProblemCollector
from ..integrators.newmark import Newmark
from ..models._keys import check_keys
from ..timeloop.step_sequence import AdaptiveSettings, adaptive_problem
from .responses_spec import read_number

PATH = "integrator.adaptive"


def adaptive_settings(spec: Any, dt: float | None, t0: float | None, t_end: float | None,
                      scheme: Newmark | None, pc: ProblemCollector) -> AdaptiveSettings | None:
    """``integrator.adaptive`` (None when absent); problems are reported under their key paths:
    tolerances positive, 0 < dt_min < dt_max, and a scheme whose local error the estimate measures."""
    if spec is None:
        return None
    if not check_keys(spec, PATH, allowed(PATH), pc):
        return None
    rtol = read_number(spec.get("rtol", 1e-4), f"{PATH}.rtol", pc, positive=True)
    atol = read_number(spec.get("atol", 1e-8), f"{PATH}.atol", pc, positive=True)
    if dt is None or t0 is None or t_end is None:
        return None
    dt_min = read_number(spec.get("dt_min", 1e-6 * dt), f"{PATH}.dt_min", pc, positive=True)
    dt_max = read_number(spec.get("dt_max", t_end - t0), f"{PATH}.dt_max", pc, positive=True)
    if dt_min is not None and dt_max is not None and dt_min >= dt_max:
        pc.add(f"{PATH}.dt_min", f"expected less than dt_max = {dt_max:g} s, found {dt_min:g} s")
    if scheme is not None and (why := adaptive_problem(scheme)):
        pc.add(PATH, why)
    if None in (rtol, atol, dt_min, dt_max) or pc.problems:
        return None
    assert rtol is not None and atol is not None and dt_min is not None and dt_max is not None
    return AdaptiveSettings(rtol, atol, dt_min, dt_max)
