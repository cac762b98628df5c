"""Post-check of a sized structure: every member's stress and stability ratios at every stored step.

An aggregate constraint (KS or sampled maximum) bounds the largest ratio; this check does not
trust it: it runs the design once more, keeps the displacement history and evaluates, member
by member and step by step,

* bars: σ/σ_t, −σ/σ_c and −N/P_E (P_E = π²EI/(KL)², bars with ``inertia``);
* beams (plane and 3D): the extreme-fibre stresses σ = N/A ± M/W at both ends, σ/σ_t and −σ/σ_c;
  the flexural buckling ratio −N/P_E (P_E with the beam's length, the weaker axis of a 3D beam);
  and the beam-column interaction u of AISC 360-16 Eq. H1-1a/b (:mod:`dynsens.responses.member_stability`).

The limits are read from the case's ``stress_ratio`` responses (σ_t, σ_c), ``buckling_ratio`` and
``interaction_ratio`` responses (the beams' K, the largest given; F_y and φ, the smallest given),
each overridable by a keyword.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import yaml

from .case.load import Case
from .errors import CaseError, ProblemCollector
from .expressions.restricted import compile_expression
from .responses.member_stability import MEMBER_COMPONENTS, buckling_scale, interaction_forms
from .models.base import StepState
from .models.structural.model import StructuralModel
from .simulation import run_case

KINDS = ("tension", "compression", "buckling", "interaction")


@dataclass
class MemberCheck:
    """Largest ratios per member over all stored steps (N steps, n_e members: bars, then beams).

    tension, compression, buckling, interaction : (n_e,) largest σ/σ_t, −σ/σ_c, −N/P_E and the
    beam-column interaction u (NaN: not checked; bars have no interaction).
    """

    names: tuple[str, ...]
    tension: np.ndarray
    compression: np.ndarray
    buckling: np.ndarray
    steps: int
    interaction: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        if len(self.interaction) != len(self.names):
            self.interaction = np.full(len(self.names), np.nan)

    def _table(self) -> dict[str, np.ndarray]:
        return {k: getattr(self, k) for k in KINDS}

    @property
    def largest(self) -> float:
        """The largest ratio of any member, any kind, any stored step."""
        return float(np.nanmax(np.concatenate(list(self._table().values()))))

    def worst(self) -> tuple[str, str, float]:
        """(member, kind, ratio) of the largest ratio."""
        table = self._table()
        kind = max(table, key=lambda k: np.nanmax(table[k]) if np.isfinite(table[k]).any() else -np.inf)
        i = int(np.nanargmax(table[kind]))
        return self.names[i], kind, float(table[kind][i])

    def count_above(self, limit: float) -> int:
        """How many members have a ratio of any kind above ``limit``."""
        stacked = np.vstack(list(self._table().values()))
        return int(np.sum(np.nanmax(np.where(np.isfinite(stacked), stacked, -np.inf), axis=0) > limit))

    def passes(self, tol: float = 1e-3) -> bool:
        """Every ratio <= 1 + tol."""
        return self.largest <= 1.0 + tol


def _number(value: Any) -> float:
    """A limit of a (validated) response entry: a number or a constant expression such as '470/2'."""
    return float(compile_expression(value, set()).evaluate({})) if isinstance(value, str) else float(value)


def _response_entries(case: Case, kind: str) -> list[dict]:
    return [r for r in (yaml.safe_load(case.text) or {}).get("responses", []) or []
            if isinstance(r, dict) and r.get("type") == kind]


def has_member_limits(case: Case) -> bool:
    """Whether the case's responses say what to check members against: a ``stress_ratio``'s
    limits, or a ``buckling_ratio`` or ``interaction_ratio`` response."""
    return (any(v is not None for v in stress_limits(case))
            or bool(_response_entries(case, "buckling_ratio") or _response_entries(case, "interaction_ratio")))


def stress_limits(case: Case) -> tuple[float | None, float | None]:
    """(σ_t, σ_c) of the case's ``stress_ratio`` responses (the smallest of each; None: none)."""
    limits: dict[str, list[float]] = {"tension_limit": [], "compression_limit": []}
    for r in _response_entries(case, "stress_ratio"):
        for key in limits:
            value = r.get(key, r.get("limit"))
            if value is not None:
                limits[key].append(_number(value))
    return (min(limits["tension_limit"], default=None), min(limits["compression_limit"], default=None))


@dataclass(frozen=True)
class StabilityLimits:
    """The beams' effective-length factor K, yield stress F_y (None: no interaction check) and
    resistance factor φ."""

    K: float = 1.0
    yield_stress: float | None = None
    resistance_factor: float = 1.0


