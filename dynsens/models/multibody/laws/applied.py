"""Applied loads: a ``point_force`` (a vector times a time function at a marker) and a
``torque`` (on a body), in global or body axes (:class:`..forces.PointForce`,
:class:`..forces.Torque`)."""
from __future__ import annotations

from ....case_keys.keys import Section, _k, _req
from ...timefunctions import build_time_function
from ..build_forces import point_on
from ..force_law import ForceElements, ForceLaw, register_law
from ..forces import PointForce, Torque
from ..spec import Reader

POINT_FORCE_KEYS = Section("forces[i], type: point_force", "A force at a marker.", (
    _req("type", "enum", "force type", values=("point_force",)), _k("name", "name", "force name"),
    _req("body", "name", "body"), _k("point", "name", "marker (default: the COM)"),
    _req("force", "vector", "[Fx, Fy, Fz]", length=3),
    _k("frame", "enum", "components in global or body axes", values=("global", "body"), default="global"),
    _k("function", "any", "time function multiplying the force", default="constant"),
), type_value="point_force")

TORQUE_KEYS = Section("forces[i], type: torque", "A torque on a body.", (
    _req("type", "enum", "force type", values=("torque",)), _k("name", "name", "force name"),
    _req("body", "name", "body"), _req("torque", "vector", "[Mx, My, Mz]", length=3),
    _k("frame", "enum", "components in global or body axes", values=("global", "body"), default="global"),
    _k("function", "any", "time function multiplying the torque", default="constant"),
), type_value="torque")


def _applied(rd: Reader, f: dict, fp: str, name: str, kind: str, out: ForceElements) -> None:
    """A ``point_force`` or a ``torque``: a vector times a time function, in global or body axes."""
    body = rd.body(f.get("body"), f"{fp}.body")
    frame = f.get("frame", "global")
    if frame not in ("global", "body"):
        rd.problems.add(f"{fp}.frame", f"expected 'global' or 'body', found {frame!r}")
    fn = build_time_function(f.get("function"), f"{fp}.function", rd.table, rd.problems)
    vkey = "force" if kind == "point_force" else "torque"
    if vkey not in f:
        rd.problems.add(f"{fp}.{vkey}", "missing ([x, y, z])")
    idx = rd.vec3(f.get(vkey), f"{fp}.{vkey}", [0.0, 0.0, 0.0])
    if body is None or fn is None:
        return
    if body.point_mass and (kind == "torque" or frame == "body"):
        rd.problems.add(f"{fp}.{'type' if kind == 'torque' else 'frame'}",
                        f"'{body.name}' is a point mass, which has no orientation and carries no "
                        "moment: apply a force in global axes at its position")
        return
    if kind == "point_force":
        pt = point_on(rd, body, f.get("point"), f"{fp}.point", f"f:{name}.point")
        if pt is not None:
            out.forces.append(PointForce(name, pt, idx, frame, fn))  # type: ignore[arg-type]
    else:
        out.forces.append(Torque(name, body.index, idx, frame, fn))  # type: ignore[arg-type]


@register_law
class PointForceLaw(ForceLaw):
    """Point forces (global ones have a block of their own in the compiled kernels)."""

    type = "point_force"
    order = 1
    keys = POINT_FORCE_KEYS
    compiled = True

    def read(self, rd: Reader, entry: dict, path: str, name: str, out: ForceElements) -> None:
        _applied(rd, entry, path, name, self.type, out)


@register_law
class TorqueLaw(ForceLaw):
    """Torques (closed-form other forces: exact Jacobians, added per step to compiled residuals)."""

    type = "torque"
    order = 2
    keys = TORQUE_KEYS
    compiled = True

    def read(self, rd: Reader, entry: dict, path: str, name: str, out: ForceElements) -> None:
        _applied(rd, entry, path, name, self.type, out)
