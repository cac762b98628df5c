r"""Plane co-rotational Euler–Bernoulli beams (frames in the x–y plane).

Each beam has the nodal unknowns (u_x, u_y, θ_z) at both ends, in global coordinates.  The
element follows its chord: with d = X₂ − X₁ + u₂ − u₁, ℓ = |d|, the rigid rotation α of the
chord from its initial direction and the local deformations

.. math:: u_l = ℓ − L,\quad θ_{1l} = θ_1 − α,\quad θ_{2l} = θ_2 − α,

the local forces are N = EA u_l/L, M₁ = (2EI/L)(2θ_{1l} + θ_{2l}), M₂ = (2EI/L)(θ_{1l} + 2θ_{2l})
and the global internal force is f = N r + M₁(e₃ − z/ℓ) + M₂(e₆ − z/ℓ) with r = ∂ℓ/∂u =
[−c, −s, 0, c, s, 0], z = ℓ ∂α/∂u = [s, −c, 0, −s, c, 0].  Its exact tangent is

.. math:: K = Bᵀ D B + (N/ℓ) z zᵀ + ((M₁ + M₂)/ℓ²)(r zᵀ + z rᵀ),

B the rows [r; e₃ − z/ℓ; e₆ − z/ℓ], D = [[EA/L, 0, 0], [0, 4EI/L, 2EI/L], [0, 2EI/L, 4EI/L]].
Rotations of any size are allowed: α is taken on the branch nearest the nodal rotations, so
local rotations stay small while the element turns through several revolutions.

Mass: ``lumped`` (ρAL/2 per node and direction, ρAL³/78 per rotation: HRZ lumping) or ``consistent``:
the cubic-Hermite mass M_l of the element taken in its chord frame, so that it turns with the
element, M(β) = Tᵀ(β) M_l T(β) (β the current chord angle): the position-dependent mass of the
governing equation.  Its inertia forces follow from Lagrange's equations with the kinetic energy
T = ½ u̇ᵀ M(β) u̇: M ü + (M'u̇)(g·u̇) − ½(u̇ᵀM'u̇) g, g = ∂β/∂u, with exact Jacobians.

Sections: ``{A, I, c}`` given directly (c: distance of the extreme fibre from the neutral
axis, for stresses), or ``{shape: tube, D, t}``, ``{shape: rectangle, b, h}``, ``{shape: box,
b, h, t}`` whose dimensions may be design expressions (bending about the axis ⟂ to h).
Stresses at the extreme fibres of both ends: σ = N/A ± M c/I.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ...case_keys import allowed
from ...errors import ProblemCollector
from .._keys import check_keys, did_you_mean
from ..parameters import ParameterTable

SHAPES = {"tube": ("D", "t"), "rectangle": ("b", "h"), "box": ("b", "h", "t"), "properties": ("A", "I", "c")}
#: shapes with a wall t that must leave a hole (2·t below every outer width)
HOLLOW = ("tube", "box")
MASS_KINDS = ("lumped", "consistent")
BEAM_KEYS = allowed("structural.beam")


def section_properties(shape: str, dims: list[Any]) -> tuple[Any, Any, Any]:
    """Area A, second moment of area I and extreme-fibre distance c of a section (complex-safe).

    tube: outer diameter D, wall t; rectangle: width b, height h; box: b, h, wall t;
    properties: (A, I, c) themselves.  Units: length of the case (A in length², I in length⁴).
    """
    if shape == "tube":
        D, t = dims
        d = D - 2 * t
        return np.pi / 4 * (D * D - d * d), np.pi / 64 * (D ** 4 - d ** 4), D / 2
    if shape == "rectangle":
        b, h = dims
        return b * h, b * h ** 3 / 12, h / 2
    if shape == "box":
        b, h, t = dims
        bi, hi = b - 2 * t, h - 2 * t
        return b * h - bi * hi, (b * h ** 3 - bi * hi ** 3) / 12, h / 2
    A, I, c = dims
    return A, I, c


def _angle(y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """atan2(y, x) elementwise, complex-safe for complex-step perturbations (first order in the
    imaginary parts, which is exact to round-off for steps of 1e-20)."""
    base = np.arctan2(np.real(y), np.real(x))
    if not (np.iscomplexobj(y) or np.iscomplexobj(x)):
        return base
    xr, yr = np.real(x), np.real(y)
    return base + 1j * (xr * np.imag(y) - yr * np.imag(x)) / (xr * xr + yr * yr)


@dataclass
class BeamSet:
    """The plane beams of a model: 6 DOF indices each (x, y, θ of node 1, then of node 2; index n
    is the fixed slot) and their parameter indices."""

    names: list[str] = field(default_factory=list)
    dofs: list[list[int]] = field(default_factory=list)
    coords: list[list[int]] = field(default_factory=list)    # X1, Y1, X2, Y2
    E: list[int] = field(default_factory=list)
    rho: list[int] = field(default_factory=list)
    shape: list[str] = field(default_factory=list)
    dims: list[list[int]] = field(default_factory=list)
    consistent: list[bool] = field(default_factory=list)

    def freeze(self) -> None:
        """Index arrays for vectorized evaluation."""
        self.idx = np.array(self.dofs, dtype=int).reshape(-1, 6)
        self.X = np.array(self.coords, dtype=int).reshape(-1, 4)
        self.E_idx, self.rho_idx = np.array(self.E, int), np.array(self.rho, int)
        self.is_consistent = np.array(self.consistent, bool)

    def __len__(self) -> int:
        return len(self.names)

    # ------------------------------------------------------------------ parameters
    def parameters(self, pv: np.ndarray, out: dict[str, Any]) -> None:
        """Derived beam data for the parameter vector ``pv`` into ``out`` (keys ``beam_*``)."""
        X = pv[self.X]
        D0 = X[:, 2:] - X[:, :2]
        L = np.sqrt(np.sum(D0 * D0, axis=1))
        props = [section_properties(s, [pv[i] for i in d]) for s, d in zip(self.shape, self.dims)]
        A, I, c = (np.array([p[k] for p in props], dtype=pv.dtype) for k in range(3))
        E, rho = pv[self.E_idx], pv[self.rho_idx]
        out.update(beam_D0=D0, beam_L=L, beam_EA=E * A, beam_EI=E * I, beam_A=A, beam_I=I, beam_c=c,
                   beam_rhoA=rho * A, beam_mass=rho * A * L)
        if self.is_consistent.any():
            out["beam_Ml"] = self.local_mass(out)

    STACK_KEYS = ("beam_D0", "beam_L", "beam_EA", "beam_EI", "beam_A", "beam_I", "beam_c", "beam_Ml")

    def lumped_mass(self, params: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
        """(DOF indices, masses) of the lumped beams: ρAL/2 per translation and ρAL³/78 per
        rotation (the consistent mass's diagonal scaled to the element mass, HRZ lumping)."""
        lump = ~self.is_consistent
        m, L = params["beam_rhoA"][lump] * params["beam_L"][lump], params["beam_L"][lump]
        half, rot = m / 2, m * L * L / 78
        vals = np.stack([half, half, rot, half, half, rot], axis=1)
        return self.idx[lump], vals

    def local_mass(self, params: dict[str, Any]) -> np.ndarray:
        """Cubic-Hermite (consistent) mass matrices (n_c, 6, 6) of the consistent beams in their
        chord frame (axial, transverse, rotation at each end)."""
        sel = np.flatnonzero(self.is_consistent)
        L, m = params["beam_L"][sel], params["beam_rhoA"][sel] * params["beam_L"][sel]
        z = np.zeros_like(L)
        one = z + 1
        l2 = L * L
        return np.stack([
            [140 * one, z, z, 70 * one, z, z],
            [z, 156 * one, 22 * L, z, 54 * one, -13 * L],
            [z, 22 * L, 4 * l2, z, 13 * L, -3 * l2],
            [70 * one, z, z, 140 * one, z, z],
            [z, 54 * one, 13 * L, z, 156 * one, -22 * L],
            [z, -13 * L, -3 * l2, z, -22 * L, 4 * l2]]).transpose(2, 0, 1) * (m / 420)[:, None, None]

    def turning_mass(self, qe: np.ndarray, params: dict[str, Any]) -> dict[str, np.ndarray]:
        """Mass M(β) = Tᵀ M_l T of the consistent beams at their current chord angle β and its
        first two β-derivatives; g = ∂β/∂u and ℓ, r, z (batch axes allowed)."""
        sel = np.flatnonzero(self.is_consistent)
        U = qe[..., self.idx[sel]]
        D0 = params["beam_D0"][..., sel, :]
        d = D0 + U[..., 3:5] - U[..., 0:2]
        ell = np.sqrt(np.sum(d * d, axis=-1))
        c, s = d[..., 0] / ell, d[..., 1] / ell
        zero, one = 0 * c, 0 * c + 1

        def rot(a: Any, b: Any, e: Any) -> np.ndarray:      # [[a, b, 0], [-b, a, 0], [0, 0, e]] per end
            R = np.stack([np.stack([a, b, zero], -1), np.stack([-b, a, zero], -1),
                          np.stack([zero, zero, e], -1)], -2)
            T = np.zeros(R.shape[:-2] + (6, 6), dtype=R.dtype)
            T[..., :3, :3] = R
            T[..., 3:, 3:] = R
            return T
        T, T1, T2 = rot(c, s, one), rot(-s, c, zero), rot(-c, -s, zero)   # T(β), T'(β), T''(β)
        Ml = params["beam_Ml"]

        def sandwich(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
            return np.einsum("...ji,...jk,...kl->...il", X, Ml, Y)
        M, M1 = sandwich(T, T), sandwich(T1, T) + sandwich(T, T1)
        M2 = sandwich(T2, T) + 2 * sandwich(T1, T1) + sandwich(T, T2)
        z = np.stack([s, -c, zero, -s, c, zero], axis=-1)
        r = np.stack([-c, -s, zero, c, s, zero], axis=-1)
        return {"M": M, "M1": M1, "M2": M2, "g": z / ell[..., None], "ell": ell, "r": r, "z": z, "sel": sel}

    def inertia(self, qe: np.ndarray, qde: np.ndarray, qdde: np.ndarray, params: dict[str, Any]) -> np.ndarray:
        r"""Inertia forces (..., n_c, 6) of the consistent beams from Lagrange's equations with
        T = ½ u̇ᵀ M(β) u̇:  M ü + (M' u̇)(g·u̇) − ½ (u̇ᵀ M' u̇) g."""
        k = self.turning_mass(qe, params)
        sel = k["sel"]
        V, A = qde[..., self.idx[sel]], qdde[..., self.idx[sel]]
        MV1 = np.einsum("...ij,...j->...i", k["M1"], V)
        gv = np.sum(k["g"] * V, axis=-1)
        return np.einsum("...ij,...j->...i", k["M"], A) + MV1 * gv[..., None] \
            - 0.5 * np.sum(V * MV1, axis=-1)[..., None] * k["g"]

    def inertia_jacobians(self, qe: np.ndarray, qde: np.ndarray, qdde: np.ndarray, params: dict[str, Any]
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(rows, cols) and the exact ∂/∂ü, ∂/∂u̇, ∂/∂u of :meth:`inertia` (flattened, one state)."""
        k = self.turning_mass(qe, params)
        sel = k["sel"]
        V, A = qde[self.idx[sel]], qdde[self.idx[sel]]
        M1, M2, g = k["M1"], k["M2"], k["g"]
        G = -(k["z"][:, :, None] * k["r"][:, None, :] + k["r"][:, :, None] * k["z"][:, None, :]) \
            / (k["ell"] ** 2)[:, None, None]                     # ∂g/∂u
        MV1, MV2, MA1 = (np.einsum("eij,ej->ei", X, y) for X, y in ((M1, V), (M2, V), (M1, A)))
        gv = np.sum(g * V, axis=-1)
        vMv1, vMv2 = np.sum(V * MV1, axis=-1), np.sum(V * MV2, axis=-1)
        GV = np.einsum("eij,ej->ei", G, V)

        def outer(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            return a[:, :, None] * b[:, None, :]
        C = outer(MV1, g) + gv[:, None, None] * M1 - outer(g, MV1)
        K = outer(MA1, g) + gv[:, None, None] * outer(MV2, g) + outer(MV1, GV) \
            - 0.5 * vMv2[:, None, None] * outer(g, g) - 0.5 * vMv1[:, None, None] * G
        idx = self.idx[sel]
        rows, cols = np.repeat(idx, 6, axis=1).ravel(), np.tile(idx, (1, 6)).ravel()
        return rows, cols, k["M"].reshape(-1), C.reshape(-1), K.reshape(-1)

    # ------------------------------------------------------------------ state
    def state(self, qe: np.ndarray, params: dict[str, Any]) -> dict[str, np.ndarray]:
        """Chord, rotation and local forces of all beams for extended states qe (..., n+1)."""
        U = qe[..., self.idx]                                   # (..., n_e, 6)
        D0, L = params["beam_D0"], params["beam_L"]
        du = U[..., 3:5] - U[..., 0:2]
        d = D0 + du
        ell = np.sqrt(np.sum(d * d, axis=-1))
        c, s = d[..., 0] / ell, d[..., 1] / ell
        c0, s0 = D0[..., 0] / L, D0[..., 1] / L
        alpha = _angle(c0 * s - s0 * c, c0 * c + s0 * s)
        th1, th2 = U[..., 2], U[..., 5]
        # the branch of α nearest the nodal rotations (several revolutions allowed)
        turns = np.round((np.real(th1 + th2) / 2 - np.real(alpha)) / (2 * np.pi))
        alpha = alpha + 2 * np.pi * turns
        t1, t2 = th1 - alpha, th2 - alpha
        # ℓ − L written as (2 D0·Δu + Δu·Δu)/(ℓ + L): no cancellation for small displacements
        ul = (2 * np.sum(D0 * du, axis=-1) + np.sum(du * du, axis=-1)) / (ell + L)
        k = 2 * params["beam_EI"] / L
        N = params["beam_EA"] * ul / L
        M1, M2 = k * (2 * t1 + t2), k * (t1 + 2 * t2)
        zero = 0 * c
        r = np.stack([-c, -s, zero, c, s, zero], axis=-1)
        z = np.stack([s, -c, zero, -s, c, zero], axis=-1)
        return {"ell": ell, "N": N, "M1": M1, "M2": M2, "r": r, "z": z}

    def forces(self, qe: np.ndarray, params: dict[str, Any]) -> np.ndarray:
        """Element end forces and moments (..., n_e, 6) in global coordinates."""
        st = self.state(qe, params)
        zl = st["z"] / st["ell"][..., None]
        f = st["N"][..., None] * st["r"] - (st["M1"] + st["M2"])[..., None] * zl
        f[..., 2] = f[..., 2] + st["M1"]
        f[..., 5] = f[..., 5] + st["M2"]
        return f

    def local_stiffness(self, params: dict[str, Any]) -> np.ndarray:
        """D (..., n_e, 3, 3) = ∂(N, M₁, M₂)/∂(u_l, θ_1l, θ_2l), the constant local stiffness."""
        L, EI = params["beam_L"], params["beam_EI"]
        a, k, z = params["beam_EA"] / L, 2 * EI / L, 0 * L
        return np.stack([a, z, z, z, 2 * k, k, z, k, 2 * k], axis=-1).reshape(L.shape + (3, 3))

    def deformations(self, qe: np.ndarray, params: dict[str, Any], hessian: bool = False
                     ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """(B, H, D) of the local deformations e = (u_l, θ_1l, θ_2l) at qe (..., n+1): B = ∂e/∂u
        (..., n_e, 3, 6), with ``hessian`` H = ∂²e/∂u² (n_e, 3, 6, 6) (one state), D as
        :meth:`local_stiffness`."""
        st = self.state(qe, params)
        return self._jacobian(st), self._hessian(st) if hessian else None, self.local_stiffness(params)

    @staticmethod
    def _jacobian(st: dict[str, np.ndarray]) -> np.ndarray:
        """B = ∂(u_l, θ_1l, θ_2l)/∂u (..., n_e, 3, 6): rows r, e₃ − z/ℓ, e₆ − z/ℓ."""
        zl = st["z"] / st["ell"][..., None]
        B = np.stack([st["r"], -zl, -zl], axis=-2)
        B[..., 1, 2] += 1
        B[..., 2, 5] += 1
        return B

    @staticmethod
    def _hessian(st: dict[str, np.ndarray]) -> np.ndarray:
        """H = ∂²(u_l, θ_1l, θ_2l)/∂u² (..., n_e, 3, 6, 6): ∂²ℓ/∂u² = z zᵀ/ℓ and
        ∂²θ_l/∂u² = −∂²α/∂u² = (r zᵀ + z rᵀ)/ℓ²."""
        ell, r, z = st["ell"], st["r"], st["z"]
        zz = z[..., :, None] * z[..., None, :] / ell[..., None, None]
        rz = r[..., :, None] * z[..., None, :]
        rz = (rz + np.swapaxes(rz, -1, -2)) / (ell * ell)[..., None, None]
        return np.stack([zz, rz, rz], axis=-3)

    def tangent(self, qe: np.ndarray, params: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rows, cols, values) of the exact element tangents K = Bᵀ D B + Σ f_m H_m (one state)."""
        st = self.state(qe, params)
        n_e = len(st["ell"])
        B, H = self._jacobian(st), self._hessian(st)
        K = np.einsum("eai,eab,ebj->eij", B, self.local_stiffness(params), B)
        K = K + np.einsum("em,emij->eij", np.stack([st["N"], st["M1"], st["M2"]], axis=-1), H)
        return np.repeat(self.idx, 6, axis=1).ravel(), np.tile(self.idx, (1, 6)).ravel(), K.reshape(n_e, -1).ravel()

    def fibre_stress(self, qe: np.ndarray, params: dict[str, Any]) -> np.ndarray:
        """Extreme-fibre stresses (..., n_e, 4): end 1 ±, end 2 ± (σ = N/A ± M c/I)."""
        st = self.state(qe, params)
        axial = st["N"] / params["beam_A"]
        W = params["beam_I"] / params["beam_c"]
        b1, b2 = st["M1"] / W, st["M2"] / W
        return np.stack([axial + b1, axial - b1, axial + b2, axial - b2], axis=-1)

    def design_touch(self) -> list[tuple[list[int], np.ndarray]]:
        """Per beam: the parameter indices it reads and its DOFs (for the column colouring)."""
        return [([*self.X[e], self.E_idx[e], self.rho_idx[e], *self.dims[e]], self.idx[e])
                for e in range(len(self))]


def parse_beam(el: dict, ep: str, name: str, beams: BeamSet, table: ParameterTable,
               node_dofs: Callable[[Any, str], list[int]], node_coords: dict[str, list[int]],
               problems: ProblemCollector) -> None:
    """Read one ``type: beam`` element entry into ``beams``; node_dofs gives (x, y, θz) DOFs."""
    check_keys(el, ep, BEAM_KEYS, problems, required=("nodes", "E", "section"))
    pair = el.get("nodes", [])
    if not isinstance(pair, list) or len(pair) != 2:
        problems.add(f"{ep}.nodes", f"expected [node_a, node_b], found {pair!r}")
        return
    sec = el.get("section")
    if not check_keys(sec, f"{ep}.section", allowed("structural.beam_section"), problems) \
            or not isinstance(sec, dict):
        return
    shape = sec.get("shape", "properties")
    if shape not in SHAPES:
        problems.add(f"{ep}.section.shape", f"unknown shape {shape!r}{did_you_mean(shape, SHAPES)} "
                                            f"(known: {', '.join(SHAPES)})")
        return
    needed = SHAPES[shape]
    extra = [k for k in sec if k != "shape" and k not in needed]
    if extra:
        problems.add(f"{ep}.section", f"{shape} takes {', '.join(needed)}, not {', '.join(extra)}")
    missing = [k for k in needed if k not in sec]
    if missing:
        problems.add(f"{ep}.section", f"{shape} needs {', '.join(missing)}")
        return
    mass = el.get("mass", "lumped")
    if mass not in MASS_KINDS:
        problems.add(f"{ep}.mass", f"expected lumped or consistent, found {mass!r}")
    dofs = node_dofs(pair[0], f"{ep}.nodes") + node_dofs(pair[1], f"{ep}.nodes")
    if any(p not in node_coords for p in pair):
        return
    table.require_apart(node_coords[pair[0]], node_coords[pair[1]], f"{ep}.nodes", "beam")
    beams.names.append(name)
    beams.dofs.append(dofs)
    beams.coords.append(node_coords[pair[0]] + node_coords[pair[1]])
    beams.E.append(table.add(el.get("E"), f"{ep}.E", problems, positive=True))
    beams.rho.append(table.add(el.get("density", 0.0), f"{ep}.density", problems, nonnegative=True))
    append_section(beams, shape, needed, sec, ep, table, problems, mass == "consistent")


def append_section(beams: Any, shape: str, needed: tuple[str, ...], sec: dict, ep: str, table: ParameterTable,
                   problems: ProblemCollector, consistent: bool) -> None:
    """Append a beam's section to ``beams`` (plane or 3D set): its shape, its dimensions as
    parameters (a hollow section's wall checked against its outer size) and its mass kind."""
    beams.shape.append(shape)
    dims = [table.add(sec[k], f"{ep}.section.{k}", problems, positive=True) for k in needed]
    beams.dims.append(dims)
    if shape in HOLLOW:
        table.require_wall(dims[needed.index("t")], {k: i for k, i in zip(needed, dims) if k != "t"},
                           f"{ep}.section.t")
    beams.consistent.append(consistent)
