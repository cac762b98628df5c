r"""Co-rotational kinematics of the space-frame beam (``kinematics: corotational``): large
displacements and rotations, small strains.

Rotation parametrization: the node unknowns θ_x, θ_y, θ_z are a *total* rotation vector ψ in
global axes, the node frame is R_i = exp(ψ_i)·R₀ (Rodrigues, exp(ψ)x = x + a ψ×x + b ψ×(ψ×x),
a = sin|ψ|/|ψ|, b = (1 − cos|ψ|)/|ψ|², evaluated as power series in |ψ|², exact at ψ = 0).  A
vector is additive, so the Newmark update handles ψ like any other unknown; the map ψ → R is
regular for |ψ| < 2π, which bounds a node's rotation about a fixed axis to just under a full
turn (rescaling ψ by 2π near the limit is not implemented).  Node frames are explicit (R₀ and ψ
in global axes), which is what a later coupling to rigid bodies needs.

Element frame: e₁ along the current chord, e₃ ∝ e₁ × (t₁ + t₂)/2 (t_i the nodes' rotated local
y axes), e₂ = e₃ × e₁.  Local rotations: the rotation vector of Q_i = R_rᵀR_i,
θ_i = (asin|v|/|v|)·v with v = vex(Q_i − Q_iᵀ)/2 = sin θ·n (exact for local rotations below
π/2, which the element frame keeps small; series in |v|²); stretch u = (ℓ² − L²)/(ℓ + L).  Strain energy
Π = EA u²/2L + GJ(θ₂ₓ − θ₁ₓ)²/2L + Σ_{plane} (EI/L)(2θ₁² + 2θ₁θ₂ + 2θ₂²); the internal force
∇Π and the tangent ∇²Π are exact: they are carried through the kinematics as second-order
forward derivatives (:class:`Jet2`) with respect to the element's 12 unknowns, whose values
may be complex (complex step of a whole run passes through).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

_N_SERIES = 30


class Jet2:
    """A value with its gradient g (..., 12) and, when ``order`` is 2, Hessian H (..., 12, 12)."""

    __slots__ = ("v", "g", "H")
    __array_ufunc__ = None          # numpy arrays defer to the jet's reflected operators

    def __init__(self, v: Any, g: Any, H: Any = None):
        self.v, self.g, self.H = v, g, H

    def __add__(self, o: Any) -> "Jet2":
        if isinstance(o, Jet2):
            return Jet2(self.v + o.v, self.g + o.g, None if self.H is None else self.H + o.H)
        return Jet2(self.v + o, self.g, self.H)

    __radd__ = __add__

    def __neg__(self) -> "Jet2":
        return Jet2(-self.v, -self.g, None if self.H is None else -self.H)

    def __sub__(self, o: Any) -> "Jet2":
        return self + (-o)

    def __rsub__(self, o: Any) -> "Jet2":
        return (-self) + o

    def __mul__(self, o: Any) -> "Jet2":
        if not isinstance(o, Jet2):
            o = np.asarray(o)
            return Jet2(self.v * o, self.g * o[..., None], None if self.H is None else self.H * o[..., None, None])
        H = None
        if self.H is not None:
            outer = self.g[..., :, None] * o.g[..., None, :]
            H = self.v[..., None, None] * o.H + o.v[..., None, None] * self.H + outer + np.swapaxes(outer, -1, -2)
        return Jet2(self.v * o.v, self.v[..., None] * o.g + o.v[..., None] * self.g, H)

    __rmul__ = __mul__

    def apply(self, f: Any, df: Any, d2f: Any) -> "Jet2":
        """φ(self) from φ, φ', φ'' at the value."""
        H = None if self.H is None else \
            df[..., None, None] * self.H + d2f[..., None, None] * self.g[..., :, None] * self.g[..., None, :]
        return Jet2(f, df[..., None] * self.g, H)

    def __truediv__(self, o: Any) -> "Jet2":
        if not isinstance(o, Jet2):
            return self * (1.0 / np.asarray(o))
        inv = 1.0 / o.v
        return self * o.apply(inv, -inv * inv, 2 * inv * inv * inv)

    def sqrt(self) -> "Jet2":
        r = np.sqrt(self.v)
        return self.apply(r, 0.5 / r, -0.25 / (r * self.v))


