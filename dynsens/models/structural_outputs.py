"""Quantities of a structural model that responses and events read (``Model.output``):
DOF displacements, velocities, accelerations; element forces, stresses, strains, buckling
ratios (bars), extreme-fibre stresses and end forces (beams), spring forces."""
from __future__ import annotations

from typing import Any

import numpy as np

from ..case_keys import allowed
from ..errors import ProblemCollector
from ._keys import check_keys, did_you_mean
from .base import Output, StepState


class StructuralOutputs:
    """Mixin of :class:`~dynsens.models.structural.StructuralModel`: its ``output`` method."""

    dof_names: list[str]
    node_names: list[str]
    dim: int
    sets: list[Any]

    def output(self, spec: Any, path: str, problems: ProblemCollector) -> Output | None:
        """Quantities: ``{dof: NAME|[NAMES], kind: displacement|velocity|acceleration}``,
        ``{node: NAME, kind: ...}`` (the node's free translation DOFs x, y (z)) or
        ``{element: NAME|[NAMES]|all, kind: ...}``: what each element kind reports (bars force,
        stress, strain and buckling, the ratio −N/P_E of the compressive axial force to the Euler
        load π²EI/(KL)², positive in compression, > 1 means buckled; beams force and stress;
        springs and dampers force)."""
        if not check_keys(spec, path, allowed("structural.quantity"), problems):
            return None
        kind = spec.get("kind", "displacement" if "dof" in spec or "node" in spec else "force")
        if sum(k in spec for k in ("dof", "node", "element")) > 1:
            problems.add(path, "give one of 'dof', 'node' or 'element'")
            return None
        if "node" in spec:
            free = self._node_dofs(spec["node"], path, problems)
            if free is None:
                return None
            spec = {"dof": free, "kind": kind}
        if "dof" in spec:
            return self._dof_output(spec["dof"], kind, path, problems)
        if "element" not in spec:
            problems.add(path, "expected 'dof' or 'element'")
            return None
        return self._element_output(spec["element"], kind, path, problems)

    def _node_dofs(self, node: Any, path: str, problems: ProblemCollector) -> list[str] | None:
        """The free translation DOFs of a node, or None with a problem listed."""
        if not isinstance(node, str) or node not in self.node_names:
            problems.add(f"{path}.node", f"unknown node {node!r}{did_you_mean(str(node), self.node_names)}")
            return None
        free = [f"{node}.{a}" for a in "xyz"[:self.dim] if f"{node}.{a}" in self.dof_names]
        if not free:
            problems.add(f"{path}.node", f"every translation of node {node!r} is fixed")
            return None
        return free

    def _dof_output(self, dofs: Any, kind: str, path: str, problems: ProblemCollector) -> Output | None:
        """Displacements, velocities or accelerations of named DOFs."""
        names = dofs if isinstance(dofs, list) else [dofs]
        if not names:
            problems.add(f"{path}.dof", "expected a dof name or a non-empty list of dof names, found []")
            return None
        field_of = {"displacement": "q", "velocity": "qd", "acceleration": "qdd"}
        if kind not in field_of:
            problems.add(f"{path}.kind", f"unknown kind {kind!r} for a dof{did_you_mean(kind, field_of)} "
                                         f"(known: {', '.join(field_of)})")
            return None
        idx = []
        for nm in names:
            if nm not in self.dof_names:
                problems.add(f"{path}.dof", f"unknown or fixed dof {nm!r}{did_you_mean(nm, self.dof_names)}")
            else:
                idx.append(self.dof_names.index(nm))
        if len(idx) != len(names):
            return None
        ia = np.array(idx)
        fld = field_of[kind]
        unit = ""  # the case's own unit system; a response may name it with 'unit'
        return Output(lambda t, s, prm, _f=fld, _i=ia: getattr(s, _f)[_i],
                      tuple(f"{n}.{kind}" for n in names), unit, linear=True)

    def _element_output(self, names: Any, kind: str, path: str, problems: ProblemCollector) -> Output | None:
        """Quantities of named elements (``all``: the members, bars and beams; else the springs),
        grouped by their sets, in the sets' order."""
        if names == "all":
            members = [nm for k in self.sets if k.member for nm in k.names]
            names = members if members else [nm for k in self.sets if k.type == "spring" for nm in k.names]
        names = names if isinstance(names, list) else [names]
        owner = {nm: k for k in self.sets for nm in k.names}
        known = list(dict.fromkeys(knd for k in self.sets for knd in k.output_kinds))
        if kind not in known:
            problems.add(f"{path}.kind",
                         f"unknown kind {kind!r}{did_you_mean(kind, known)} (known: {', '.join(known)})")
            return None
        picked = self._pick(names, owner, kind, path, problems)
        if picked is None:
            return None
        if len({self.sets[j].member for j in picked}) > 1:
            problems.add(f"{path}.element", "mix springs and bars or beams in separate quantities")
            return None
        parts = [self.sets[j].output(np.array(idx), kind, path, problems) for j, idx in sorted(picked.items())]
        if any(p is None for p in parts):
            return None
        unit = "-" if kind in ("strain", "buckling") else ""
        if len(parts) == 1:
            return Output(parts[0][0], parts[0][1], unit, batched=True, autonomous=True)

        def joined(t: float, s: StepState, prm: dict[str, Any]) -> np.ndarray:
            return np.concatenate([fn(t, s, prm) for fn, _ in parts], axis=-1)
        return Output(joined, sum((lab for _, lab in parts), ()), unit, batched=True, autonomous=True)

    def _pick(self, names: list[Any], owner: dict[str, Any], kind: str, path: str,
              problems: ProblemCollector) -> dict[int, list[int]] | None:
        """Element indices per set position of the named elements that report ``kind``; None
        with one problem per unknown name and per kind of element that does not report it."""
        picked: dict[int, list[int]] = {}        # set position -> element indices
        refused: dict[str, list[str]] = {}       # one problem per kind of element, naming them all
        for nm in names:
            k = owner.get(nm)
            if k is None:
                problems.add(f"{path}.element", f"unknown element {nm!r}{did_you_mean(nm, list(owner))}")
            elif kind in k.output_kinds:
                picked.setdefault(self.sets.index(k), []).append(k.names.index(nm))
            else:
                refused.setdefault(k.refusal(kind), []).append(nm)
        for what, which in refused.items():
            problems.add(f"{path}.kind", f"{what}, not {kind!r}: {', '.join(which[:5])}"
                                         f"{f' and {len(which) - 5} more' if len(which) > 5 else ''}")
        return picked if sum(len(v) for v in picked.values()) == len(names) else None
