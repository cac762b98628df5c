"""Point masses (``type: mass``): a mass on a DOF, or on every translation of a node."""
from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from ....case_keys import allowed
from ..._keys import check_keys
from .kind import ElementKind, ReadContext, Touch, register_kind


@register_kind
class PointMasses(ElementKind):
    """The point masses of a model: a diagonal mass term per DOF they sit on."""

    type = "mass"
    order = 0
    section = "structural.mass"
    compiled = True
    stack_keys: ClassVar[tuple[str, ...]] = ()

    def __init__(self) -> None:
        self.names: list[str] = []
        self.terms: list[tuple[int, int]] = []     # (DOF, parameter index of the mass)

    def read(self, entry: dict, path: str, name: str, ctx: ReadContext) -> None:
        check_keys(entry, path, allowed(self.section), ctx.problems, required=("mass",))
        pi = ctx.table.add(entry.get("mass"), f"{path}.mass", ctx.problems, positive=True)
        targets = [ctx.dof(entry["dof"], f"{path}.dof")] if "dof" in entry else \
            ctx.node_dofs(entry.get("node"), f"{path}.node") if "node" in entry else []
        if not targets:
            ctx.problems.add(path, "a mass needs 'dof' or 'node'")
        self.names.append(name)
        self.terms += [(d, pi) for d in targets]

    def freeze(self, model: Any) -> None:
        self.mass_dof = np.array([d for d, _ in self.terms], dtype=int)
        self.mass_idx = np.array([p for _, p in self.terms], dtype=int)

    def dofs(self) -> list[int]:
        return [d for d, _ in self.terms]

    def parameters(self, pv: np.ndarray, out: dict[str, Any], mass: np.ndarray) -> None:
        np.add.at(mass, self.mass_dof, pv[self.mass_idx])

    def structural_mass(self, params: dict[str, Any]) -> Any:
        """A mass on a node counts once, not once per direction."""
        return np.sum(params["pv"][np.unique(self.mass_idx)]) if len(self.mass_idx) else None

    def design_touch(self) -> list[Touch]:
        return list(zip(self.mass_idx, self.mass_dof))
