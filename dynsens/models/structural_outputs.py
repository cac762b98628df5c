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
    spring_names: list[str]
    damper_names: list[str]
    bar_names: list[str]
    bar_I: np.ndarray
    beams: Any
    frames: Any
    nl_dampers: Any
    damper_dofs: np.ndarray
    c: np.ndarray
    _spring_state: Any
    _bar_state: Any
    _ext: Any

    def output(self, spec: Any, path: str, problems: ProblemCollector) -> Output | None:
        """Quantities: ``{dof: NAME|[NAMES], kind: displacement|velocity|acceleration}``,
        ``{node: NAME, kind: ...}`` (the node's free translation DOFs x, y (z)) or
        ``{element: NAME|[NAMES]|all, kind: force|stress|strain|buckling}``; ``buckling`` is the
        ratio −N/P_E of the compressive axial force to the Euler load π²EI/(KL)² (bars with
        ``inertia``; positive in compression, > 1 means buckled); of beams with K = 1 and the
        beam's own length L (plane beams one component, 3D beams one per axis: EI_y, EI_z)."""
        if not check_keys(spec, path, allowed("structural.quantity"), problems):
            return None
        kind = spec.get("kind", "displacement" if "dof" in spec or "node" in spec else "force")
        if sum(k in spec for k in ("dof", "node", "element")) > 1:
            problems.add(path, "give one of 'dof', 'node' or 'element'")
            return None
        if "node" in spec:
            node = spec["node"]
            if not isinstance(node, str) or node not in self.node_names:
                problems.add(f"{path}.node", f"unknown node {node!r}{did_you_mean(str(node), self.node_names)}")
                return None
            free = [f"{node}.{a}" for a in "xyz"[:self.dim] if f"{node}.{a}" in self.dof_names]
            if not free:
                problems.add(f"{path}.node", f"every translation of node {node!r} is fixed")
                return None
            spec = {"dof": free, "kind": kind}
        if "dof" in spec:
            names = spec["dof"] if isinstance(spec["dof"], list) else [spec["dof"]]
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
        if "element" not in spec:
            problems.add(path, "expected 'dof' or 'element'")
            return None
        names = spec["element"]
        members = list(self.bar_names) + list(self.beams.names) + list(self.frames.names)
        all_names = self.spring_names + self.damper_names + self.nl_dampers.names + members
        if names == "all":
            names = members if members else list(self.spring_names)
        names = names if isinstance(names, list) else [names]
        dampers = self.damper_names + self.nl_dampers.names
        if names and all(nm in dampers for nm in names):
            return self._damper_output(names, kind, path, problems)
        kinds = ("force", "stress", "strain", "buckling")
        if kind not in kinds:
            problems.add(f"{path}.kind",
                         f"unknown kind {kind!r}{did_you_mean(kind, kinds)} (known: {', '.join(kinds)})")
            return None
        bars, springs, beams, frames = [], [], [], []
        refused: dict[str, list[str]] = {}       # one problem per kind of element, naming them all
        for nm in names:
            if nm in self.bar_names:
                bars.append(self.bar_names.index(nm))
            elif nm in self.beams.names and kind in ("force", "stress", "buckling"):
                beams.append(self.beams.names.index(nm))
            elif nm in self.frames.names and kind in ("force", "stress", "buckling"):
                frames.append(self.frames.names.index(nm))
            elif nm in self.beams.names or nm in self.frames.names:
                refused.setdefault("beams report 'force' (N, M1, M2), 'stress' (extreme fibres) and 'buckling'",
                                   []).append(nm)
            elif nm in self.spring_names and kind == "force":
                springs.append(self.spring_names.index(nm))
            elif nm in self.spring_names:
                refused.setdefault("springs report only 'force'", []).append(nm)
            else:
                problems.add(f"{path}.element", f"unknown element {nm!r}{did_you_mean(nm, all_names)}")
        for what, which in refused.items():
            problems.add(f"{path}.kind", f"{what}, not {kind!r}: {', '.join(which[:5])}"
                                         f"{f' and {len(which) - 5} more' if len(which) > 5 else ''}")
        if len(bars) + len(springs) + len(beams) + len(frames) != len(names):
            return None
        lacking = [self.bar_names[b] for b in bars if self.bar_I[b] < 0]
        if kind == "buckling" and lacking:
            problems.add(f"{path}.element", f"buckling needs the bar's 'inertia' (second moment of area); "
                                            f"missing for {', '.join(lacking[:5])}{' ...' if len(lacking) > 5 else ''}")
            return None
        if springs and (bars or beams or frames):
            problems.add(f"{path}.element", "mix springs and bars or beams in separate quantities")
            return None
        if springs:
            si = np.array(springs)
            return Output(lambda t, s, prm, _i=si: self._spring_state(s.q, prm, _i, tangent=False)[0],
                          tuple(f"{n}.force" for n in names), "", batched=True, autonomous=True)
        bi = np.array(bars)

        def bar_out(t: float, s: StepState, prm: dict[str, Any], _i: np.ndarray = bi, _k: str = kind) -> np.ndarray:
            bs = self._bar_state(s.q, prm)
            if _k == "strain":
                return bs["strain"][..., _i]
            if _k == "force":
                return bs["N"][..., _i]
            if _k == "buckling":
                return (-bs["N"] / prm["P_euler"])[..., _i]
            return (prm["E"] * bs["strain"])[..., _i]

        unit = "-" if kind in ("strain", "buckling") else ""
        parts = [(bar_out, tuple(f"{self.bar_names[b]}.{kind}" for b in bars))] if bars else []
        if beams:
            parts.append(self._beam_output(np.array(beams), kind))
        if frames:
            parts.append(self._frame_output(np.array(frames), kind))
        if len(parts) == 1:
            return Output(parts[0][0], parts[0][1], unit, batched=True, autonomous=True)

        def joined(t: float, s: StepState, prm: dict[str, Any]) -> np.ndarray:
            return np.concatenate([fn(t, s, prm) for fn, _ in parts], axis=-1)
        return Output(joined, sum((lab for _, lab in parts), ()), unit, batched=True, autonomous=True)

    def _damper_output(self, names: list[str], kind: str, path: str, problems: ProblemCollector) -> Output | None:
        """Forces of viscous dampers, linear (c v) or nonlinear (c v (v² + ε²)^((α−1)/2))."""
        if kind != "force":
            problems.add(f"{path}.kind", f"dampers report only 'force', not {kind!r}")
            return None
        lin = [self.damper_names.index(n) for n in names if n in self.damper_names]
        nl = [self.nl_dampers.names.index(n) for n in names if n in self.nl_dampers.names]
        li, ni = np.array(lin, dtype=int), np.array(nl, dtype=int)

        def forces(t: float, s: StepState, prm: dict[str, Any]) -> np.ndarray:
            qde = self._ext(s.qd)
            pv = prm["pv"]
            v_lin = qde[..., self.damper_dofs[li, 0]] - qde[..., self.damper_dofs[li, 1]]
            F_nl, _ = self.nl_dampers.force(self.nl_dampers.velocity(qde), pv)
            return np.concatenate([pv[..., self.c[li]] * v_lin, F_nl[..., ni]], axis=-1)
        labels = tuple(f"{self.damper_names[i]}.force" for i in lin) + \
            tuple(f"{self.nl_dampers.names[i]}.force" for i in nl)
        return Output(forces, labels, "", batched=True, autonomous=True)

    def _beam_output(self, bi: np.ndarray, kind: str) -> tuple[Any, tuple[str, ...]]:
        """Beams ``bi``: extreme-fibre stresses (4 per beam: end 1 ±, end 2 ±) or end forces
        (N, M1, M2 per beam); the function and the component labels."""
        names = [self.beams.names[b] for b in bi]
        if kind == "buckling":
            def ratio(t: float, s: StepState, prm: dict[str, Any]) -> np.ndarray:
                N = self.beams.state(self._ext(s.q), prm)["N"]
                return (-N * prm["beam_L"] ** 2 / (np.pi ** 2 * prm["beam_EI"]))[..., bi]
            return ratio, tuple(f"{n}.buckling" for n in names)
        if kind == "stress":
            labels = tuple(f"{n}.stress.{e}" for n in names for e in ("1+", "1-", "2+", "2-"))

            def fn(t: float, s: StepState, prm: dict[str, Any]) -> np.ndarray:
                sig = self.beams.fibre_stress(self._ext(s.q), prm)[..., bi, :]
                return sig.reshape(sig.shape[:-2] + (-1,))
            return fn, labels
        labels = tuple(f"{n}.{c}" for n in names for c in ("N", "M1", "M2"))

        def forces(t: float, s: StepState, prm: dict[str, Any]) -> np.ndarray:
            st = self.beams.state(self._ext(s.q), prm)
            f = np.stack([st["N"], st["M1"], st["M2"]], axis=-1)[..., bi, :]
            return f.reshape(f.shape[:-2] + (-1,))
        return forces, labels

    def _frame_output(self, fi: np.ndarray, kind: str) -> tuple[Any, tuple[str, ...]]:
        """3D beams ``fi``: largest and smallest fibre stresses at both ends (4 per beam) or
        section forces N, T, My1, Mz1, My2, Mz2; the function and the component labels."""
        names = [self.frames.names[b] for b in fi]
        if kind == "buckling":
            labels = tuple(f"{n}.buckling.{a}" for n in names for a in "yz")

            def ratio(t: float, s: StepState, prm: dict[str, Any]) -> np.ndarray:
                N = self.frames.end_forces(self._ext(s.q), prm)[..., fi, 0]
                L2 = (prm["frame_L"] ** 2 / np.pi ** 2)[..., fi]
                r = np.stack([-N * L2 / prm["frame_EIy"][..., fi], -N * L2 / prm["frame_EIz"][..., fi]], axis=-1)
                return r.reshape(r.shape[:-2] + (-1,))
            return ratio, labels
        if kind == "stress":
            labels = tuple(f"{n}.stress.{e}" for n in names for e in ("1+", "1-", "2+", "2-"))
            method = self.frames.fibre_stress
        else:
            labels = tuple(f"{n}.{c}" for n in names for c in ("N", "T", "My1", "Mz1", "My2", "Mz2"))
            method = self.frames.end_forces

        def fn(t: float, s: StepState, prm: dict[str, Any]) -> np.ndarray:
            v = method(self._ext(s.q), prm)[..., fi, :]
            return v.reshape(v.shape[:-2] + (-1,))
        return fn, labels