def _series(s: Any, coeffs: list[float]) -> tuple[Any, Any, Any]:
    """Σ_k c_k s^k and its first two derivatives in s (complex-safe)."""
    n = len(coeffs)
    powers = [1.0 + 0.0 * s]
    for _ in range(n):
        powers.append(powers[-1] * s)
    f = sum(coeffs[k] * powers[k] for k in range(n))
    d1 = sum(coeffs[k] * k * powers[k - 1] for k in range(1, n))
    d2 = sum(coeffs[k] * k * (k - 1) * powers[k - 2] for k in range(2, n))
    return f, d1, d2


# sin r/r, (1 − cos r)/r² and asin r/r as series in s = r² (the first two entire, the last for |r| < 1)
_SINC = [(-1.0) ** k / math.factorial(2 * k + 1) for k in range(_N_SERIES)]
_COSC = [(-1.0) ** k / math.factorial(2 * k + 2) for k in range(_N_SERIES)]
_ASINC = [math.factorial(2 * k) / (4 ** k * math.factorial(k) ** 2 * (2 * k + 1)) for k in range(_N_SERIES)]


def _of(s: Any, coeffs: list[float]) -> Any:
    """The series at s, a jet or a value."""
    return s.apply(*_series(s.v, coeffs)) if isinstance(s, Jet2) else _series(s, coeffs)[0]


def _cross(a: list, b: list) -> list:
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _dot(a: list, b: list) -> Any:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _rotate(psi: list, x: list) -> list:
    """exp(ψ)x = x + a ψ×x + b ψ×(ψ×x) for a jet ψ and a constant vector x (components (n_e,))."""
    s = _dot(psi, psi)
    a, b = _of(s, _SINC), _of(s, _COSC)
    px = _cross(psi, x)
    ppx = _cross(psi, px)
    return [x[k] + a * px[k] + b * ppx[k] for k in range(3)]


def local_deformations(U: list, D0: np.ndarray, L: Any, R0: np.ndarray) -> list:
    """(u, θ₁ₓ, θ₁ᵧ, θ₁_z, θ₂ₓ, θ₂ᵧ, θ₂_z) of the elements: U the 12 unknowns (jets or arrays),
    D0 (..., 3) initial chords, R0 (..., 3, 3) initial frames (rows e₁, e₂, e₃)."""
    d = [U[6 + k] - U[k] + D0[..., k] for k in range(3)]
    frames = []
    for node in (0, 1):
        psi = U[6 * node + 3:6 * node + 6]
        frames.append([_rotate(psi, [R0[..., j, k] for k in range(3)]) for j in range(3)])   # rotated e1, e2, e3
    return corotated_deformations(d, frames, L)


def corotated_deformations(d: list, frames: list, L: Any) -> list:
    """(u, θ₁ₓ, θ₁ᵧ, θ₁_z, θ₂ₓ, θ₂ᵧ, θ₂_z) from the current chord d (3 components) and the node
    frames ``frames[i][j]`` (the element's initial axis e_j carried by node i, 3 components each;
    jets or arrays), L the initial length; shared with the multibody beam members."""
    ell2 = _dot(d, d)
    ell = ell2.sqrt() if isinstance(ell2, Jet2) else np.sqrt(ell2)
    u = (ell2 - L * L) / (ell + L)
    e1 = [d[k] / ell for k in range(3)]
    q = [(frames[0][1][k] + frames[1][1][k]) * 0.5 for k in range(3)]
    c = _cross(e1, q)
    cn2 = _dot(c, c)
    cn = cn2.sqrt() if isinstance(cn2, Jet2) else np.sqrt(cn2)
    e3 = [c[k] / cn for k in range(3)]
    e2 = _cross(e3, e1)
    er = [e1, e2, e3]
    out = [u]
    for n in frames:
        Q = [[_dot(er[j], n[k]) for k in range(3)] for j in range(3)]   # Q_jk = e_j · n_k
        v = [(Q[2][1] - Q[1][2]) * 0.5, (Q[0][2] - Q[2][0]) * 0.5, (Q[1][0] - Q[0][1]) * 0.5]   # sin θ·n
        c = _of(_dot(v, v), _ASINC)                                     # θ/sin θ: the rotation vector θ·n
        out += [c * v[k] for k in range(3)]
    return out


