r"""A ``rope`` between two markers: an elastic line that carries tension only.

With L = |P_2 − P_1| its length, L0 its free length and EA its axial stiffness (force), the
tension is

    N = EA / L0 · g(L − L0),

g(e) = max(e, 0) (``switch: exact``) or the smooth ½(e + √(e² + w²)) (``switch: smooth``, w a
length > 0: the width of the transition; a slack rope then keeps a tension of order EA w² /
(4 L0 |e|)).  −N d/L acts on P_2 and +N d/L on P_1 (d = P_2 − P_1), as for a spring.  The
switch is the cable's (:func:`dynsens.models.structural.elements.cables.switch`), complex-safe (the exact
switch decides on the real part), so design partials may be taken by complex step.

The law declares ``compiled = False``: its elements are *other forces* of the model, evaluated in
Python (:func:`..residual.other_forces_q`; their state Jacobians by complex step of the
residual), and a model with a rope steps on the Python path.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ....case_keys import Key, Section
from ....errors import ProblemCollector
from ...base import Output
from ...structural.elements.cables import switch
from ..bodies import Ctx, Diff, Point
from ..build_forces import attachments
from ..force_law import ForceElements, ForceLaw, register_law
from ..forces import ForceElement
from ..outputs import _ctx
from ..rotations import dot
from ..spec import Reader

if TYPE_CHECKING:
    from ..model import MultibodyModel

ROPE_KEYS = Section("forces[i], type: rope", "Tension-only rope between two markers: N = EA/L0 · g(L − L0), "
                    "g(e) = max(e, 0) (`switch: exact`) or ½(e + √(e² + w²)) (`switch: smooth`, width w).", (
                        Key("type", "enum", "force type", required=True, values=("rope",)),
                        Key("name", "name", "force name"),
                        Key("body_1", "name", "body 1", required=True),
                        Key("point_1", "name", "marker on body 1", required=True),
                        Key("body_2", "name", "body 2", required=True),
                        Key("point_2", "name", "marker on body 2", required=True),
                        Key("stiffness", "expr", "axial stiffness EA (force, > 0)", required=True),
                        Key("free_length", "expr", "free length L0 (> 0)", required=True),
                        Key("switch", "enum", "tension-only law: exact max(e, 0), or smooth",
                            default="exact", values=("exact", "smooth")),
                        Key("width", "expr", "smoothing width w of `switch: smooth` (a length, > 0)"),
                    ), type_value="rope")


@dataclass(eq=False)
class Rope(ForceElement):
    """A tension-only rope from ``p1`` to ``p2``; EA, L0 and the width w (None: the exact switch)
    by parameter index."""

    name: str
    p1: Point
    p2: Point
    ea: int
    free_length: int
    width: int | None

    def __post_init__(self) -> None:
        self.d = Diff(self.p2, self.p1)        # one term: its kinematics are cached per Ctx by identity

    def state(self, ctx: Ctx) -> tuple[Any, Any, Any]:
        """(d (3, k), L (1, k), N (1, k)): the separation P_2 − P_1, the length and the tension."""
        d = self.d.kin(ctx)[0]
        L = np.sqrt(dot(d, d))
        pv = ctx.params.pv
        L0 = pv[self.free_length]
        g, _ = switch(L - L0, None if self.width is None else pv[self.width])
        return d, L, pv[self.ea] / L0 * g

    def add(self, ctx: Ctx, out: np.ndarray) -> None:
        d, L, N = self.state(ctx)
        # ends that meet (L = 0) leave the rope slack: no force (N·d/L would be 0/0 = NaN); the real
        # part decides, as the switch does, so a complex-step perturbation of the state stays finite
        self.d.apply(ctx, -N * d / np.where(np.real(L) > 0, L, 1.0), out)


@register_law
class RopeLaw(ForceLaw):
    """Ropes: in the model's ``forces`` (its other forces, evaluated in Python)."""

    type = "rope"
    order = 6
    keys = ROPE_KEYS
    compiled = False
    output_kinds = ("length", "force")
    what = "rope"

    def read(self, rd: Reader, entry: dict, path: str, name: str, out: ForceElements) -> None:
        """A ``rope`` between two points, with its stiffness, free length and switch."""
        ends = attachments(rd, entry, path, name)
        ea = rd.num(entry.get("stiffness", 1.0), f"{path}.stiffness", positive=True)
        L0 = rd.num(entry.get("free_length", 1.0), f"{path}.free_length", positive=True)
        for key in ("stiffness", "free_length"):
            if key not in entry:
                rd.problems.add(f"{path}.{key}", "missing")
        kind = entry.get("switch", "exact")
        width = None
        if kind == "smooth":
            if "width" not in entry:
                rd.problems.add(f"{path}.width", "missing (the smoothing width of `switch: smooth`, a length > 0)")
            width = rd.num(entry.get("width", 1.0), f"{path}.width", positive=True)
        elif kind != "exact":
            rd.problems.add(f"{path}.switch", f"expected 'exact' or 'smooth', found {kind!r}")
        elif "width" in entry:
            rd.problems.add(f"{path}.width", "only with `switch: smooth`")
        if ends is not None:
            out.forces.append(Rope(name, ends[1], ends[3], ea, L0, width))

    def elements(self, model: "MultibodyModel") -> list[Any]:
        return [f for f in model.forces if isinstance(f, Rope)]

    def output(self, model: "MultibodyModel", element: Any, kind: Any, path: str,
               problems: ProblemCollector) -> Output | None:
        """A rope's length or tension."""
        if not self.known_kind(kind, path, problems):
            return None
        level = 1 + self.output_kinds.index(kind)
        return Output(lambda t, s, prm: element.state(_ctx(s, prm, t))[level][0], (f"{element.name}.{kind}",))
