"""Springs (``type: spring``) between two DOFs, or a DOF and ground: f = k₁δ + k₂δ² + k₃δ³ with
δ = u_a − u_b (:func:`~dynsens.models.structural.spring_law.spring_law`)."""
from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from ....case_keys import allowed
from ....errors import ProblemCollector
from ..._keys import check_keys
from ..spring_law import spring_law
from .kind import ElementKind, ModelContext, ReadContext, Touch, Triplets, register_kind

PAIR_SIGNS = np.array([1.0, -1.0])


def read_pair(entry: dict, path: str, kind: str, ctx: ReadContext) -> list[int] | None:
    """The two DOF indices of a spring or damper entry (the second n: ground), or None with a
    problem listed."""
    problems = ctx.problems
    pair = entry.get("dofs", [])
    if not isinstance(pair, list) or len(pair) not in (1, 2):
        problems.add(f"{path}.dofs", f"expected [dof] or [dof_a, dof_b|ground], found {pair!r}")
        return None
    n_known = len(problems.problems)
    ids = [ctx.dof(d, f"{path}.dofs") for d in pair] + ([ctx.n] if len(pair) == 1 else [])
    if ids[0] == ids[1] and len(problems.problems) == n_known:
        problems.add(f"{path}.dofs", f"expected a {kind} between two different DOFs (or a DOF and ground), "
                                     f"found {pair!r}: " + ("it would act on ground (or fixed DOFs) only"
                                                            if ids[0] == ctx.n else "both ends are one DOF"))
        return None
    return ids


@register_kind
class Springs(ElementKind):
    """The springs of a model, evaluated together: one elongation product δ = q @ Gᵀ."""

    type = "spring"
    order = 1
    section = "structural.spring"
    compiled = True
    output_kinds = ("force",)
    stack_keys: ClassVar[tuple[str, ...]] = ("k1", "k2", "k3")

    def __init__(self) -> None:
        self.names: list[str] = []
        self.pairs: list[list[int]] = []
        self.k: dict[str, list[int]] = {"k1": [], "k2": [], "k3": []}
        self.has_higher = False            # some spring has k2 or k3 (a nonlinear law)
        self._zero = -1                    # the parameter index of the k2, k3 not given

    def read(self, entry: dict, path: str, name: str, ctx: ReadContext) -> None:
        check_keys(entry, path, allowed(self.section), ctx.problems, required=("dofs", "k"))
        ids = read_pair(entry, path, "spring", ctx)
        if ids is None:
            return
        higher = {}
        for key in ("k2", "k3"):
            if key in entry:
                self.has_higher = True
                higher[key] = ctx.table.add(entry[key], f"{path}.{key}", ctx.problems)
            else:
                if self._zero < 0:
                    self._zero = ctx.table.add(0.0, "", ctx.problems)
                higher[key] = self._zero
        self.names.append(name)
        self.pairs.append(ids)
        self.k["k1"].append(ctx.table.add(entry.get("k"), f"{path}.k", ctx.problems))
        for key, index in higher.items():
            self.k[key].append(index)

    def freeze(self, model: ModelContext) -> None:
        self.dof_idx = np.array(self.pairs, dtype=int).reshape(-1, 2)
        self.k1, self.k2, self.k3 = (np.array(self.k[key], dtype=int) for key in ("k1", "k2", "k3"))
        self.linear = model.linear
        # element forces -> nodal forces as one matrix product (works with a leading batch axis)
        self.scatter = model.scatter(self.dof_idx, PAIR_SIGNS, True)
        self.elongation = self.scatter.transposed()   # (n, n_s): δ = q @ it
        self._elongation_of: dict[tuple[int, ...], Any] = {}     # columns of selected springs
        # the state of the last residual: Newton linearizes at the state it has just evaluated,
        # and the tangent needs the same products (kept with q and params themselves)
        self._last: tuple[Any, Any, np.ndarray, np.ndarray] | None = None

    def nonlinear(self) -> bool:
        return self.has_higher

    def parameters(self, pv: np.ndarray, out: dict[str, Any], mass: np.ndarray) -> None:
        if len(self):
            out.update(k1=pv[self.k1], k2=pv[self.k2], k3=pv[self.k3])

    def state(self, q: np.ndarray, params: dict[str, Any], springs: np.ndarray | None = None,
              tangent: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Spring forces f (..., n_s) and, with ``tangent``, the tangents df/dδ (else None) of all
        springs or of the indices ``springs``; params may carry a leading batch axis."""
        keep = springs is None and tangent
        if keep:
            last = self._last
            if last is not None and last[0] is q and last[1] is params:
                return last[2], last[3]
        if springs is None:
            elongation = self.elongation
        else:
            key = tuple(springs.tolist())
            if key not in self._elongation_of:
                self._elongation_of[key] = self.elongation.columns(springs)
            elongation = self._elongation_of[key]
        delta = elongation(q)                        # δ = u_a − u_b for every spring

        def pick(key: str) -> np.ndarray:
            return params[key] if springs is None else params[key][..., springs]
        k1 = pick("k1")
        if self.linear:
            return k1 * delta, (k1 + 0 * delta if tangent else None)
        f, kt = spring_law(delta, k1, pick("k2"), pick("k3"))
        if not tangent:
            return f, None
        if keep:
            f.flags.writeable = kt.flags.writeable = False     # kept: never changed in place
            self._last = (q, params, f, kt)
        return f, kt

    def internal_force(self, q: np.ndarray, params: dict[str, Any]) -> np.ndarray | None:
        if not len(self):
            return None
        # a single state: the tangent at it is asked for next (Newton), batches need none
        fs, _ = self.state(q, params, tangent=q.ndim == 1)
        return self.scatter(fs)

    def tangent(self, q: np.ndarray, params: dict[str, Any], corotated: bool) -> list[Triplets]:
        if not len(self):
            return []
        _, kt = self.state(q, params)
        assert kt is not None
        a, b = self.dof_idx[:, 0], self.dof_idx[:, 1]
        return [(a, a, kt), (b, b, kt), (a, b, -kt), (b, a, -kt)]

    def design_touch(self) -> list[Touch]:
        return [([k[e] for k in (self.k1, self.k2, self.k3) if len(k)], dofs)
                for e, dofs in enumerate(self.dof_idx)]

    def output(self, index: np.ndarray, kind: str, path: str, problems: ProblemCollector) -> Any:
        def forces(t: float, s: Any, prm: dict[str, Any]) -> np.ndarray:
            return self.state(s.q, prm, index, tangent=False)[0]
        return forces, tuple(f"{self.names[i]}.force" for i in index)

    def refusal(self, kind: str) -> str:
        return "springs report only 'force'"
