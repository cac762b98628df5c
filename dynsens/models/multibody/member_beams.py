r"""Co-rotational beam members between node bodies that carry an orientation (issue 33).

A ``type: beam`` member joins two *node frames*: node i is a rigid body b_i (not a point mass:
the beam loads its orientation) at its COM or at one of its markers s̄_i, with the body's
orientation, or the ground at a marker.  The element is the 3D co-rotational Euler–Bernoulli beam
of the structural model (:mod:`dynsens.models.structural.beams3d_corot`), fed with the node positions and
frames of the multibody state instead of rotation vectors:

* chord d = P_2 − P_1, P_i = r_i + A(p_i) s̄_i;
* node frames n_ij = A(p_i) ē_ij, ē_ij the element's initial axes e_j (e₁ along the initial
  chord, e₂ the part of ``orientation`` normal to it, e₃ = e₁ × e₂) in body i's axes;
* local deformations (stretch, end rotations in the co-rotated element frame) and strain energy
  Π exactly as :func:`.beams3d_corot.corotated_deformations` / ``energy_gradients``.

The generalized force on the node bodies is Q = −∂Π/∂q, carried through A(p) = Q(p, p) (the
quadratic form of :mod:`.rotations`) as forward derivatives (:class:`.beams3d_corot.Jet2`,
first order) in the 7 coordinates of each moving node.  This equals the virtual-rotation map
Q_p = 2 Eᵀ n of forces.py for the element's end moments n, up to a component along p that the
Euler-parameter normalisation absorbs.  An optional stiffness-proportional damping β (s) adds
β ∂Π/∂e evaluated at the deformation rates ė (material damping of every deformation mode).
The element is evaluated outside the kernel; its Jacobians are exact, from the second-order jets
(:meth:`BeamMember.add_jacobians`), not by complex step.

Mass: lumped as the structural co-rotational beam's: ρ A L/2 on each node's mass, and a rotary
inertia about the element axes of ρ I_p L/2 (twist, I_p = I_y + I_z) and ρ A L³/78 (bending,
HRZ), added to the node body's inertia tensor in its axes (at its COM: exact for a node at the
COM).  Sections are given by their properties A, I_y, I_z, J (local y = e₂, z = e₃).

Outputs: ``{element: BEAM, kind: force | moments}``: the axial force N and the six local end
moments (M_x1, M_y1, M_z1, M_x2, M_y2, M_z2) (∂Π/∂θ, element axes).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import ProblemCollector
from .._keys import did_you_mean
from ..base import Output, StepState
from ..structural.beams3d_corot import Jet2, corotated_deformations, energy_gradients, local_stiffness
from .bodies import GROUND, BodyDef, Ctx, MBParams, Point
from .forces import ForceElement
from .spec import Reader

Array = np.ndarray
BEAM_KINDS = ("force", "moments")
SECTION = ("E", "G", "area", "Iy", "Iz", "J", "density", "damping")


def _rotate_quad(p: list, s: list) -> list:
    """A(p)s̄ = (p₀² − e·e) s̄ + 2 e (e·s̄) + 2 p₀ e × s̄ for p = [p₀, e] (jets or arrays)."""
    e0, e = p[0], p[1:]
    es = e[0] * s[0] + e[1] * s[1] + e[2] * s[2]
    c = e0 * e0 - (e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    exs = [e[1] * s[2] - e[2] * s[1], e[2] * s[0] - e[0] * s[2], e[0] * s[1] - e[1] * s[0]]
    return [c * s[k] + 2.0 * e[k] * es + 2.0 * e0 * exs[k] for k in range(3)]


@dataclass(eq=False)
class BeamMember(ForceElement):
    """A co-rotational beam between node frames (module docstring); parameter indices of the
    section (``idx`` by :data:`SECTION` name), node points ``point_1``, ``point_2`` (Point of
    the node body and its offset key), ``axes`` the vec keys of ē_ij [node][j], ``length`` the
    scal key of L0."""

    name: str
    point_1: Point
    point_2: Point
    axes: tuple[tuple[str, str, str], tuple[str, str, str]]
    idx: dict[str, int]
    length: str
    exact_jacobians = True

    # ---------------------------------------------------------------- kinematics
    def _section(self, prm: MBParams) -> tuple[Any, ...]:
        pv, i = prm.pv, self.idx
        E, G = pv[i["E"]], pv[i["G"]]
        return (prm.scal[self.length], E * pv[i["area"]], G * pv[i["J"]], E * pv[i["Iy"]], E * pv[i["Iz"]])

    def deformations(self, ctx: Ctx, order: int = 1) -> tuple[list, list[tuple[int, int]]]:
        """The 7 local deformations as jets in the moving nodes' coordinates (values (k,),
        gradients (k, n_s), with ``order`` 2 Hessians (k, n_s, n_s)) and the q rows (offset,
        count) of the seeds."""
        nodes = [pt for pt in (self.point_1, self.point_2)]
        moving = [pt.body for pt in nodes if pt.body != GROUND]
        n_s, k = 7 * len(moving), ctx.k
        eye = np.broadcast_to(np.eye(n_s), (k, n_s, n_s)) if n_s else None
        zero = np.zeros((k, n_s, n_s)) if order == 2 else None
        pos: list[list[Any]] = []
        frames: list[list[list[Any]]] = []
        seeds: list[tuple[int, int]] = []
        for pt, keys in zip(nodes, self.axes):
            vec = ctx.params.vec
            s = [vec[pt.key][c, 0] for c in range(3)]
            if pt.body == GROUND:
                pos.append([s[c] + 0.0 * ctx.q[0] for c in range(3)])
                frames.append([[vec[key][c, 0] + 0.0 * ctx.q[0] for c in range(3)] for key in keys])
                continue
            a, j0 = 7 * pt.body, 7 * len(seeds)
            seeds.append((a, 7))
            q = [Jet2(ctx.q[a + c], eye[:, j0 + c], zero) for c in range(7)]  # type: ignore[index]
            r, p = q[:3], q[3:]
            As = _rotate_quad(p, s)
            pos.append([r[c] + As[c] for c in range(3)])
            frames.append([_rotate_quad(p, [vec[key][c, 0] for c in range(3)]) for key in keys])
        d = [pos[1][c] - pos[0][c] for c in range(3)]
        L0 = ctx.params.scal[self.length]
        return corotated_deformations(d, frames, L0), seeds

    def local_forces(self, ctx: Ctx, order: int = 1) -> tuple[list, list, list[tuple[int, int]]]:
        """(f, dl, seeds): the 7 local forces (elastic + damping) (k,), the deformation jets
        (of ``order`` 1 or 2)."""
        dl, seeds = self.deformations(ctx, order)
        L, EA, GJ, EIy, EIz = self._section(ctx.params)
        f = energy_gradients([x.v for x in dl], L, EA, GJ, EIy, EIz)
        beta = ctx.params.pv[self.idx["damping"]]
        if seeds:
            qd = np.concatenate([ctx.qd[a:a + n] for a, n in seeds]).T           # (k, n_s)
            rates = [np.sum(x.g * qd, axis=-1) for x in dl]
            fd = energy_gradients(rates, L, EA, GJ, EIy, EIz)
            f = [f[m] + beta * fd[m] for m in range(7)]
        return f, dl, seeds

    def add(self, ctx: Ctx, out: Array) -> None:
        f, dl, seeds = self.local_forces(ctx)
        if not seeds:
            return
        grad = sum(f[m][:, None] * dl[m].g for m in range(7))                   # ∂Π/∂q (k, n_s)
        j = 0
        for a, n in seeds:
            out[a:a + n] -= grad[:, j:j + n].T
            j += n

    def add_jacobians(self, t: float, q: Array, qd: Array, prm: MBParams, Kq: Array, Kqd: Array) -> None:
        """Kq += ∂Q/∂q and Kqd += ∂Q/∂q̇ (n_q, n_q) at one state, exact: with the deformation
        jets' gradients B = ∂e/∂q, Hessians H_m = ∂²e_m/∂q², the (constant) local stiffness D
        and the local forces f = D (e + β ė), ė = B q̇,
        ∂Q/∂q = −(Bᵀ D B + Σ_m f_m H_m + β Bᵀ D [H_m q̇]_m), ∂Q/∂q̇ = −β Bᵀ D B."""
        ctx = Ctx(q[:, None], qd[:, None], np.zeros((q.shape[0], 1)), prm, t)
        f, dl, seeds = self.local_forces(ctx, order=2)
        if not seeds:
            return
        L, EA, GJ, EIy, EIz = self._section(prm)
        section = {"L": L, "EA": EA, "GJ": GJ, "EIy": EIy, "EIz": EIz}
        D = local_stiffness(section, np.zeros((), np.result_type(q, prm.pv)))
        B = np.stack([x.g[0] for x in dl])                                       # (7, n_s)
        rows = np.concatenate([np.arange(a, a + n) for a, n in seeds])
        qds = qd[rows]
        beta = prm.pv[self.idx["damping"]]
        DB = D @ B
        Hqd = np.stack([x.H[0] @ qds for x in dl])                               # ∂ė/∂q (7, n_s)
        Kq[np.ix_(rows, rows)] -= B.T @ DB + sum(f[m][0] * dl[m].H[0] for m in range(7)) + beta * (DB.T @ Hqd)
        Kqd[np.ix_(rows, rows)] -= beta * (B.T @ DB)

    # ---------------------------------------------------------------- mass
    def lump_mass(self, prm: MBParams) -> None:
        """ρAL/2 on each moving node's mass and the rotary inertia about the element axes."""
        pv, i = prm.pv, self.idx
        L = prm.scal[self.length]
        m = pv[i["density"]] * pv[i["area"]] * L
        moments = (pv[i["density"]] * (pv[i["Iy"]] + pv[i["Iz"]]) * L / 2, m * L * L / 78, m * L * L / 78)
        for pt, keys in zip((self.point_1, self.point_2), self.axes):
            if pt.body == GROUND:
                continue
            bp = prm.bodies[pt.body]
            bp.mass = bp.mass + m / 2
            rot = sum(Ij * (prm.vec[key] @ prm.vec[key].T) for Ij, key in zip(moments, keys))
            bp.inertia = bp.inertia + rot

    def grounded_mass(self, prm: MBParams) -> Any:
        """The half of the member's mass on a ground node (counted by the ``mass`` response)."""
        pv, i = prm.pv, self.idx
        half = 0.5 * pv[i["density"]] * pv[i["area"]] * prm.scal[self.length]
        return sum(half for pt in (self.point_1, self.point_2) if pt.body == GROUND)

    def output(self, model: Any, kind: Any, path: str, problems: ProblemCollector) -> Output | None:
        """``{element: BEAM, kind: force | moments}`` (one state at a time)."""
        if kind not in BEAM_KINDS:
            problems.add(f"{path}.kind", f"unknown beam quantity {kind!r}{did_you_mean(kind, BEAM_KINDS)} "
                                         f"(known: {', '.join(BEAM_KINDS)})")
            return None

        def fn(t: float, s: StepState, prm: Any) -> Any:
            f = self.local_forces(Ctx(s.q[:, None], s.qd[:, None], s.qdd[:, None], prm, t))[0]
            return np.array([f[0][0]]) if kind == "force" else np.array([x[0] for x in f[1:]])
        labels = (f"{self.name}.N",) if kind == "force" else \
            tuple(f"{self.name}.{c}" for c in ("Mx1", "My1", "Mz1", "Mx2", "My2", "Mz2"))
        return Output(fn, labels)


