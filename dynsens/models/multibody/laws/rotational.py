r"""The ``rotational_spring_damper`` between two rigid bodies: torque −k(φ − φ0) − d φ̇ about an
axis (:class:`..rotational.RotationalSpringDamper`; blocks of its own in the compiled kernels)."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ....case_keys.keys import Section, _k, _req
from ....errors import ProblemCollector
from ...base import Output
from ..bodies import BodyDef, Direction
from ..build_forces import two_bodies
from ..force_law import ForceElements, ForceLaw, register_law
from ..outputs import _ctx
from ..rotational import RotationalSpringDamper
from ..spec import Reader

if TYPE_CHECKING:
    from ..model import MultibodyModel

ROTATIONAL_KEYS = Section("forces[i], type: rotational_spring_damper",
                                              "Torque −k(φ − φ0) − d φ̇ about an axis between two bodies.", (
    _req("type", "enum", "force type", values=("rotational_spring_damper",)), _k("name", "name", "force name"),
    _req("body_1", "name", "body 1 (or ground)"), _req("body_2", "name", "body 2"),
    _req("axis", "vector", "axis (global at t0)", length=3),
    _k("stiffness", "expr", "k (torque per rad)", default=0.0), _k("damping", "expr", "d", default=0.0),
    _k("free_angle", "expr", "φ0 (rad)", default=0.0),
), type_value="rotational_spring_damper")

_ROT_UNITS = {"angle": "rad", "angle_rate": "rad/s", "torque": ""}


def _rotational(rd: Reader, f: dict, fp: str, name: str, b1: BodyDef, b2: BodyDef
                ) -> RotationalSpringDamper | None:
    if b1 is b2:
        rd.problems.add(f"{fp}.body_2", "a rotational spring-damper needs two different bodies")
        return None
    if "axis" not in f:
        rd.problems.add(f"{fp}.axis", "missing (the axis of the relative rotation, global at the initial pose)")
        return None
    keys = rd.frame_recipes(f"f:{name}", rd.vec3(f.get("axis"), f"{fp}.axis"), b1, b2)
    return RotationalSpringDamper(
        name, Direction(b1.index, keys["u1"]), Direction(b1.index, keys["v1"]), Direction(b2.index, keys["u2"]),
        rd.num(f.get("stiffness", 0.0), f"{fp}.stiffness"), rd.num(f.get("damping", 0.0), f"{fp}.damping"),
        rd.num(f.get("free_angle", 0.0), f"{fp}.free_angle"))


@register_law
class RotationalSpringDamperLaw(ForceLaw):
    """Rotational spring-dampers: in the model's ``forces`` (its ``rotational`` elements)."""

    type = "rotational_spring_damper"
    order = 4
    keys = ROTATIONAL_KEYS
    compiled = True
    output_kinds = tuple(_ROT_UNITS)
    what = "rotational spring"

    def read(self, rd: Reader, entry: dict, path: str, name: str, out: ForceElements) -> None:
        """A ``rotational_spring_damper`` between two rigid bodies."""
        bodies = two_bodies(rd, entry, path)
        if bodies is None:
            return
        b1, b2 = bodies
        if b1.point_mass or b2.point_mass:
            rd.problems.add(f"{path}.body_{1 if b1.point_mass else 2}", "a point mass has no orientation: "
                                                                        "a rotational spring cannot act on it")
            return
        rot = _rotational(rd, entry, path, name, b1, b2)
        if rot is not None:
            out.forces.append(rot)

    def elements(self, model: "MultibodyModel") -> list[Any]:
        return list(model.rotational)

    def output(self, model: "MultibodyModel", element: Any, kind: Any, path: str,
               problems: ProblemCollector) -> Output | None:
        """A rotational spring-damper's angle, rate or torque (its state(): angle, rate, torque)."""
        if not self.known_kind(kind, path, problems):
            return None
        level = self.output_kinds.index(kind)
        return Output(lambda t, s, prm: element.state(_ctx(s, prm, t))[level][0], (f"{element.name}.{kind}",),
                      _ROT_UNITS[kind])
