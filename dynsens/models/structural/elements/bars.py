r"""Truss bars (``type: bar``), 2D or 3D, geometrically nonlinear: total Lagrangian with the
Green–Lagrange strain ε = (ℓ² − L²)/(2L²), axial force N = E A ε, nodal forces ± N d/L (d the
current bar vector); the tangent is (EA/L³) d dᵀ + (N/L) I per node pair.  Mass lumped, ρAL/2
per node and direction.  Outputs: force N, stress Eε, strain ε and the buckling ratio −N/P_E
with the Euler load P_E = π²EI/(KL)² (bars with ``inertia``)."""
from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from ....case_keys import allowed
from ....errors import ProblemCollector
from ..._keys import check_keys
from ..corotated_damping import DampedKind
from .kind import ElementKind, extend, ModelContext, ReadContext, Touch, Triplets, register_kind


@register_kind
class Bars(ElementKind):
    """The bars of a model: 2·dim DOF indices each (node 1, then node 2) and parameter indices."""

    type = "bar"
    order = 3
    compiled = False                # Python only: the compiled step serves spring networks
    section = "structural.bar"
    member = True
    output_kinds: ClassVar[tuple[str, ...]] = ("force", "stress", "strain", "buckling")
    stack_keys: ClassVar[tuple[str, ...]] = ("D0", "L0", "EA", "E", "P_euler")
    #: the prefix of the derived parameters' keys (a kind derived from bars keeps its own)
    prefix: ClassVar[str] = ""

    def __init__(self) -> None:
        self.names: list[str] = []
        self.pairs: list[list[int]] = []
        self.nodes: list[tuple[str, str]] = []
        self.p: dict[str, list[int]] = {k: [] for k in ("A", "E", "rho", "I", "K")}

    def read(self, entry: dict, path: str, name: str, ctx: ReadContext) -> None:
        check_keys(entry, path, allowed(self.section), ctx.problems, required=("nodes", "area", "E"))
        pair = entry.get("nodes", [])
        if not isinstance(pair, list) or len(pair) != 2:
            ctx.problems.add(f"{path}.nodes", f"expected [node_a, node_b], found {pair!r}")
            return
        table, problems = ctx.table, ctx.problems
        self.pairs.append(ctx.node_dofs(pair[0], f"{path}.nodes") + ctx.node_dofs(pair[1], f"{path}.nodes"))
        self.names.append(name)
        self.p["A"].append(table.add(entry.get("area"), f"{path}.area", problems, positive=True))
        self.p["E"].append(table.add(entry.get("E"), f"{path}.E", problems, positive=True))
        self.p["rho"].append(table.add(entry.get("density", 0.0), f"{path}.density", problems, nonnegative=True))
        self.p["I"].append(table.add(entry["inertia"], f"{path}.inertia", problems, positive=True)
                           if "inertia" in entry else -1)
        self.p["K"].append(table.add(entry.get("effective_length_factor", 1.0), f"{path}.effective_length_factor",
                                     problems, positive=True))
        self.nodes.append((pair[0], pair[1]))
        self.node_coords = ctx.node_coords
        if pair[0] in ctx.node_coords and pair[1] in ctx.node_coords:
            table.require_apart(ctx.node_coords[pair[0]], ctx.node_coords[pair[1]], f"{path}.nodes", self.type)

    def freeze(self, model: ModelContext) -> None:
        self.dim = dim = model.dim
        self.n = model.n
        self.idx = np.array(self.pairs, dtype=int).reshape(-1, 2 * dim)
        self.A, self.E, self.rho, self.I, self.K = (np.array(self.p[k], dtype=int) for k in ("A", "E", "rho", "I", "K"))
        # undeformed bar vectors from nodal coordinates (parameter indices, may be design-dependent)
        self.X = np.array([[self.node_coords[b] + [] for b in pair] for pair in self.nodes], dtype=int) \
            .reshape(-1, 2, dim) if self.nodes else np.zeros((0, 2, dim), int)
        self.scatter = model.scatter(self.idx, np.ones(2 * dim), False)

    def dofs(self) -> list[int]:
        return [d for row in self.pairs for d in row]

    def nonlinear(self) -> bool:
        return bool(len(self))

    def parameters(self, pv: np.ndarray, out: dict[str, Any], mass: np.ndarray) -> None:
        if not len(self):
            return
        X = pv[self.X]                       # (n_e, 2, dim)
        D0 = X[:, 1] - X[:, 0]
        L0 = np.sqrt(np.sum(D0 * D0, axis=1))
        A, E, rho = pv[self.A], pv[self.E], pv[self.rho]
        half = 0.5 * rho * A * L0
        np.add.at(mass, self.idx, np.repeat(half[:, None], 2 * self.dim, axis=1))
        derived = dict(D0=D0, L0=L0, EA=E * A, E=E, A=A, bar_mass=2 * half)
        # Euler load π²EI/(KL)² (force unit); infinite for a bar without 'inertia' (the
        # buckling output refuses such bars)
        KL = pv[self.K] * L0
        has = self.I >= 0
        inertia = np.where(has, pv[np.maximum(self.I, 0)], 1.0)
        derived["P_euler"] = np.where(has, np.pi ** 2 * E * inertia / (KL * KL), np.inf)
        out.update({self.prefix + k: v for k, v in derived.items()})

    def structural_mass(self, params: dict[str, Any]) -> Any:
        return np.sum(params[self.prefix + "bar_mass"]) if len(self) else None

    def state(self, q: np.ndarray, params: dict[str, Any]) -> dict[str, np.ndarray]:
        """Bar vectors d (..., n_e, dim), Green–Lagrange strains and axial forces (..., n_e)."""
        qe = extend(q)
        U = qe[..., self.idx].reshape(qe.shape[:-1] + (-1, 2, self.dim))
        du = U[..., 1, :] - U[..., 0, :]
        D0 = params[self.prefix + "D0"]
        d = D0 + du
        L0 = params[self.prefix + "L0"]
        # (ℓ² − L²) written as 2 D0·Δu + Δu·Δu: no cancellation for small displacements
        strain = (2.0 * np.sum(D0 * du, axis=-1) + np.sum(du * du, axis=-1)) / (2 * L0 * L0)
        N = params[self.prefix + "EA"] * strain
        return {"d": d, "strain": strain, "N": N}

    def internal_force(self, q: np.ndarray, params: dict[str, Any]) -> np.ndarray | None:
        if not len(self):
            return None
        bs = self.state(q, params)
        fe = (bs["N"] / params[self.prefix + "L0"])[..., None] * bs["d"]
        return self.scatter(np.concatenate([-fe, fe], axis=-1).reshape(fe.shape[:-2] + (-1,)))

    def tangent(self, q: np.ndarray, params: dict[str, Any], corotated: bool) -> list[Triplets]:
        if not (len(self) and corotated):
            return []
        bs = self.state(q, params)
        d, N, L0 = bs["d"], bs["N"], params[self.prefix + "L0"]
        k_node = (self.axial_stiffness(bs, params) / L0 ** 3)[:, None, None] * d[:, :, None] * d[:, None, :] \
            + (N / L0)[:, None, None] * np.eye(self.dim)
        ke = np.block([[k_node, -k_node], [-k_node, k_node]])
        idx = self.idx
        return [(np.repeat(idx, 2 * self.dim, axis=1).ravel(), np.tile(idx, (1, 2 * self.dim)).ravel(),
                 ke.reshape(len(idx), -1).ravel())]

    def axial_stiffness(self, bs: dict[str, np.ndarray], params: dict[str, Any]) -> np.ndarray:
        """dN/dε (force unit) at the bars' state ``bs``: EA."""
        return params[self.prefix + "EA"]

    def deformations(self, qe: np.ndarray, params: dict[str, Any], hessian: bool = False
                     ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """(B, H, D) of the bars' Green–Lagrange strains ε at qe (..., n+1): B = ∂ε/∂u =
        [−d, d]/L² (..., n_e, 1, 2·dim), H = [[I, −I], [−I, I]]/L² and D = EA·L (the energy
        ½ EA L ε²), for :mod:`..corotated_damping`."""
        bs = self.state(qe[..., :self.n], params)
        L2 = (params["L0"] ** 2)[..., None]
        B = (np.concatenate([-bs["d"], bs["d"]], axis=-1) / L2)[..., None, :]
        H = None
        if hessian:
            eye = np.eye(self.dim)
            H = np.block([[eye, -eye], [-eye, eye]])[None, None] / L2[..., None, None]
        return B, H, (params["EA"] * params["L0"])[..., None, None]

    def damped_kind(self) -> DampedKind:
        """The bars' share of Rayleigh's β K on deformation rates (:mod:`..corotated_damping`)."""
        return DampedKind(self.idx, self.scatter, self.deformations)

    def stress(self, bs: dict[str, np.ndarray], params: dict[str, Any]) -> np.ndarray:
        """Axial stresses (..., n_e) at the bars' state ``bs``: E ε."""
        return params[self.prefix + "E"] * bs["strain"]

    def design_touch(self) -> list[Touch]:
        # inertia and effective length enter outputs only (buckling), not F_R: no rows
        return [([self.A[e], self.E[e], self.rho[e], *np.ravel(self.X[e])], dofs)
                for e, dofs in enumerate(self.idx)] + \
            [([p for p in (self.I[e], self.K[e]) if p >= 0], []) for e in range(len(self))]

    def output_reads(self, index: np.ndarray, kind: str) -> list[Touch]:
        # every output reads the bar's geometry (D0, L0 from its nodes' coordinates) and its DOFs
        return [([*np.ravel(self.X[e]), *self._output_parameters(e, kind)], self.idx[e]) for e in index]

    def _output_parameters(self, e: int, kind: str) -> list[int]:
        """The parameter indices of bar e the output ``kind`` reads beyond its geometry."""
        return {"strain": [], "stress": [self.E[e]], "force": [self.A[e], self.E[e]],
                "buckling": [self.A[e], self.E[e], self.I[e], self.K[e]]}[kind]

    def output(self, index: np.ndarray, kind: str, path: str, problems: ProblemCollector) -> Any:
        lacking = [self.names[b] for b in index if self.I[b] < 0]
        if kind == "buckling" and lacking:
            problems.add(f"{path}.element", f"buckling needs the bar's 'inertia' (second moment of area); "
                                            f"missing for {', '.join(lacking[:5])}{' ...' if len(lacking) > 5 else ''}")
            return None

        def bar_out(t: float, s: Any, prm: dict[str, Any]) -> np.ndarray:
            bs = self.state(s.q, prm)
            if kind == "strain":
                return bs["strain"][..., index]
            if kind == "force":
                return bs["N"][..., index]
            if kind == "buckling":
                return (-bs["N"] / prm["P_euler"])[..., index]
            return self.stress(bs, prm)[..., index]
        return bar_out, tuple(f"{self.names[b]}.{kind}" for b in index)