def member_node(rd: Reader, ref: Any, path: str) -> tuple[BodyDef, str] | None:
    """A member end: ``body`` (its COM) or ``body.marker`` (the ground only through a marker);
    (body, vec key of the point in body axes) or None once a problem is reported."""
    if not isinstance(ref, str):
        rd.problems.add(path, f"expected a body name or 'body.marker', found {ref!r}")
        return None
    if "." in ref:
        return rd.marker_ref(ref, path)
    body = rd.body(ref, path)
    if body is not None and body.index == GROUND:
        rd.problems.add(path, "the ground has no nodal point: name a marker, 'ground.MARKER'")
        return None
    return None if body is None else (body, "zero")


def _beam_node(rd: Reader, ref: Any, path: str) -> tuple[BodyDef, str] | None:
    """A beam end (:func:`member_node`): rigid bodies or the ground only."""
    end = member_node(rd, ref, path)
    if end is not None and end[0].point_mass:
        rd.problems.add(path, f"'{end[0].name}' is a point mass, which has no orientation: a beam needs "
                              "node bodies with rotational inertia (use a bar, or a small rigid body)")
        return None
    return end


def read_beam(rd: Reader, m: dict, mp: str, name: str) -> BeamMember | None:
    """One ``type: beam`` entry at ``mp`` (keys checked by the caller)."""
    nodes = m.get("nodes")
    if not isinstance(nodes, list) or len(nodes) != 2:
        rd.problems.add(f"{mp}.nodes", f"expected [node_1, node_2] (body or body.marker), found {nodes!r}")
        return None
    ends = [_beam_node(rd, ref, f"{mp}.nodes[{k}]") for k, ref in enumerate(nodes)]
    idx = {key: rd.num(m.get(key, 0.0), f"{mp}.{key}", positive=key not in ("density", "damping"),
                       nonnegative=key in ("density", "damping")) for key in SECTION}
    orient = rd.vec3(m.get("orientation"), f"{mp}.orientation", [0.0, 0.0, 1.0])
    if ends[0] is None or ends[1] is None:
        return None
    (b1, k1), (b2, k2) = ends  # type: ignore[misc]
    if b1 is b2:
        rd.problems.add(f"{mp}.nodes", "a member needs two different node bodies")
        return None
    g1, g2 = rd.global_point_recipe(b1, k1), rd.global_point_recipe(b2, k2)
    rd.scal.append((f"{name}.L0", lambda prm: np.sqrt(np.sum((g2(prm) - g1(prm)) ** 2))))

    def axis(prm: MBParams, j: int) -> Any:
        """The element's initial axis e_j (global): e₁ along the chord, e₂ from ``orientation``."""
        d = g2(prm) - g1(prm)
        e1 = d / np.sqrt(np.sum(d * d))
        v = np.array([prm.pv[i] for i in orient])
        if abs(np.real(np.sum(v * e1))) > (1 - 1e-9) * np.sqrt(np.real(np.sum(v * v))):
            v = np.array([0.0, 1.0, 0.0])       # the default's fallback: global y for a beam along z
        e2 = v - np.sum(v * e1) * e1
        e2 = e2 / np.sqrt(np.sum(e2 * e2))
        return (e1, e2, np.cross(e1, e2))[j]
    axes = tuple(tuple(rd.local_direction(b, f"mb:{name}.e{j + 1}.{n}", lambda prm, _j=j: axis(prm, _j))
                       for j in range(3)) for n, b in (("1", b1), ("2", b2)))
    return BeamMember(name, Point(b1.index, k1), Point(b2.index, k2), axes, idx,  # type: ignore[arg-type]
                      f"{name}.L0")

