"""Beams (``type: beam``): plane co-rotational beams in a ``dim: 2`` model
(:class:`~dynsens.models.structural.beams.BeamSet`), space-frame beams, small rotations or co-rotational,
in a ``dim: 3`` model (:class:`~dynsens.models.structural.beams3d.Beam3DSet`).  Both carry nodal rotations;
their mass is lumped, or consistent (turning with plane beams, constant for space frames)."""
from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from ....errors import ProblemCollector
from ..beams import BeamSet, parse_beam
from ..beams3d import Beam3DSet, parse_beam_3d
from ..corotated_damping import DampedKind
from .kind import ElementKind, extend, ModelContext, ReadContext, Touch, Triplets, register_kind

STRESS_LABELS = ("1+", "1-", "2+", "2-")


class _BeamKind(ElementKind):
    """What plane and space beams share: their set's arrays, forces, masses and outputs."""

    section = "structural.beam"
    member = True
    output_kinds = ("force", "stress", "buckling")
    width: ClassVar[int]          # DOFs per element
    mass_key: ClassVar[str]       # the derived parameter of the elements' masses
    set: Any

    def dofs(self) -> list[int]:
        return [d for row in self.set.dofs for d in row]

    def freeze(self, model: ModelContext) -> None:
        self.set.freeze()
        self.scatter = model.scatter(self.set.idx, np.ones(self.width), False)
        self.inertia_scatter = model.scatter(self.set.idx[self.set.is_consistent], np.ones(self.width), False)

    def parameters(self, pv: np.ndarray, out: dict[str, Any], mass: np.ndarray) -> None:
        if len(self):
            self.set.parameters(pv, out)
            idx, vals = self.set.lumped_mass(out)
            np.add.at(mass, idx, vals)

    def structural_mass(self, params: dict[str, Any]) -> Any:
        return np.sum(params[self.mass_key]) if len(self) else None

    def internal_force(self, q: np.ndarray, params: dict[str, Any]) -> np.ndarray | None:
        if not len(self):
            return None
        fb = self.set.forces(extend(q), params)
        return self.scatter(fb.reshape(fb.shape[:-2] + (-1,)))

    def design_touch(self) -> list[Touch]:
        return self.set.design_touch()

    def refusal(self, kind: str) -> str:
        return "beams report 'force' (N, M1, M2), 'stress' (extreme fibres) and 'buckling'"


@register_kind
class PlaneBeams(_BeamKind):
    """The plane co-rotational beams of a ``dim: 2`` model."""

    type = "beam"
    dims = (2,)
    order = 4
    compiled = False                # Python only: the compiled step serves spring networks
    width = 6
    mass_key = "beam_mass"
    stack_keys = BeamSet.STACK_KEYS

    def __init__(self) -> None:
        self.set = BeamSet()
        self.names = self.set.names

    def read(self, entry: dict, path: str, name: str, ctx: ReadContext) -> None:
        for key in ("G", "orientation", "kinematics"):
            if key in entry:
                ctx.problems.add(f"{path}.{key}", f"'{key}' belongs to 3D beams (dim: 3); a plane beam has none")
        parse_beam(entry, path, name, self.set, ctx.table, ctx.beam_dofs, ctx.node_coords, ctx.problems)

    def nonlinear(self) -> bool:
        return bool(len(self))

    def mass_turns(self) -> bool:
        return any(self.set.consistent)

    def damped(self) -> bool:
        return self.mass_turns()      # (the turning mass's inertia forces depend on q̇)

    def tangent(self, q: np.ndarray, params: dict[str, Any], corotated: bool) -> list[Triplets]:
        if not (len(self) and corotated):
            return []
        return [self.set.tangent(extend(q), params)]

    def inertia_force(self, qe: np.ndarray, qde: np.ndarray, qdde: np.ndarray, params: dict[str, Any]) -> Any:
        if not self.mass_turns():
            return None
        fe = self.set.inertia(qe, qde, qdde, params)
        return self.inertia_scatter(fe.reshape(fe.shape[:-2] + (-1,)))

    def mass_entries(self, qe: np.ndarray, params: dict[str, Any]) -> list[Triplets]:
        if not self.mass_turns():
            return []
        Mb = self.set.turning_mass(qe, params)["M"]
        idx = self.set.idx[self.set.is_consistent]
        return [(np.repeat(idx, 6, axis=1).ravel(), np.tile(idx, (1, 6)).ravel(), Mb.reshape(-1))]

    def inertia_jacobians(self, qe: np.ndarray, qde: np.ndarray, qdde: np.ndarray, params: dict[str, Any]
                          ) -> Any:
        return self.set.inertia_jacobians(qe, qde, qdde, params) if self.mass_turns() else None

    def damped_kind(self) -> DampedKind:
        return DampedKind(self.set.idx, self.scatter, self.set.deformations)

    def output(self, index: np.ndarray, kind: str, path: str, problems: ProblemCollector) -> Any:
        """Extreme-fibre stresses (4 per beam: end 1 ±, end 2 ±), end forces (N, M1, M2) or the
        buckling ratio −N/P_E with P_E = π²EI/L² (K = 1, the beam's own length L)."""
        names = [self.names[b] for b in index]
        if kind == "buckling":
            def ratio(t: float, s: Any, prm: dict[str, Any]) -> np.ndarray:
                N = self.set.state(extend(s.q), prm)["N"]
                return (-N * prm["beam_L"] ** 2 / (np.pi ** 2 * prm["beam_EI"]))[..., index]
            return ratio, tuple(f"{n}.buckling" for n in names)
        if kind == "stress":
            def stress(t: float, s: Any, prm: dict[str, Any]) -> np.ndarray:
                sig = self.set.fibre_stress(extend(s.q), prm)[..., index, :]
                return sig.reshape(sig.shape[:-2] + (-1,))
            return stress, tuple(f"{n}.stress.{e}" for n in names for e in STRESS_LABELS)

        def forces(t: float, s: Any, prm: dict[str, Any]) -> np.ndarray:
            st = self.set.state(extend(s.q), prm)
            f = np.stack([st["N"], st["M1"], st["M2"]], axis=-1)[..., index, :]
            return f.reshape(f.shape[:-2] + (-1,))
        return forces, tuple(f"{n}.{c}" for n in names for c in ("N", "M1", "M2"))


