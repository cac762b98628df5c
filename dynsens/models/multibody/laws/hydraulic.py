r"""The ``hydraulic_cylinder`` between two markers, with its two chamber pressures as first-order
states (:class:`..hydraulics.HydraulicCylinder`; a law of the compiled kernels)."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ....case_keys.keys import Section, _k, _req
from ....errors import ProblemCollector
from ...base import Output
from ...timefunctions import build_time_function
from ..bodies import Diff
from ..build_forces import attachments
from ..force_law import ForceElements, ForceLaw, register_law
from ..hydraulics import HydraulicCylinder
from ..outputs import _axial
from ..spec import Reader

if TYPE_CHECKING:
    from ..model import MultibodyModel

CYLINDER_KEYS = Section("forces[i], type: hydraulic_cylinder", "Two-chamber cylinder between two "
                                        "markers; its chamber pressures are first-order states.", (
    _req("type", "enum", "force type", values=("hydraulic_cylinder",)), _k("name", "name", "force name"),
    _req("body_1", "name", "barrel body"), _req("point_1", "name", "barrel pivot marker"),
    _req("body_2", "name", "rod body"), _req("point_2", "name", "rod eye marker"),
    _k("bore", "expr", "piston diameter (or give area_1)"), _k("rod", "expr", "rod diameter (or give area_2)"),
    _k("area_1", "expr", "piston-side area"), _k("area_2", "expr", "rod-side area"),
    _req("length_0", "expr", "pin-to-pin length at zero stroke"), _req("stroke_max", "expr", "stroke"),
    _req("bulk_modulus", "expr", "effective bulk modulus"),
    _req("dead_volume_1", "expr", "piston-side dead (line) volume"),
    _req("dead_volume_2", "expr", "rod-side dead (line) volume"),
    _k("tank_conductance", "expr", "laminar return-line conductance (rod side to tank)", default=0.0),
    _k("tank_pressure", "expr", "tank pressure", default=0.0),
    _k("damping", "expr", "viscous damping on the stroke rate", default=0.0),
    _req("pump_flow", "expr", "pump flow into the piston side (volume per time)"),
    _k("pump_function", "any", "time function multiplying the pump flow", default="constant"),
    _k("initial_pressures", "any", "'static' (p1 holds the load, p2 = tank), or [p1 | static, p2]",
       default="static"),
), type_value="hydraulic_cylinder")


def _cylinder(rd: Reader, f: dict, fp: str, name: str, d: Diff, p_index: int) -> HydraulicCylinder | None:
    idx: dict[str, int] = {}
    req = ("length_0", "stroke_max", "bulk_modulus", "dead_volume_1", "dead_volume_2", "pump_flow")
    for key in req:
        if key not in f:
            rd.problems.add(f"{fp}.{key}", "missing")
        idx[key] = rd.num(f.get(key, 1.0), f"{fp}.{key}", positive=key != "pump_flow")
    idx["tank_conductance"] = rd.num(f.get("tank_conductance", 0.0), f"{fp}.tank_conductance", nonnegative=True)
    idx["tank_pressure"] = rd.num(f.get("tank_pressure", 0.0), f"{fp}.tank_pressure")
    idx["damping"] = rd.num(f.get("damping", 0.0), f"{fp}.damping", nonnegative=True)
    if ("bore" in f) == ("area_1" in f):
        rd.problems.add(fp, "give exactly one of 'bore' (piston diameter) or 'area_1' (piston area)")
        return None
    if "bore" in f:
        ib = rd.num(f["bore"], f"{fp}.bore", positive=True)
        rd.scal.append((name + ".A1", lambda prm, _i=ib: np.pi / 4.0 * prm.pv[_i] ** 2))
    else:
        ia = rd.num(f["area_1"], f"{fp}.area_1", positive=True)
        rd.scal.append((name + ".A1", lambda prm, _i=ia: prm.pv[_i]))
    if "rod" in f:
        ir = rd.num(f["rod"], f"{fp}.rod", positive=True)
        rd.scal.append((name + ".A2", lambda prm, _i=ir, _n=name: prm.scal[_n + ".A1"]
                        - np.pi / 4.0 * prm.pv[_i] ** 2))
    elif "area_2" in f:
        ia2 = rd.num(f["area_2"], f"{fp}.area_2", positive=True)
        rd.scal.append((name + ".A2", lambda prm, _i=ia2: prm.pv[_i]))
    else:
        rd.problems.add(fp, "give 'rod' (rod diameter) or 'area_2' (rod-side annulus area)")
        return None
    pump = build_time_function(f.get("pump_function"), f"{fp}.pump_function", rd.table, rd.problems)
    ini = f.get("initial_pressures", "static")
    initial: Any = "static"
    p2 = idx["tank_pressure"]
    if isinstance(ini, list) and len(ini) == 2:
        if ini[0] != "static":
            initial = rd.num(ini[0], f"{fp}.initial_pressures[0]")
        p2 = rd.num(ini[1], f"{fp}.initial_pressures[1]")
    elif ini != "static":
        rd.problems.add(f"{fp}.initial_pressures", f"expected 'static' or [p1 | static, p2], found {ini!r}")
    if pump is None:
        return None
    return HydraulicCylinder(name, d, idx, pump, p_index, initial, p2)


@register_law
class HydraulicCylinderLaw(ForceLaw):
    """Hydraulic cylinders: the model's ``cylinders`` (axial elements with pressure states)."""

    type = "hydraulic_cylinder"
    order = 5
    keys = CYLINDER_KEYS
    compiled = True
    output_kinds = ("stroke", "stroke_rate", "pressure_1", "pressure_2", "force", "volume_1", "volume_2")
    what = "cylinder"

    def read(self, rd: Reader, entry: dict, path: str, name: str, out: ForceElements) -> None:
        """A ``hydraulic_cylinder`` between two points, with its two chamber pressures as states."""
        ends = attachments(rd, entry, path, name)
        if ends is None:
            return
        _, P1, _, P2 = ends
        cyl = _cylinder(rd, entry, path, name, Diff(P2, P1), out.n_p)
        if cyl is not None:
            out.cylinders.append(cyl)
            out.n_p += 2

    def elements(self, model: "MultibodyModel") -> list[Any]:
        return list(model.cylinders)

    def output(self, model: "MultibodyModel", element: Any, kind: Any, path: str,
               problems: ProblemCollector) -> Output | None:
        """A hydraulic cylinder's stroke, pressures, force or volumes."""
        if not self.known_kind(kind, path, problems):
            return None
        name = element.name
        if kind in ("pressure_1", "pressure_2"):
            j = element.p_index + (kind == "pressure_2")
            return Output(lambda t, s, prm: s.p[j:j + 1], (f"{name}.{kind}",), linear=True)
        # the push force depends on the state only (t enters the pressure rates: pump flow)
        return Output(_axial(model, element, kind), (f"{name}.{kind}",), batched=True, autonomous=True)
