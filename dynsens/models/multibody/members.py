r"""Flexible members inside a mechanism: bars between node bodies (issue 33).

Formulation.  A structural member connects two *nodes*; a node is a body of the mechanism —
a point mass (:mod:`.pointmass`) or a small rigid body — so the members are discretised in
*absolute nodal coordinates*: the nodes' own coordinates (COM position, Euler parameters) are
the structural degrees of freedom, and the ordinary joints attach nodes to rigid bodies (a
spherical or distance joint to a point-mass node, any joint to a rigid node).  The coupled
system keeps the multibody unknowns z = [q̈; λ; ṗ] per step; a member adds an internal force
to Q and its mass to the node bodies.  Sensitivities run through the coupled system like any
other force element: the member's law is differentiated exactly by the kernel, and its
constants (E, A, ρ, the free length) enter the parameter vector, so they may be design
expressions.

Bar (``type: bar``).  An axial element between the nodes' attachment points P_1, P_2
(``node`` = the body's COM, or ``body.marker``), with the *engineering* (Biot) strain

    ε = (L − L0) / L0,      N = E A ε + c L̇,      σ = N / A,

L = ‖P_2 − P_1‖, N the tension (force unit), σ the nominal stress (force / length²), c an
optional axial dashpot (force·time/length).  L0 is the free length: the distance Li at the initial
(guess) pose, or, with ``initial_force: N0``, L0 = Li E A/(E A + N0), so that the bar carries N0
at the initial pose — a pretension, or the static force that lets a mechanism with elastic
members start from equilibrium (the start pressure ``static`` of a cylinder then holds it).  The
engineering strain makes the bar an exact linear spring of stiffness EA/L0 along its current
axis — geometrically nonlinear (large rotations), materially linear in L — so a hanging mass
stretches it by exactly m g L0/(E A).  The law is the spring-damper's (:func:`.forces.spring_law`
with k = EA/L0), which both kernels (numpy and compiled) know with its exact Jacobian.

Mass.  Each member's mass ρ A Li (Li its length at the initial pose; Li = L0 without a
pretension) is lumped onto its end nodes, ρ A Li/2 each, added to the node body's mass at its COM
(exact for a point-mass node or a marker at the COM; a half on the ground does not move, but the
``mass`` response counts it).  The node masses therefore depend on the design (A, ρ, Li), and so
do the weight, the inertia forces and the ``mass`` response.  For
a bar hanging under its own weight the lumping is exact at the free end: the continuous bar's
end displacement ρ g L²/(2E) equals (ρ A L/2) g L/(E A).

Outputs: ``{element: BAR, kind: force | stress | strain | length}`` (N, σ, ε, L).

Beams (``type: beam``): co-rotational beams between node frames, :mod:`.member_beams`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ...case_keys import allowed, required
from ...errors import ProblemCollector
from .._keys import check_keys, did_you_mean
from ..base import Output, StepState
from .bodies import GROUND, Diff, MBParams, Point
from .forces import SpringDamper
from .kernel import KParams, kernel_params
from .member_beams import BeamMember, member_node, read_beam
from .spec import Reader

if TYPE_CHECKING:  # pragma: no cover
    from .model import MultibodyModel

MEMBER_TYPES = ("bar", "beam")
BAR_KINDS = ("force", "stress", "strain", "length")


@dataclass(eq=False)
class Bar(SpringDamper):
    """A bar member: a spring-damper of stiffness E A / L0 along its current axis (module
    docstring).  ``E``, ``A``, ``rho`` are parameter indices (the SpringDamper's ``k`` and ``k3``
    are unused: −1); ``c`` the dashpot's index; ``free_length`` the key of L0 in params.scal;
    ``nodes`` the node bodies' indices (GROUND for the ground)."""

    E: int = -1
    A: int = -1
    rho: int = -1
    nodes: tuple[int, int] = (GROUND, GROUND)
    initial_length: str = ""     # the key of Li in params.scal ("": Li = L0, no pretension)

    law_kind = 0       # the spring-damper's law (compiled kernel too)

    def constants(self, prm: Any) -> np.ndarray:
        """[E A / L0, 0, c, L0] for one parameter set (complex-safe)."""
        pv = prm.pv
        L0 = prm.scal[self.free_length]
        return np.array([pv[self.E] * pv[self.A] / L0, 0.0 * L0, pv[self.c], L0])

    def half_mass(self, prm: MBParams) -> Any:
        """ρ A Li / 2 (mass unit): the share of each end node."""
        return 0.5 * prm.pv[self.rho] * prm.pv[self.A] * prm.scal[self.initial_length or self.free_length]

    def lump_mass(self, prm: MBParams) -> None:
        """Add ρ A Li / 2 to the mass of each moving end node."""
        for b in self.nodes:
            if b != GROUND:
                prm.bodies[b].mass = prm.bodies[b].mass + self.half_mass(prm)

    def grounded_mass(self, prm: MBParams) -> Any:
        """The member mass lumped on the ground (not in any body; counted by the ``mass``
        response)."""
        return sum(self.half_mass(prm) for b in self.nodes if b == GROUND)


def _free_length(prm: MBParams, length: Any, iE: int, iA: int, iN: int) -> Any:
    """L0 = Li E A / (E A + N0) (length unit): the free length of a bar that carries the tension
    N0 at its initial length Li (complex-safe)."""
    EA = prm.pv[iE] * prm.pv[iA]
    return length(prm) * EA / (EA + prm.pv[iN])


