r"""The axial ``spring_damper`` between two markers, tension
F = k (L − L0) + k3 (L − L0)³ + c L̇ (:class:`..forces.SpringDamper`; a law of the compiled
kernels)."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ....case_keys.keys import Section, _k, _req
from ....errors import ProblemCollector
from ...base import Output
from ..bodies import Diff
from ..build_forces import attachments
from ..force_law import ForceElements, ForceLaw, register_law
from ..forces import SpringDamper
from ..outputs import _axial
from ..spec import Reader

if TYPE_CHECKING:
    from ..model import MultibodyModel

SPRING_DAMPER_KEYS = Section("forces[i], type: spring_damper", "Axial spring-damper between two markers: "
                                   "f = k(L − L0) + k3(L − L0)³ + d L̇.", (
    _req("type", "enum", "force type", values=("spring_damper",)), _k("name", "name", "force name"),
    _req("body_1", "name", "body 1"), _req("point_1", "name", "marker on body 1"),
    _req("body_2", "name", "body 2"), _req("point_2", "name", "marker on body 2"),
    _k("stiffness", "expr", "k", default=0.0), _k("cubic_stiffness", "expr", "k3", default=0.0),
    _k("damping", "expr", "d", default=0.0), _k("free_length", "expr", "L0 (default: the initial length)"),
), type_value="spring_damper")


@register_law
class SpringDamperLaw(ForceLaw):
    """Spring-dampers: the model's ``springs`` (axial elements)."""

    type = "spring_damper"
    order = 3
    keys = SPRING_DAMPER_KEYS
    compiled = True
    output_kinds = ("length", "length_rate", "force")
    what = "spring"

    def read(self, rd: Reader, entry: dict, path: str, name: str, out: ForceElements) -> None:
        """A ``spring_damper`` between two points; its free length given or that of the initial pose."""
        f, fp = entry, path
        ends = attachments(rd, f, fp, name)
        if ends is None:
            return
        b1, P1, b2, P2 = ends
        if b1 is b2 and P1.key == P2.key:
            rd.problems.add(fp, f"expected two distinct points, found point_1 and point_2 both "
                                f"{f.get('point_1', 'the COM')!r} of body '{b1.name}': a spring from a point "
                                "to itself has zero length and no direction")
            return
        free = f.get("free_length")
        key = f"{name}.L0"
        g1 = rd.global_point_recipe(b1, P1.key)
        g2 = rd.global_point_recipe(b2, P2.key)
        rd.axial_ends.append((fp, g1, g2))      # a zero length at the initial pose: build.py reports it
        if free is None or free == "initial":
            rd.scal.append((key, lambda prm, _a=g1, _b=g2: np.sqrt(np.sum((_b(prm) - _a(prm)) ** 2))))
        else:
            il = rd.num(free, f"{fp}.free_length", positive=True)
            rd.scal.append((key, lambda prm, _i=il: prm.pv[_i]))
        out.springs.append(SpringDamper(name, Diff(P2, P1), rd.num(f.get("stiffness", 0.0), f"{fp}.stiffness"),
                                        rd.num(f.get("cubic_stiffness", 0.0), f"{fp}.cubic_stiffness"),
                                        rd.num(f.get("damping", 0.0), f"{fp}.damping"), key))

    def elements(self, model: "MultibodyModel") -> list[Any]:
        return list(model.springs)

    def output(self, model: "MultibodyModel", element: Any, kind: Any, path: str,
               problems: ProblemCollector) -> Output | None:
        """A spring's length, length rate or force."""
        if not self.known_kind(kind, path, problems, listed=False):
            return None
        return Output(_axial(model, element, kind), (f"{element.name}.{kind}",), batched=True, autonomous=True)
