r"""Viscous dampers (``type: damper``) between two DOFs, or a DOF and ground: linear f = c δ̇
(in the constant damping matrix), or nonlinear f = c δ̇ (δ̇² + ε²)^((α−1)/2) with ``exponent``
and ``regularization`` (:class:`~dynsens.models.structural.dampers.NonlinearDampers`)."""
from __future__ import annotations

from typing import Any

import numpy as np

from ....case_keys import allowed
from ....errors import ProblemCollector
from ..._keys import check_keys
from ..dampers import NonlinearDampers
from .kind import ElementKind, extend, ModelContext, ReadContext, Touch, Triplets, register_kind
from .springs import PAIR_SIGNS, read_pair


@register_kind
class Dampers(ElementKind):
    """The dampers of a model: the linear ones' constant matrix, the nonlinear ones' forces."""

    type = "damper"
    order = 2
    section = "structural.damper"
    compiled = True                 # (linear dampers: a compiled step serves no nonlinear one)
    output_kinds = ("force",)

    def __init__(self) -> None:
        self.names: list[str] = []
        self.linear_names: list[str] = []
        self.pairs: list[list[int]] = []
        self.c_list: list[int] = []
        self.nl = NonlinearDampers()

    def read(self, entry: dict, path: str, name: str, ctx: ReadContext) -> None:
        check_keys(entry, path, allowed(self.section), ctx.problems, required=("dofs", "c"))
        ids = read_pair(entry, path, "damper", ctx)
        if ids is None:
            return
        table, problems = ctx.table, ctx.problems
        if "exponent" in entry or "regularization" in entry:
            if "exponent" not in entry or "regularization" not in entry:
                problems.add(path, "a nonlinear damper needs 'exponent' (α) and 'regularization' (velocity ε > 0)")
                return
            self.nl.names.append(name)
            self.nl.dofs.append(ids)
            self.nl.c.append(table.add(entry.get("c"), f"{path}.c", problems, nonnegative=True))
            self.nl.alpha.append(table.add(entry["exponent"], f"{path}.exponent", problems, positive=True))
            self.nl.eps.append(table.add(entry["regularization"], f"{path}.regularization", problems, positive=True))
        else:
            self.linear_names.append(name)
            self.pairs.append(ids)
            self.c_list.append(table.add(entry.get("c"), f"{path}.c", problems, nonnegative=True))
        self.names.append(name)

    def freeze(self, model: ModelContext) -> None:
        self.dof_idx = np.array(self.pairs, dtype=int).reshape(-1, 2)
        self.c = np.array(self.c_list, dtype=int)
        self.nl.freeze()
        self.nl_scatter = model.scatter(self.nl.idx, PAIR_SIGNS, True)

    def served_compiled(self) -> bool:
        return not len(self.nl)

    def nonlinear(self) -> bool:
        return bool(len(self.nl))

    def damped(self) -> bool:
        return bool(len(self))

    def damping_entries(self, params: dict[str, Any]) -> list[Triplets]:
        if not len(self.linear_names):
            return []
        c = params["pv"][self.c]
        a, b = self.dof_idx[:, 0], self.dof_idx[:, 1]
        return [(a, a, c), (b, b, c), (a, b, -c), (b, a, -c)]

    def damping_force(self, qd: np.ndarray, params: dict[str, Any]) -> Any:
        if not len(self.nl):
            return None
        qde = extend(qd)
        F, _ = self.nl.force(self.nl.velocity(qde), params["pv"])
        return self.nl_scatter(F)

    def damping_tangent(self, qd: np.ndarray, params: dict[str, Any]) -> list[Triplets]:
        if not len(self.nl):
            return []
        qde = extend(qd)
        rows, cols, vals = self.nl.tangent(qde, params["pv"])
        return list(zip(rows, cols, vals))

    def design_touch(self) -> list[Touch]:
        return [(self.c[e], dofs) for e, dofs in enumerate(self.dof_idx)] + self.nl.design_touch()

    def output(self, index: np.ndarray, kind: str, path: str, problems: ProblemCollector) -> Any:
        """Forces of viscous dampers, linear (c v) or nonlinear (c v (v² + ε²)^((α−1)/2)): the
        linear ones first, then the nonlinear ones."""
        names = [self.names[i] for i in index]
        lin = [self.linear_names.index(n) for n in names if n in self.linear_names]
        nl = [self.nl.names.index(n) for n in names if n in self.nl.names]
        li, ni = np.array(lin, dtype=int), np.array(nl, dtype=int)

        def forces(t: float, s: Any, prm: dict[str, Any]) -> np.ndarray:
            qde = extend(s.qd)
            pv = prm["pv"]
            v_lin = qde[..., self.dof_idx[li, 0]] - qde[..., self.dof_idx[li, 1]]
            F_nl, _ = self.nl.force(self.nl.velocity(qde), pv)
            return np.concatenate([pv[..., self.c[li]] * v_lin, F_nl[..., ni]], axis=-1)
        labels = tuple(f"{self.linear_names[i]}.force" for i in lin) + \
            tuple(f"{self.nl.names[i]}.force" for i in nl)
        return forces, labels

    def refusal(self, kind: str) -> str:
        return "dampers report only 'force'"