@register_kind
class SpaceBeams(_BeamKind):
    """The space-frame beams of a ``dim: 3`` model: small rotations (constant K and, when
    consistent, constant M) or co-rotational."""

    type = "beam"
    dims = (3,)
    order = 5
    compiled = False                # Python only: the compiled step serves spring networks
    width = 12
    mass_key = "frame_mass"
    stack_keys = Beam3DSet.STACK_KEYS

    def __init__(self) -> None:
        self.set = Beam3DSet()
        self.names = self.set.names

    def read(self, entry: dict, path: str, name: str, ctx: ReadContext) -> None:
        parse_beam_3d(entry, path, name, self.set, ctx.table, ctx.beam_dofs, ctx.node_coords, ctx.problems,
                      ctx.given_coords)

    def nonlinear(self) -> bool:
        return any(self.set.corot)

    def constant_mass(self) -> bool:
        return any(self.set.consistent)

    def tangent(self, q: np.ndarray, params: dict[str, Any], corotated: bool) -> list[Triplets]:
        if not len(self):
            return []
        return [self.set.tangent(extend(q), params,
                                 corotated)]

    def inertia_force(self, qe: np.ndarray, qde: np.ndarray, qdde: np.ndarray, params: dict[str, Any]) -> Any:
        if not self.constant_mass():
            return None
        fe = self.set.inertia(qdde, params)
        return self.inertia_scatter(fe.reshape(fe.shape[:-2] + (-1,)))

    def mass_entries(self, qe: np.ndarray, params: dict[str, Any]) -> list[Triplets]:
        return [self.set.consistent_entries(params)] if self.constant_mass() else []

    def damped_kind(self) -> DampedKind:
        corot = self.set.idx[self.set.is_corot]
        return DampedKind(corot, self.model.scatter(corot, np.ones(12), False), self.set.deformations)

    def freeze(self, model: ModelContext) -> None:
        super().freeze(model)
        self.model = model

    def range_problem(self, qe: np.ndarray, params: dict[str, Any]) -> str | None:
        return self.set.range_problem(qe, params) if len(self) else None

    def output(self, index: np.ndarray, kind: str, path: str, problems: ProblemCollector) -> Any:
        """Largest and smallest fibre stresses at both ends (4 per beam), section forces N, T,
        My1, Mz1, My2, Mz2, or the buckling ratios −N/P_E about y and z (K = 1, P_E = π²EI/L²)."""
        names = [self.names[b] for b in index]
        if kind == "buckling":
            def ratio(t: float, s: Any, prm: dict[str, Any]) -> np.ndarray:
                N = self.set.end_forces(extend(s.q), prm)[..., index, 0]
                L2 = (prm["frame_L"] ** 2 / np.pi ** 2)[..., index]
                r = np.stack([-N * L2 / prm["frame_EIy"][..., index], -N * L2 / prm["frame_EIz"][..., index]], axis=-1)
                return r.reshape(r.shape[:-2] + (-1,))
            return ratio, tuple(f"{n}.buckling.{a}" for n in names for a in "yz")
        if kind == "stress":
            labels = tuple(f"{n}.stress.{e}" for n in names for e in STRESS_LABELS)
            method = self.set.fibre_stress
        else:
            labels = tuple(f"{n}.{c}" for n in names for c in ("N", "T", "My1", "Mz1", "My2", "Mz2"))
            method = self.set.end_forces

        def fn(t: float, s: Any, prm: dict[str, Any]) -> np.ndarray:
            v = method(extend(s.q), prm)[..., index, :]
            return v.reshape(v.shape[:-2] + (-1,))
        return fn, labels

