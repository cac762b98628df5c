r"""Space-frame beams (``dim: 3``): Euler–Bernoulli bending in two planes, axial and St-Venant
torsion; small rotations, or large ones with co-rotational kinematics.

Each beam has six unknowns per node in global coordinates, u = (u_x, u_y, u_z, θ_x, θ_y, θ_z):
three translations and a small rotation vector.  The element frame is explicit: the local x
axis e₁ runs along the chord X₂ − X₁, the local y axis e₂ is the part of the ``orientation``
vector v normal to it (default: global z, or global y for a beam along z), e₃ = e₁ × e₂.
With the rotation T = blockdiag(R, R, R, R), R = [e₁; e₂; e₃], the element stiffness and
mass are K = Tᵀ K_l T, M = Tᵀ M_l T, K_l the textbook 12 × 12 matrix (EA/L axial, GJ/L
torsion, EI_z (12, 6L, 4L², 2L²)/L³ for bending in the local x–y plane, EI_y with the
opposite coupling sign in the x–z plane).

Rotations (``kinematics: small``, the default): the element is linear (K constant), the
rotation vector is additive and the Newmark update handles it like any other unknown.
``kinematics: corotational`` (:mod:`dynsens.models.structural.beams3d_corot`): large displacements and
rotations; the node unknowns are then a total rotation vector ψ per node (R_i = exp(ψ_i)R₀), still a
vector that Newmark updates additively (no multiplicative update is needed), regular for
|ψ| < 2π; chosen over incremental rotation vectors because the state stays a plain vector in
global coordinates, which the sensitivity and adjoint machinery and a later coupling to rigid
bodies take as they are.  Its lumped rotary inertia acts on ψ̈ in global axes (exact for small
rotations and for turning about a fixed axis; otherwise the rotary inertia, a share ~(h/L)² of
the translational one, is approximate); consistent mass is refused with it.

Mass: ``lumped`` ρAL/2 per translation, ρAL³/78 per bending rotation (HRZ, as the plane beam)
and ρI_pL/2 per twist (I_p = I_y + I_z); or ``consistent`` (cubic-Hermite bending, linear
axial and torsion with ρI_p), constant in global coordinates.

Sections: ``{A, Iy, Iz, J, cy, cz}`` (c: extreme-fibre distances along local y and z), or
the plane beam's shapes: ``tube`` D, t (J = I_p), ``rectangle`` b, h and ``box`` b, h, t
(h along local y, b along local z; J of a rectangle by Roark's series, of a box by Bredt's
formula for the mid-wall line).  Stresses at the extreme fibres of both ends:
σ = N/A ± (|M_y| c_z/I_y + |M_z| c_y/I_z) (corners of a rectangle, box or given properties),
σ = N/A ± √(M_y² + M_z²)·(D/2)/I for a tube.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ...case_keys import allowed
from ...errors import ProblemCollector
from .._keys import check_keys, did_you_mean
from .beams import append_section
from .beams3d_corot import deformations, element_forces, local_deformations, local_forces
from ..parameters import ParameterTable

SHAPES3 = {"tube": ("D", "t"), "rectangle": ("b", "h"), "box": ("b", "h", "t"),
           "properties": ("A", "Iy", "Iz", "J", "cy", "cz")}


def _abs(x: Any) -> Any:
    """|x| branching on the real part (complex step passes through)."""
    return np.where(np.real(x) < 0, -x, x)


def section_properties_3d(shape: str, dims: list[Any]) -> tuple[Any, ...]:
    """(A, I_y, I_z, J, c_y, c_z) of a section (complex-safe); h along local y, b along z."""
    if shape == "tube":
        D, t = dims
        d = D - 2 * t
        area, inertia = np.pi / 4 * (D * D - d * d), np.pi / 64 * (D ** 4 - d ** 4)
        return area, inertia, inertia, 2 * inertia, D / 2, D / 2
    if shape == "rectangle":
        b, h = dims
        long, short = (h, b) if np.real(h) >= np.real(b) else (b, h)
        r = short / long
        J = long * short ** 3 * (1 / 3 - 0.21 * r * (1 - r ** 4 / 12))
        return b * h, h * b ** 3 / 12, b * h ** 3 / 12, J, h / 2, b / 2
    if shape == "box":
        b, h, t = dims
        bi, hi = b - 2 * t, h - 2 * t
        bm, hm = b - t, h - t                   # mid-wall line
        J = 2 * t * bm * bm * hm * hm / (bm + hm)
        return b * h - bi * hi, (h * b ** 3 - hi * bi ** 3) / 12, (b * h ** 3 - bi * hi ** 3) / 12, J, h / 2, b / 2
    return tuple(dims)


def _symmetric(L: Any, entries: list[tuple[int, int, Any]]) -> np.ndarray:
    """(n_e, 12, 12) symmetric matrices with the upper-triangle ``entries`` (i, j, value)."""
    M = np.zeros(np.shape(L) + (12, 12), dtype=np.result_type(L, *(v for _, _, v in entries)))
    for i, j, v in entries:
        M[..., i, j] = v
        M[..., j, i] = v
    return M


def local_stiffness(L: Any, EA: Any, GJ: Any, EIy: Any, EIz: Any) -> np.ndarray:
    """Textbook local stiffness (n_e, 12, 12); unknowns per node u, v, w, θx, θy, θz."""
    e: list[tuple[int, int, Any]] = []
    for a, b, k in ((0, 6, EA / L), (3, 9, GJ / L)):
        e += [(a, a, k), (b, b, k), (a, b, -k)]
    # bending in x–y (v, θz: 1, 5, 7, 11) and in x–z (w, θy: 2, 4, 8, 10; coupling sign flipped)
    for (v1, r1, v2, r2), EI, s in (((1, 5, 7, 11), EIz, 1.0), ((2, 4, 8, 10), EIy, -1.0)):
        c = EI / L ** 3
        e += [(v1, v1, 12 * c), (v2, v2, 12 * c), (v1, v2, -12 * c),
              (v1, r1, s * 6 * L * c), (v1, r2, s * 6 * L * c), (r1, v2, -s * 6 * L * c), (v2, r2, -s * 6 * L * c),
              (r1, r1, 4 * L * L * c), (r2, r2, 4 * L * L * c), (r1, r2, 2 * L * L * c)]
    return _symmetric(L, e)


def local_mass(L: Any, m: Any, Ip_per_A: Any) -> np.ndarray:
    """Consistent local mass (n_e, 12, 12) of element mass m = ρAL; torsion with ρI_p."""
    e: list[tuple[int, int, Any]] = []
    for a, b, k in ((0, 6, m / 6), (3, 9, m * Ip_per_A / 6)):
        e += [(a, a, 2 * k), (b, b, 2 * k), (a, b, k)]
    c = m / 420
    for (v1, r1, v2, r2), s in (((1, 5, 7, 11), 1.0), ((2, 4, 8, 10), -1.0)):
        e += [(v1, v1, 156 * c), (v2, v2, 156 * c), (v1, v2, 54 * c),
              (v1, r1, s * 22 * L * c), (v1, r2, -s * 13 * L * c), (r1, v2, s * 13 * L * c), (v2, r2, -s * 22 * L * c),
              (r1, r1, 4 * L * L * c), (r2, r2, 4 * L * L * c), (r1, r2, -3 * L * L * c)]
    return _symmetric(L, e)


@dataclass
class Beam3DSet:
    """The space-frame beams of a model: 12 DOF indices each (node 1 then node 2, each
    x, y, z, rx, ry, rz; index n is the fixed slot) and their parameter indices."""

    names: list[str] = field(default_factory=list)
    dofs: list[list[int]] = field(default_factory=list)
    coords: list[list[int]] = field(default_factory=list)     # X1, Y1, Z1, X2, Y2, Z2
    orientation: list[list[float]] = field(default_factory=list)
    E: list[int] = field(default_factory=list)
    G: list[int] = field(default_factory=list)
    rho: list[int] = field(default_factory=list)
    shape: list[str] = field(default_factory=list)
    dims: list[list[int]] = field(default_factory=list)
    consistent: list[bool] = field(default_factory=list)
    corot: list[bool] = field(default_factory=list)

    STACK_KEYS = ("frame_K", "frame_M", "frame_T", "frame_D0", "frame_R0", "frame_L", "frame_EA", "frame_GJ",
                  "frame_EIy", "frame_EIz", "frame_A", "frame_Wy", "frame_Wz", "frame_round")

    def freeze(self) -> None:
        """Index arrays for vectorized evaluation."""
        self.idx = np.array(self.dofs, dtype=int).reshape(-1, 12)
        self.X = np.array(self.coords, dtype=int).reshape(-1, 6)
        self.v = np.array([v or [0.0, 0.0, 0.0] for v in self.orientation], dtype=float).reshape(-1, 3)
        self.E_idx, self.G_idx, self.rho_idx = (np.array(a, int) for a in (self.E, self.G, self.rho))
        self.is_consistent = np.array(self.consistent, bool)
        self.round = np.array([s == "tube" for s in self.shape], bool)
        self.is_corot = np.array(self.corot, bool)

    def __len__(self) -> int:
        return len(self.names)

    def parameters(self, pv: np.ndarray, out: dict[str, Any]) -> None:
        """Element frames, global stiffness and mass matrices for parameters ``pv`` (keys ``frame_*``)."""
        X = pv[self.X]
        D0 = X[:, 3:] - X[:, :3]
        L = np.sqrt(np.sum(D0 * D0, axis=1))
        e1 = D0 / L[:, None]
        # default orientation: global z, or global y for a beam (nearly) along z
        along_z = np.abs(np.real(e1[:, 2])) > 0.99
        default = np.where(along_z[:, None], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0])
        v = np.where(np.any(self.v != 0, axis=1)[:, None], self.v, default)
        y = v - np.sum(v * e1, axis=1)[:, None] * e1
        e2 = y / np.sqrt(np.sum(y * y, axis=1))[:, None]
        R = np.stack([e1, e2, np.cross(e1, e2)], axis=1)                     # (n_e, 3, 3) rows e1, e2, e3
        T = np.zeros((len(L), 12, 12), dtype=R.dtype)
        for k in range(4):
            T[:, 3 * k:3 * k + 3, 3 * k:3 * k + 3] = R
        props = [section_properties_3d(s, [pv[i] for i in d]) for s, d in zip(self.shape, self.dims)]
        A, Iy, Iz, J, cy, cz = (np.array([p[k] for p in props], dtype=pv.dtype) for k in range(6))
        E, G, rho = pv[self.E_idx], pv[self.G_idx], pv[self.rho_idx]
        Kl = local_stiffness(L, E * A, G * J, E * Iy, E * Iz)
        m = rho * A * L
        Ml = local_mass(L, m, (Iy + Iz) / A)
        out.update(frame_T=T, frame_D0=D0, frame_R0=R, frame_L=L, frame_EA=E * A, frame_GJ=G * J,
                   frame_EIy=E * Iy, frame_EIz=E * Iz,
                   frame_A=A, frame_Wy=Iy / cz, frame_Wz=Iz / cy, frame_round=self.round, frame_mass=m,
                   frame_rhoIp=rho * (Iy + Iz) * L,
                   frame_K=np.einsum("eji,ejk,ekl->eil", T, Kl, T),
                   frame_M=np.einsum("eji,ejk,ekl->eil", T, Ml, T))

    def lumped_mass(self, params: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
        """(DOF indices, masses) of the lumped beams: ρAL/2 per translation, ρAL³/78 per
        bending rotation, ρI_pL/2 per twist, each about the element axes turned to global (the
        diagonal of Rᵀ diag(twist, bend, bend) R per node)."""
        lump = ~self.is_consistent
        m, L = params["frame_mass"][lump], params["frame_L"][lump]
        R = params["frame_T"][lump, :3, :3]
        rot = np.einsum("eki,ek,eki->ei", R, np.stack([params["frame_rhoIp"][lump] / 2, m * L * L / 78,
                                                        m * L * L / 78], axis=1), R)
        half = np.repeat((m / 2)[:, None], 3, axis=1)
        return self.idx[lump], np.concatenate([half, rot, half, rot], axis=1)

    def consistent_entries(self, params: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rows, cols, values) of the consistent beams' constant global mass matrices."""
        sel = self.is_consistent
        idx = self.idx[sel]
        return np.repeat(idx, 12, axis=1).ravel(), np.tile(idx, (1, 12)).ravel(), params["frame_M"][sel].ravel()

    def inertia(self, qdde: np.ndarray, params: dict[str, Any]) -> np.ndarray:
        """M ü of the consistent beams (..., n_c, 12)."""
        return np.einsum("...eij,...ej->...ei", params["frame_M"][..., self.is_consistent, :, :],
                         qdde[..., self.idx[self.is_consistent]])

    def _corot(self, params: dict[str, Any]) -> dict[str, Any]:
        """The co-rotational beams' data (``frame_*`` entries restricted to them)."""
        cr = self.is_corot
        return {k: params[f"frame_{k}"][..., cr, :, :] if k == "R0" else
                params[f"frame_{k}"][..., cr, :] if k == "D0" else params[f"frame_{k}"][..., cr]
                for k in ("D0", "L", "R0", "EA", "GJ", "EIy", "EIz")}

    def forces(self, qe: np.ndarray, params: dict[str, Any]) -> np.ndarray:
        """Element end forces and moments (..., n_e, 12) in global coordinates: K u, or ∇Π of
        the co-rotational beams."""
        f = np.einsum("...eij,...ej->...ei", params["frame_K"], qe[..., self.idx])
        if not self.is_corot.any():
            return f
        f_cr, _ = element_forces(qe[..., self.idx[self.is_corot]], self._corot(params), 1)
        f = f.astype(np.result_type(f, f_cr))
        f[..., self.is_corot, :] = f_cr
        return f

    def deformations(self, qe: np.ndarray, params: dict[str, Any], hessian: bool = False
                     ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """(B, H, D) of the co-rotational beams' local deformations at qe (..., n+1) (see
        :func:`.beams3d_corot.deformations`)."""
        return deformations(qe[..., self.idx[self.is_corot]], self._corot(params), hessian)

    def tangent(self, qe: np.ndarray, params: dict[str, Any], corotated: bool = True
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rows, cols, values) of the element stiffness matrices (∇²Π of the co-rotational
        beams at state qe, one state); without ``corotated`` the linear beams' only."""
        K = params["frame_K"]
        if not corotated:
            K = np.where(self.is_corot[:, None, None], 0.0, K)
        elif self.is_corot.any():
            _, K_cr = element_forces(qe[self.idx[self.is_corot]], self._corot(params), 2)
            K = K.astype(np.result_type(K, K_cr))
            K[self.is_corot] = K_cr
        return np.repeat(self.idx, 12, axis=1).ravel(), np.tile(self.idx, (1, 12)).ravel(), K.ravel()

    def end_forces(self, qe: np.ndarray, params: dict[str, Any]) -> np.ndarray:
        """Section forces (..., n_e, 6): N, T, M_y1, M_z1, M_y2, M_z2 (sagging/tension positive;
        the moments as the beam's own, not the nodal reactions: end 1 negated), in the element
        frame (the current one of a co-rotational beam)."""
        fl = np.einsum("...eij,...ej->...ei", params["frame_T"], self.forces(qe, params))
        out = np.stack([fl[..., 6], fl[..., 9], -fl[..., 4], -fl[..., 5], fl[..., 10], fl[..., 11]], axis=-1)
        if self.is_corot.any():
            n, _, m1y, m1z, m2x, m2y, m2z = local_forces(qe[..., self.idx[self.is_corot]], self._corot(params))
            cr = np.stack([n, m2x, -m1y, -m1z, m2y, m2z], axis=-1)
            out = out.astype(np.result_type(out, cr))
            out[..., self.is_corot, :] = cr
        return out

    def fibre_stress(self, qe: np.ndarray, params: dict[str, Any]) -> np.ndarray:
        """Largest and smallest fibre stresses (..., n_e, 4): end 1 +, −, end 2 +, −."""
        f = self.end_forces(qe, params)
        axial = f[..., 0] / params["frame_A"]
        out = []
        for My, Mz in ((f[..., 2], f[..., 3]), (f[..., 4], f[..., 5])):
            corner = _abs(My) / params["frame_Wy"] + _abs(Mz) / params["frame_Wz"]
            sq = My * My + Mz * Mz
            resultant = np.where(np.real(sq) > 0, np.sqrt(np.where(np.real(sq) > 0, sq, 1.0)), 0.0) / params["frame_Wy"]
            bend = np.where(params["frame_round"], resultant, corner)
            out += [axial + bend, axial - bend]
        return np.stack(out, axis=-1)

    def range_problem(self, qe: np.ndarray, params: dict[str, Any]) -> str | None:
        """Why a state leaves the co-rotational beams' range (a node rotation vector near a full
        turn, or a local rotation beyond 0.5 rad, where the element is too long for the bend), or None."""
        if not self.is_corot.any():
            return None
        Ue = np.real(qe[self.idx[self.is_corot]])
        psi = np.sqrt(np.sum(np.concatenate([Ue[:, 3:6], Ue[:, 9:12]]) ** 2, axis=1))
        if psi.max() > 1.9 * np.pi:
            return (f"a node of a corotational 3D beam turned by |ψ| = {psi.max():.4g} rad, near one full turn "
                    f"(2π), where its rotation vector is singular")
        prm = self._corot(params)
        dl = local_deformations([Ue[:, i] for i in range(12)], *(np.real(prm[k]) for k in ("D0", "L", "R0")))
        theta = np.abs(np.array(dl[1:]))                                # (6, n_c) local rotations
        if theta.max() > 0.5:
            e = np.flatnonzero(self.is_corot)[int(np.argmax(theta.max(axis=0)))]
            return (f"corotational 3D beam {self.names[e]!r} bends by {theta.max():.3g} rad within the element "
                    f"(more than 0.5 rad): use shorter elements")
        return None

    def design_touch(self) -> list[tuple[list[int], np.ndarray]]:
        """Per beam: the parameter indices it reads and its DOFs (for the column colouring)."""
        return [([*self.X[e], self.E_idx[e], self.G_idx[e], self.rho_idx[e], *self.dims[e]], self.idx[e])
                for e in range(len(self))]


def parse_beam_3d(el: dict, ep: str, name: str, beams: Beam3DSet, table: ParameterTable,
                  node_dofs: Callable[[Any, str], list[int]], node_coords: dict[str, list[int]],
                  problems: ProblemCollector, given_coords: dict[str, Any] | None = None) -> None:
    """Read one ``type: beam`` element entry of a ``dim: 3`` model into ``beams``; node_dofs
    gives a node's (x, y, z, rx, ry, rz) DOFs; ``given_coords`` (the nodes' ``coords`` entries)
    let an ``orientation`` along the beam be refused when the coordinates are numbers."""
    check_keys(el, ep, allowed("structural.beam"), problems, required=("nodes", "E", "G", "section"))
    pair = el.get("nodes", [])
    if not isinstance(pair, list) or len(pair) != 2:
        problems.add(f"{ep}.nodes", f"expected [node_a, node_b], found {pair!r}")
        return
    sec = el.get("section")
    shape = _section_shape(sec, ep, problems)
    if shape is None:
        return
    assert isinstance(sec, dict)
    needed = SHAPES3[shape]
    mass, kinematics = _mass_and_kinematics(el, ep, problems)
    v = el.get("orientation")
    dofs = node_dofs(pair[0], f"{ep}.nodes") + node_dofs(pair[1], f"{ep}.nodes")
    if any(p not in node_coords for p in pair):
        return
    if not _orientation_ok(v, [(given_coords or {}).get(p) for p in pair], ep, problems):
        return
    table.require_apart(node_coords[pair[0]], node_coords[pair[1]], f"{ep}.nodes", "beam")
    beams.names.append(name)
    beams.dofs.append(dofs)
    beams.coords.append(node_coords[pair[0]] + node_coords[pair[1]])
    beams.orientation.append([float(c) for c in v] if v is not None else [])
    beams.E.append(table.add(el.get("E"), f"{ep}.E", problems, positive=True))
    beams.G.append(table.add(el.get("G"), f"{ep}.G", problems, positive=True))
    beams.rho.append(table.add(el.get("density", 0.0), f"{ep}.density", problems, nonnegative=True))
    append_section(beams, shape, needed, sec, ep, table, problems, mass == "consistent")
    beams.corot.append(kinematics == "corotational")


def _section_shape(sec: Any, ep: str, problems: ProblemCollector) -> str | None:
    """The shape of a 3D beam's ``section`` with exactly its dimensions, or None with a problem listed."""
    if not check_keys(sec, f"{ep}.section", allowed("structural.beam_section"), problems) or not isinstance(sec, dict):
        return None
    shape = sec.get("shape", "properties")
    if shape not in SHAPES3:
        problems.add(f"{ep}.section.shape", f"unknown shape {shape!r}{did_you_mean(shape, SHAPES3)}")
        return None
    needed = SHAPES3[shape]
    extra = [k for k in sec if k != "shape" and k not in needed]
    missing = [k for k in needed if k not in sec]
    if extra or missing:
        problems.add(f"{ep}.section", f"a {shape} section of a 3D beam takes {', '.join(needed)}"
                                      + (f"; not {', '.join(extra)}" if extra else "")
                                      + (f"; missing {', '.join(missing)}" if missing else ""))
        return None
    return str(shape)


def _mass_and_kinematics(el: dict, ep: str, problems: ProblemCollector) -> tuple[Any, Any]:
    """The beam's ``mass`` (lumped or consistent) and ``kinematics`` (small or corotational)."""
    mass = el.get("mass", "lumped")
    if mass not in ("lumped", "consistent"):
        problems.add(f"{ep}.mass", f"expected lumped or consistent, found {mass!r}")
    kinematics = el.get("kinematics", "small")
    if kinematics not in ("small", "corotational"):
        problems.add(f"{ep}.kinematics", f"expected small or corotational, found {kinematics!r}")
    elif kinematics == "corotational" and mass == "consistent":
        problems.add(f"{ep}.mass", "a corotational 3D beam has lumped mass only, so far")
    return mass, kinematics


def _numbers(v: Any, length: int) -> bool:
    """Whether v is a list of ``length`` plain numbers (not booleans)."""
    return isinstance(v, list) and len(v) == length and all(
        isinstance(c, (int, float)) and not isinstance(c, bool) for c in v)


def _orientation_ok(v: Any, ends: list[Any], ep: str, problems: ProblemCollector) -> bool:
    """Whether the ``orientation`` v (None: the default) is a non-zero vector that crosses the
    beam axis (checked where both ends' coordinates are numbers); else a problem listed."""
    if v is None:
        return True
    if not _numbers(v, 3) or not np.any(np.asarray(v, float)):
        problems.add(f"{ep}.orientation", f"expected a non-zero vector [x, y, z], found {v!r}")
        return False
    if all(_numbers(c, 3) for c in ends):
        d = np.asarray(ends[1], float) - np.asarray(ends[0], float)
        w = np.asarray(v, float)
        if np.linalg.norm(np.cross(d, w)) <= 1e-9 * np.linalg.norm(d) * np.linalg.norm(w):
            problems.add(f"{ep}.orientation", f"the orientation {v} is parallel to the beam (it sets local y, "
                                              f"which must cross the beam axis)")
            return False
    return True