def energy_gradients(dl: list, L: Any, EA: Any, GJ: Any, EIy: Any, EIz: Any) -> list:
    """∂Π/∂(u, θ₁, θ₂) (7 local forces and moments) for local deformations dl."""
    u, t1x, t1y, t1z, t2x, t2y, t2z = dl
    kt, ky, kz = GJ / L, EIy / L, EIz / L
    return [EA / L * u, kt * (t1x - t2x), ky * (4 * t1y + 2 * t2y), kz * (4 * t1z + 2 * t2z),
            kt * (t2x - t1x), ky * (2 * t1y + 4 * t2y), kz * (2 * t1z + 4 * t2z)]


def local_stiffness(prm: dict[str, Any], like: np.ndarray) -> np.ndarray:
    """D (..., n_e, 7, 7) = ∂²Π/∂e², constant (the energy is quadratic in e); ``like`` (..., n_e)
    gives, broadcast with the stiffnesses, its leading shape, and its dtype."""
    shape = np.broadcast_shapes(like.shape, np.shape(prm["EA"]))
    probe = [np.zeros(shape, like.dtype) for _ in range(7)]
    D = np.zeros(shape + (7, 7), dtype=np.result_type(like, prm["EA"]))
    for j in range(7):
        probe[j] = probe[j] + 1.0
        D[..., :, j] = np.stack(energy_gradients(probe, prm["L"], prm["EA"], prm["GJ"], prm["EIy"], prm["EIz"]),
                                axis=-1)
        probe[j] = probe[j] - 1.0
    return D


def _jets(Ue: np.ndarray, prm: dict[str, Any], order: int) -> list:
    """The 7 local deformations as jets in the 12 unknowns Ue (..., n_e, 12): values and
    gradients, and with ``order`` 2 Hessians."""
    eye = np.broadcast_to(np.eye(12), Ue.shape + (12,))
    zero = np.zeros(Ue.shape + (12,)) if order == 2 else None
    U = [Jet2(Ue[..., i], eye[..., i, :], zero) for i in range(12)]
    return local_deformations(U, prm["D0"], prm["L"], prm["R0"])


def deformations(Ue: np.ndarray, prm: dict[str, Any], hessian: bool
                 ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """(B, H, D) of the local deformations e: B = ∂e/∂u (..., n_e, 7, 12), with ``hessian``
    H = ∂²e/∂u² (..., n_e, 7, 12, 12), D as :func:`local_stiffness`."""
    dl = _jets(Ue, prm, 2 if hessian else 1)
    B = np.stack([x.g for x in dl], axis=-2)
    H = np.stack([x.H for x in dl], axis=-3) if hessian else None
    # D of the parameters' shape (..., n_e), not broadcast against the states
    return B, H, local_stiffness(prm, np.zeros(np.shape(prm["EA"]), dtype=Ue.dtype))


def element_forces(Ue: np.ndarray, prm: dict[str, Any], order: int) -> tuple[np.ndarray, np.ndarray | None]:
    """Internal forces ∇Π (..., n_e, 12) and, with ``order`` 2, tangents ∇²Π (n_e, 12, 12) of
    the co-rotational elements at unknowns Ue (..., n_e, 12); prm holds their D0, L, R0 and
    stiffnesses (``frame_*`` entries restricted to them)."""
    dl = _jets(Ue, prm, order)
    fl = energy_gradients([x.v for x in dl], prm["L"], prm["EA"], prm["GJ"], prm["EIy"], prm["EIz"])
    f = sum(fl[k][..., None] * dl[k].g for k in range(7))
    if order < 2:
        return f, None
    # ∇²Π = Σ_k f_k ∇²d_k + Bᵀ D B, B rows ∇d_k; D from the quadratic energy (constant)
    B = np.stack([x.g for x in dl], axis=-2)                       # (..., 7, 12)
    D = local_stiffness(prm, Ue[..., 0])
    K = np.einsum("...ki,...kl,...lj->...ij", B, D, B) + sum(fl[k][..., None, None] * dl[k].H for k in range(7))
    return f, K


def local_forces(Ue: np.ndarray, prm: dict[str, Any]) -> list:
    """The 7 local forces (N, moments) of the co-rotational elements at unknowns Ue (values only)."""
    dl = local_deformations([Ue[..., i] for i in range(12)], prm["D0"], prm["L"], prm["R0"])
    return energy_gradients(dl, prm["L"], prm["EA"], prm["GJ"], prm["EIy"], prm["EIz"])
