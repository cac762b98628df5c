r"""Tension-only cables (``type: cable``): a bar (:mod:`.bars`, Green–Lagrange strain ε) that
carries no compression.  Its axial force is N = E A g(ε) with the switch

* ``exact``:  g(ε) = max(ε, 0) — slack below zero strain, with the kink of the exact law there
  (its tangent jumps from 0 to EA; a Newton iteration that crosses it may need more iterations,
  and a design derivative is undefined where a cable sits exactly at ε = 0);
* ``smooth``: g(ε) = ½ (ε + √(ε² + w²)) with a smoothing ``width`` w (a strain): it tends to
  max(ε, 0) as w → 0, is differentiable everywhere (sensitivities are continuous) and carries the
  small tension E A w/2 at ε = 0 (a cable that is just taut).

Nodal forces ± N d/L; tangent (E A g'(ε)/L³) d dᵀ + (N/L) I per node pair.  Mass lumped,
ρAL/2 per node and direction.  Rayleigh's stiffness-proportional damping β K₀ does not act on
cables (K₀ is taken at q = 0, where a cable is slack or at the kink).  Outputs: force N, stress
N/A and strain ε.
"""
from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from ....case_keys import Key, Section
from .bars import Bars
from .kind import ReadContext, Triplets, register_kind

SWITCHES = ("exact", "smooth")

CABLE_KEYS = Section("elements[i], type: cable", "Tension-only cable: a truss bar whose axial force "
                     "N = EA·g(ε) is max(EA ε, 0) (`switch: exact`) or EA·½(ε + √(ε² + w²)) "
                     "(`switch: smooth`, width w).", (
                         Key("type", "enum", "element type", required=True, values=("cable",)),
                         Key("name", "name", "element name"),
                         Key("nodes", "list", "[node_1, node_2]", required=True, item="name"),
                         Key("area", "expr", "cross-section area", required=True),
                         Key("E", "expr", "Young's modulus", required=True),
                         Key("density", "expr", "density (lumped mass)", default=0.0),
                         Key("switch", "enum", "tension-only law: exact max(N, 0), or smooth",
                             default="exact", values=SWITCHES),
                         Key("width", "expr", "smoothing width w of `switch: smooth` (a strain, > 0)"),
                     ), type_value="cable")


def switch(strain: Any, width: Any) -> tuple[Any, Any]:
    """(g(ε), g'(ε)) of the tension-only law for strains ``strain``; ``width`` None: the exact
    max(ε, 0) (slope 1 where ε > 0, else 0), else the smooth ½(ε + √(ε² + w²)).  Complex-safe
    (the exact switch decides on the real part)."""
    if width is None:
        taut = np.real(strain) > 0
        return np.where(taut, strain, 0.0 * strain), np.where(taut, 1.0, 0.0)
    root = np.sqrt(strain * strain + width * width)
    return 0.5 * (strain + root), 0.5 * (1.0 + strain / root)


@register_kind
class Cables(Bars):
    """The cables of a model: bars with the tension-only law (their own derived parameters)."""

    type = "cable"
    order = 6
    compiled = False                # Python only: the compiled step serves spring networks
    section = "structural.cable"
    keys = CABLE_KEYS
    output_kinds: ClassVar[tuple[str, ...]] = ("force", "stress", "strain")
    prefix = "cable_"
    stack_keys: ClassVar[tuple[str, ...]] = ("cable_D0", "cable_L0", "cable_EA", "cable_A", "cable_width")

    def __init__(self) -> None:
        super().__init__()
        self.widths: list[int] = []          # parameter index of w, or −1 (exact)

    def read(self, entry: dict, path: str, name: str, ctx: ReadContext) -> None:
        problems = ctx.problems
        law = entry.get("switch", "exact")
        if law not in SWITCHES:
            problems.add(f"{path}.switch", f"expected exact or smooth, found {law!r}")
        if (law == "smooth") != ("width" in entry):
            problems.add(f"{path}.width", "a smooth switch needs its 'width' (a strain > 0); the exact one has none")
        n_before = len(self.names)
        super().read(entry, path, name, ctx)     # the bars' reader, against the cable's key section
        if len(self.names) > n_before:
            self.widths.append(ctx.table.add(entry["width"], f"{path}.width", problems, positive=True)
                               if law == "smooth" and "width" in entry else -1)

    def parameters(self, pv: np.ndarray, out: dict[str, Any], mass: np.ndarray) -> None:
        super().parameters(pv, out, mass)
        if len(self):
            w = np.array(self.widths, dtype=int)
            out["cable_width"] = np.where(w >= 0, pv[np.maximum(w, 0)], 0.0)

    def _law(self, strain: np.ndarray, params: dict[str, Any]) -> tuple[Any, Any]:
        """(g, g') per cable: the exact switch where no width is given, else the smooth one."""
        w = params["cable_width"]
        exact = np.array(self.widths) < 0
        g_e, dg_e = switch(strain, None)
        g_s, dg_s = switch(strain, np.where(exact, 1.0, w))
        return np.where(exact, g_e, g_s), np.where(exact, dg_e, dg_s)

    def state(self, q: np.ndarray, params: dict[str, Any]) -> dict[str, np.ndarray]:
        bs = super().state(q, params)
        g, dg = self._law(bs["strain"], params)
        bs["N"] = params["cable_EA"] * g
        bs["dN"] = params["cable_EA"] * dg
        return bs

    def axial_stiffness(self, bs: dict[str, np.ndarray], params: dict[str, Any]) -> np.ndarray:
        return bs["dN"]

    def stress(self, bs: dict[str, np.ndarray], params: dict[str, Any]) -> np.ndarray:
        return bs["N"] / params["cable_A"]

    def damped_kind(self) -> Any:
        return None

    def tangent(self, q: np.ndarray, params: dict[str, Any], corotated: bool) -> list[Triplets]:
        return super().tangent(q, params, corotated) if corotated else []

    def _output_parameters(self, e: int, kind: str) -> list[int]:
        # a cable's force and stress read its law's width; its stress N/A the area
        own = [self.A[e], self.E[e], *([self.widths[e]] if self.widths[e] >= 0 else [])]
        return own if kind in ("force", "stress") else []

    def design_touch(self) -> list[Any]:
        return super().design_touch() + [([w], dofs) for w, dofs in zip(self.widths, self.idx) if w >= 0]