def read_members(rd: Reader, spec: Any, path: str, springs: list, forces: list) -> list[Any]:
    """Read the ``members`` list at ``path``: bars are appended to ``springs`` (they act through
    the axial-element kernel), beams to ``forces`` (:mod:`.member_beams`); all are returned (the
    model lumps their masses, ``lump_mass``).  Problems go to rd.problems with their YAML paths."""
    if spec is None:
        return []
    if not isinstance(spec, list):
        rd.problems.add(path, "expected a list of members ({type: bar, nodes: [A, B], E, area, ...})")
        return []
    bars: list[Any] = []
    names = {getattr(s, "name", None) for s in springs + forces}
    for i, m in enumerate(spec):
        mp = f"{path}[{i}]"
        kind = m.get("type") if isinstance(m, dict) else m
        if kind not in MEMBER_TYPES:
            rd.problems.add(f"{mp}.type", f"unknown member type {kind!r}{did_you_mean(kind, MEMBER_TYPES)} "
                                          f"(known: {', '.join(MEMBER_TYPES)})")
            continue
        if not check_keys(m, mp, allowed(f"multibody.member.{kind}"), rd.problems,
                          required=required(f"multibody.member.{kind}")):
            continue
        name = str(m.get("name", f"member{i + 1}"))
        if name in names:
            rd.problems.add(f"{mp}.name", f"duplicate element name '{name}' (members and forces share names)")
            continue
        names.add(name)
        if kind == "beam":
            beam = read_beam(rd, m, mp, name)
            if beam is not None:
                forces.append(beam)
                bars.append(beam)
            continue
        nodes = m.get("nodes")
        if not isinstance(nodes, list) or len(nodes) != 2:
            rd.problems.add(f"{mp}.nodes", f"expected [node_1, node_2] (body or body.marker), found {nodes!r}")
            continue
        ends = [member_node(rd, ref, f"{mp}.nodes[{k}]") for k, ref in enumerate(nodes)]
        iE = rd.num(m.get("E"), f"{mp}.E", positive=True)
        iA = rd.num(m.get("area"), f"{mp}.area", positive=True)
        irho = rd.num(m.get("density", 0.0), f"{mp}.density", nonnegative=True)
        ic = rd.num(m.get("damping", 0.0), f"{mp}.damping", nonnegative=True)
        if ends[0] is None or ends[1] is None:
            continue
        (b1, k1), (b2, k2) = ends  # type: ignore[misc]
        if b1 is b2:
            rd.problems.add(f"{mp}.nodes", "a member needs two different node bodies")
            continue
        for b, k, end in ((b1, k1, 1), (b2, k2, 2)):
            rd.attached(b, k, f"node {end} of member '{name}'")
        g1, g2 = rd.global_point_recipe(b1, k1), rd.global_point_recipe(b2, k2)
        key = f"{name}.L0"
        length = lambda prm, _a=g1, _b=g2: np.sqrt(np.sum((_b(prm) - _a(prm)) ** 2))   # noqa: E731
        initial = ""
        if m.get("initial_force") is None:
            rd.scal.append((key, length))
        else:
            iN = rd.num(m.get("initial_force"), f"{mp}.initial_force")
            rd.table.require_pretension(iN, iE, iA, f"{mp}.initial_force")
            initial = f"{name}.Li"
            rd.scal.append((initial, length))
            rd.scal.append((key, lambda prm, _L=length, _E=iE, _A=iA, _N=iN: _free_length(prm, _L, _E, _A, _N)))
        bar = Bar(name, Diff(Point(b2.index, k2), Point(b1.index, k1)), -1, -1, ic, key,
                  E=iE, A=iA, rho=irho, nodes=(b1.index, b2.index), initial_length=initial)
        springs.append(bar)
        bars.append(bar)
    return bars


def member_output(model: "MultibodyModel", bar: Any, kind: Any, path: str,
                  problems: ProblemCollector) -> Output | None:
    """``{element: BAR, kind: force | stress | strain | length}`` (batched, autonomous), or a
    beam's quantity (:meth:`.member_beams.BeamMember.output`)."""
    from .outputs import _axial
    if isinstance(bar, BeamMember):
        return bar.output(model, kind, path, problems)
    if kind not in BAR_KINDS:
        problems.add(f"{path}.kind", f"unknown member quantity {kind!r}{did_you_mean(kind, BAR_KINDS)} "
                                     f"(known: {', '.join(BAR_KINDS)})")
        return None
    base = _axial(model, bar, "length" if kind in ("length", "strain") else "force")
    i = model.layout.axial.index(bar)

    def fn(t: float, s: StepState, prm: Any) -> Any:
        v = base(t, s, prm)
        if kind in ("force", "length"):
            return v
        kp = prm if isinstance(prm, KParams) else kernel_params(model.layout, prm)
        ref = kp.pv[:, bar.A] if kind == "stress" else kp.ec[i][:, 3]     # A, or L0 (B,)
        ref = ref[:, None] if v.ndim == 2 else ref[0]
        return v / ref if kind == "stress" else (v - ref) / ref
    return Output(fn, (f"{bar.name}.{kind}",), batched=True, autonomous=True)