def stability_limits(case: Case) -> StabilityLimits:
    """K (the largest of the ``buckling_ratio`` and ``interaction_ratio`` responses'), F_y and φ
    (the smallest of the ``interaction_ratio`` responses'); the defaults without them."""
    inter = _response_entries(case, "interaction_ratio")
    Ks = [_number(r.get("effective_length_factor", 1.0)) for r in inter + _response_entries(case, "buckling_ratio")]
    return StabilityLimits(max(Ks, default=1.0),
                           min((_number(r["yield_stress"]) for r in inter if "yield_stress" in r), default=None),
                           min((_number(r.get("resistance_factor", 1.0)) for r in inter), default=1.0))


def check_members(case: Case, x: Any = None, *, tension_limit: float | None = None,
                  compression_limit: float | None = None, buckling: bool = True,
                  result: Any = None, effective_length_factor: float | None = None,
                  yield_stress: float | None = None, resistance_factor: float | None = None) -> MemberCheck:
    """Run ``case`` at design ``x`` (default x0) and return every bar's and beam's largest ratios.

    Limits default to the case's responses (:func:`stress_limits`, :func:`stability_limits`;
    MPa in the shipped cases); ``buckling`` checks bars that declare ``inertia`` and every beam
    (with ``yield_stress`` also the interaction).  ``result``: a run of ``case`` at ``x`` that
    stored the displacement history ``q`` (default: run it here).
    """
    x = case.x0 if x is None else np.asarray(x, dtype=float)
    st, sc = stress_limits(case)
    tension_limit = tension_limit if tension_limit is not None else st
    compression_limit = compression_limit if compression_limit is not None else sc
    given = stability_limits(case)
    K = effective_length_factor if effective_length_factor is not None else given.K
    fy = yield_stress if yield_stress is not None else given.yield_stress
    phi = resistance_factor if resistance_factor is not None else given.resistance_factor
    model = case.model
    beams = list(model.beams.names) + list(model.frames.names) if isinstance(model, StructuralModel) else []
    if not isinstance(model, StructuralModel) or not (model.bar_names or beams):
        raise CaseError("the post-check needs a structural model with bars or beams", case.source)
    bars = list(model.bar_names)
    res = result if result is not None else run_case(case, x, sensitivities=False, history=("q",))
    if "q" not in res.history:
        raise ValueError("the post-check needs a run that stored the displacement history 'q'")
    params = model.parameters(x)
    pc = ProblemCollector(case.source)
    q = res.history["q"]
    zeros = np.zeros_like(q)
    states = StepState(q, zeros, zeros, np.zeros((len(q), 0)), np.zeros((len(q), 0)), np.zeros((len(q), 0)))

    def evaluate(names: list[str], kind: str) -> tuple[np.ndarray, list[str]]:
        """The output's history (steps, k) and each component's member."""
        out = model.output({"element": names, "kind": kind}, "post-check", pc)
        pc.raise_if_any()
        assert out is not None
        return np.real(np.asarray(out.fn(0.0, states, params))), [lab.split(".", 1)[0] for lab in out.labels]

    def per_member(values: np.ndarray, owner: list[str], names: list[str]) -> np.ndarray:
        """The largest value (over steps and the member's components) of every member (n,)."""
        return np.array([values[:, [i for i, o in enumerate(owner) if o == m]].max() for m in names])

    nan = np.full(len(bars) + len(beams), np.nan)
    tension, compression, ratio, inter = nan.copy(), nan.copy(), nan.copy(), nan.copy()
    sigma, owner = evaluate(bars + beams, "stress")
    if tension_limit:
        tension = per_member(sigma, owner, bars + beams) / tension_limit
    if compression_limit:
        compression = per_member(-sigma, owner, bars + beams) / compression_limit
    has_inertia = np.asarray(model.bar_I) >= 0
    if buckling and bars and has_inertia.any():
        N, _ = evaluate(bars, "force")
        ratio[:len(bars)] = np.where(has_inertia, (-N / np.real(params["P_euler"])).max(axis=0), np.nan)
    if buckling and beams:
        b, b_owner = evaluate(beams, "buckling")
        ratio[len(bars):] = buckling_scale(K) * per_member(b, b_owner, beams)
        if fy is not None:
            inter[len(bars):] = _interaction(b, b_owner, sigma, owner, beams, interaction_forms(K, fy, phi))
    return MemberCheck(tuple(bars + beams), tension, compression, ratio, len(q), inter)


def _interaction(b: np.ndarray, b_owner: list[str], s: np.ndarray, s_owner: list[str], beams: list[str],
                 forms: np.ndarray) -> np.ndarray:
    """The largest interaction u over the steps of every beam (n,), from the buckling ratios
    ``b`` (steps, ·) and the extreme-fibre stresses ``s`` (steps, 4 per beam)."""
    out = []
    for m in beams:
        bi = [i for i, o in enumerate(b_owner) if o == m]
        si = [i for i, o in enumerate(s_owner) if o == m]
        v = np.concatenate([b[:, [bi[0], bi[-1]]], s[:, si]], axis=1)        # (steps, 6)
        assert v.shape[1] == MEMBER_COMPONENTS
        out.append(float(np.max(v @ forms.T)))
    return np.array(out)
