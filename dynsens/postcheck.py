"""Post-check of a sized truss: every member's stress and buckling ratio at every stored step.

An aggregate constraint (KS or sampled maximum) bounds the largest ratio; this check does not
trust it: it runs the design once more, keeps the displacement history and evaluates, member
by member and step by step, σ/σ_t, −σ/σ_c and −N/P_E (P_E = π²EI/(KL)², bars with
``inertia``).  The limits are read from the case's ``stress_ratio`` responses.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import yaml

from .case.load import Case
from .errors import CaseError, ProblemCollector
from .models.base import StepState
from .models.structural import StructuralModel
from .simulation import run_case


@dataclass
class MemberCheck:
    """Largest ratios per member over all stored steps (N steps, n_e members).

    tension, compression, buckling : (n_e,) largest σ/σ_t, −σ/σ_c, −N/P_E (NaN: not checked).
    """

    names: tuple[str, ...]
    tension: np.ndarray
    compression: np.ndarray
    buckling: np.ndarray
    steps: int

    @property
    def largest(self) -> float:
        """The largest ratio of any member, any kind, any stored step."""
        return float(np.nanmax(np.concatenate([self.tension, self.compression, self.buckling])))

    def worst(self) -> tuple[str, str, float]:
        """(member, kind, ratio) of the largest ratio."""
        table = {"tension": self.tension, "compression": self.compression, "buckling": self.buckling}
        kind = max(table, key=lambda k: np.nanmax(table[k]) if np.isfinite(table[k]).any() else -np.inf)
        i = int(np.nanargmax(table[kind]))
        return self.names[i], kind, float(table[kind][i])

    def count_above(self, limit: float) -> int:
        """How many members have a ratio of any kind above ``limit``."""
        stacked = np.vstack([self.tension, self.compression, self.buckling])
        return int(np.sum(np.nanmax(np.where(np.isfinite(stacked), stacked, -np.inf), axis=0) > limit))

    def passes(self, tol: float = 1e-3) -> bool:
        """Every ratio <= 1 + tol."""
        return self.largest <= 1.0 + tol


def stress_limits(case: Case) -> tuple[float | None, float | None]:
    """(σ_t, σ_c) of the case's ``stress_ratio`` responses (the smallest of each; None: none)."""
    limits: dict[str, list[float]] = {"tension_limit": [], "compression_limit": []}
    for r in (yaml.safe_load(case.text) or {}).get("responses", []) or []:
        if isinstance(r, dict) and r.get("type") == "stress_ratio":
            for key in limits:
                value = r.get(key, r.get("limit"))
                if value is not None:
                    limits[key].append(float(value))
    return (min(limits["tension_limit"], default=None), min(limits["compression_limit"], default=None))


def check_members(case: Case, x: Any = None, *, tension_limit: float | None = None,
                  compression_limit: float | None = None, buckling: bool = True,
                  result: Any = None) -> MemberCheck:
    """Run ``case`` at design ``x`` (default x0) and return every bar's largest ratios.

    Limits default to the case's ``stress_ratio`` responses (MPa in the shipped cases);
    ``buckling`` checks bars that declare ``inertia``.  ``result``: a run of ``case`` at ``x``
    that stored the displacement history ``q`` (default: run it here).
    """
    x = case.x0 if x is None else np.asarray(x, dtype=float)
    st, sc = stress_limits(case)
    tension_limit = tension_limit if tension_limit is not None else st
    compression_limit = compression_limit if compression_limit is not None else sc
    model = case.model
    if not isinstance(model, StructuralModel) or not model.bar_names:
        raise CaseError("the post-check needs a structural model with bars", case.source)
    names = tuple(model.bar_names)
    res = result if result is not None else run_case(case, x, sensitivities=False, history=("q",))
    if "q" not in res.history:
        raise ValueError("the post-check needs a run that stored the displacement history 'q'")
    params = model.parameters(x)
    pc = ProblemCollector(case.source)
    q = res.history["q"]
    zeros = np.zeros_like(q)
    states = StepState(q, zeros, zeros, np.zeros((len(q), 0)), np.zeros((len(q), 0)), np.zeros((len(q), 0)))
    nan = np.full(len(names), np.nan)

    def evaluate(kind: str) -> np.ndarray:
        out = model.output({"element": list(names), "kind": kind}, "post-check", pc)
        pc.raise_if_any()
        assert out is not None
        return np.real(np.asarray(out.fn(0.0, states, params)))      # (steps, n_e)

    sigma = evaluate("stress")
    tension = sigma.max(axis=0) / tension_limit if tension_limit else nan
    compression = -sigma.min(axis=0) / compression_limit if compression_limit else nan
    has_inertia = np.asarray(model.bar_I) >= 0
    ratio = nan.copy()
    if buckling and has_inertia.any():
        P = np.real(params["P_euler"])
        N = evaluate("force")
        ratio = np.where(has_inertia, (-N / P).max(axis=0), np.nan)
    return MemberCheck(names, tension, compression, ratio, len(q))
