"""Reading the ``model`` mapping of a multibody case: bodies, markers, and point/axis recipes.

Every numeric entry goes through the :class:`ParameterTable` (so it may be a design
expression); body-fixed vectors derived from global input (a joint point given in global
coordinates at the initial pose, an axis, a free length) are *recipes* evaluated in
``parameters(x)``, so they follow the design complex-safely.
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from ...errors import ProblemCollector
from ...case_keys import allowed
from .._keys import check_keys, did_you_mean
from ..parameters import ParameterTable
from .bodies import GROUND, BodyDef, MBParams
from .rotations import perpendicular_pair, rotate

BODY_KEYS = allowed("multibody.body")
POINT_MASS_KEYS = ("mass", "point_mass", "position", "velocity", "markers")
Recipe = Callable[..., Any]  # recipe(params); "..." admits lambdas with bound defaults


class Reader:
    """Shared state of one model build: the table, the problems, bodies and recipes."""

    def __init__(self, table: ParameterTable, problems: ProblemCollector):
        self.table = table
        self.problems = problems
        self.bodies: list[BodyDef] = []
        self.ground = BodyDef("ground", GROUND)
        self.by_name: dict[str, BodyDef] = {"ground": self.ground}
        self.vec: list[tuple[str, Recipe]] = []
        # (point-mass body, vec key, what) of every point attached to a point mass
        self.point_mass_attachments: list[tuple[str, str, str]] = []
        self.scal: list[tuple[str, Recipe]] = []
        # (YAML path, global point 1, global point 2) at the initial pose of every spring-damper
        self.axial_ends: list[tuple[str, Recipe, Recipe]] = []
        for k, e in (("e_x", (1.0, 0, 0)), ("e_y", (0, 1.0, 0)), ("e_z", (0, 0, 1.0)), ("zero", (0, 0, 0))):
            self.vec.append((k, lambda prm, _e=e: np.array(_e, dtype=float)))

    # -------------------------------------------------------------- numbers
    def num(self, value: Any, path: str, **kw: Any) -> int:
        return self.table.add(value, path, self.problems, **kw)

    def vec3(self, value: Any, path: str, default: Any = None) -> tuple[int, ...]:
        if value is None:
            value = default
        return tuple(self.table.add_many(value, path, self.problems, length=3))

    # -------------------------------------------------------------- bodies
    def read_bodies(self, spec: Any, path: str) -> None:
        if not isinstance(spec, dict) or not spec:
            self.problems.add(path, "expected a mapping name -> body (mass, inertia, position, ...)")
            return
        for name, b in spec.items():
            bp = f"{path}.{name}"
            if name == "ground":
                if check_keys(b, bp, ("markers",), self.problems):
                    self._markers(self.ground, b.get("markers"), f"{bp}.markers")
                continue
            point = isinstance(b, dict) and b.get("point_mass", False)
            if isinstance(b, dict) and not isinstance(point, bool):
                self.problems.add(f"{bp}.point_mass", f"expected true or false, found {point!r}")
                continue
            if point:
                # no inertia, no orientation: the body is its mass point (docs/multibody.md "Point masses")
                extra = [k for k in ("inertia", "orientation", "angular_velocity") if k in b]
                for k in extra:
                    self.problems.add(f"{bp}.{k}", "a point mass has no rotational inertia or "
                                                   "orientation: remove it, or drop point_mass")
                if extra or not check_keys(b, bp, POINT_MASS_KEYS, self.problems, required=("mass",)):
                    continue
            elif not check_keys(b, bp, BODY_KEYS, self.problems, required=("mass", "inertia")):
                continue
            body = BodyDef(str(name), len(self.bodies))
            body.point_mass = bool(point)
            body.mass = self.num(b.get("mass"), f"{bp}.mass", positive=True)
            inertia = [0.0, 0.0, 0.0] if point else b.get("inertia")
            if isinstance(inertia, (list, tuple)) and len(inertia) in (3, 6):
                # principal moments > 0 (also when given as expressions), none for a point mass;
                # products of any sign
                body.inertia = tuple(self.num(v, f"{bp}.inertia[{i}]", positive=i < 3 and not point)
                                     for i, v in enumerate(inertia))
                if len(inertia) == 3:
                    body.inertia += tuple(self.num(0.0, f"{bp}.inertia") for _ in range(3))
                else:       # products may make the tensor indefinite: a body that cannot exist
                    xx, yy, zz, xy, xz, yz = body.inertia
                    self.table.require_positive_definite(((xx, xy, xz), (xy, yy, yz), (xz, yz, zz)),
                                                         f"{bp}.inertia", "inertia tensor")
            else:
                self.problems.add(f"{bp}.inertia", "expected [Ixx, Iyy, Izz] or [Ixx, Iyy, Izz, Ixy, "
                                                   f"Ixz, Iyz] about the COM in body axes, found {inertia!r}")
                body.inertia = (-1,) * 6
            body.position = self.vec3(b.get("position"), f"{bp}.position", [0.0, 0.0, 0.0])
            body.velocity = self.vec3(b.get("velocity"), f"{bp}.velocity", [0.0, 0.0, 0.0])
            body.angular_velocity = self.vec3(b.get("angular_velocity"), f"{bp}.angular_velocity",
                                              [0.0, 0.0, 0.0])
            body.orientation = self._orientation(b.get("orientation"), f"{bp}.orientation")
            self.bodies.append(body)
            self.by_name[body.name] = body
            self._markers(body, b.get("markers"), f"{bp}.markers")

    def _orientation(self, o: Any, path: str) -> tuple[Any, ...]:
        if o is None:
            return ("identity",)
        if isinstance(o, dict) and "euler_parameters" in o:
            check_keys(o, path, allowed("multibody.orientation.euler"), self.problems)
            ep = tuple(self.table.add_many(o["euler_parameters"], f"{path}.euler_parameters",
                                           self.problems, length=4))
            self.table.require_nonzero(ep, f"{path}.euler_parameters", "set of Euler parameters")
            return ("ep", ep)
        if not check_keys(o, path, allowed("multibody.orientation.axis_angle"), self.problems, required=("angle",)):
            return ("identity",)
        axis = self.vec3(o.get("axis"), f"{path}.axis", [0.0, 0.0, 1.0])
        self.table.require_nonzero(axis, f"{path}.axis", "rotation axis")
        return ("axis", axis, self.num(o.get("angle"), f"{path}.angle"))

    def _markers(self, body: BodyDef, spec: Any, path: str) -> None:
        if spec is None:
            return
        if not isinstance(spec, dict):
            self.problems.add(path, "expected a mapping marker name -> [x, y, z] or {position, frame}")
            return
        for mname, m in spec.items():
            mp = f"{path}.{mname}"
            frame = "body"
            if isinstance(m, dict):
                if not check_keys(m, mp, allowed("multibody.marker"), self.problems, required=("position",)):
                    continue
                frame = m.get("frame", "body")
                if frame not in ("body", "global"):
                    self.problems.add(f"{mp}.frame", f"expected 'body' or 'global', found {frame!r}")
                m = m.get("position")
            idx = self.vec3(m, mp)
            body.markers[str(mname)] = (idx, frame)
            self.vec.append((self.marker_key(body, str(mname)), self._marker_recipe(body, idx, frame)))

    @staticmethod
    def marker_key(body: BodyDef, name: str) -> str:
        return f"m:{body.name}.{name}"

    @staticmethod
    def _pose(prm: MBParams, body: BodyDef) -> tuple[Any, Any]:
        if body.index == GROUND:
            return np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
        bp = prm.bodies[body.index]
        return bp.r0, bp.p0

    def _marker_recipe(self, body: BodyDef, idx: tuple[int, ...], frame: str) -> Recipe:
        def fn(prm: MBParams) -> Any:
            v = np.array([prm.pv[i] for i in idx])
            if frame == "global" and body.index != GROUND:
                r0, p0 = self._pose(prm, body)
                return to_body(p0, v - r0)
            return v
        return fn

    # -------------------------------------------------------------- lookups
    def two_bodies(self, j: dict, jp: str) -> tuple[BodyDef, BodyDef] | None:
        """The bodies ``body_1`` and ``body_2`` of the joint entry ``j`` at ``jp``, which must
        differ (None once a problem is reported)."""
        b1, b2 = self.body(j.get("body_1"), f"{jp}.body_1"), self.body(j.get("body_2"), f"{jp}.body_2")
        if b1 is None or b2 is None:
            return None
        if b1 is b2:
            self.problems.add(f"{jp}.body_2", "a joint needs two different bodies")
            return None
        return b1, b2

    def body(self, name: Any, path: str) -> BodyDef | None:
        if name not in self.by_name:
            self.problems.add(path, f"unknown body {name!r}{did_you_mean(name, self.by_name)} "
                                    f"(bodies: {', '.join(self.by_name)})")
            return None
        return self.by_name[name]

    def marker(self, body: BodyDef, name: Any, path: str) -> str | None:
        if name not in body.markers:
            self.problems.add(path, f"body '{body.name}' has no marker {name!r}"
                                    f"{did_you_mean(name, body.markers)} (markers: "
                                    f"{', '.join(body.markers) or 'none'})")
            return None
        return self.marker_key(body, str(name))

    def marker_ref(self, ref: Any, path: str) -> tuple[BodyDef, str] | None:
        """'body.marker' → (body, vec key)."""
        if not isinstance(ref, str) or "." not in ref:
            self.problems.add(path, f"expected 'body.marker', found {ref!r}")
            return None
        bname, mname = ref.split(".", 1)
        body = self.body(bname, path)
        if body is None:
            return None
        key = self.marker(body, mname, path)
        return None if key is None else (body, key)

    def global_point_recipe(self, body: BodyDef, key: str) -> Recipe:
        """Global position at the initial (guess) pose of the point vec[key] of body."""
        def fn(prm: MBParams) -> Any:
            r0, p0 = self._pose(prm, body)
            return r0 + rotate(p0.reshape(4, 1), prm.vec[key])[:, 0]
        return fn

    def local_point(self, body: BodyDef, key: str, global_fn: Recipe) -> str:
        """Register body-axes coordinates (rel. COM) of a global point given at the initial pose."""
        def fn(prm: MBParams) -> Any:
            r0, p0 = self._pose(prm, body)
            return to_body(p0, global_fn(prm) - r0)
        self.vec.append((key, fn))
        return key

    def local_direction(self, body: BodyDef, key: str, global_fn: Recipe) -> str:
        def fn(prm: MBParams) -> Any:
            _, p0 = self._pose(prm, body)
            return to_body(p0, global_fn(prm))
        self.vec.append((key, fn))
        return key

    def point_on(self, body: BodyDef, spec: Any, path: str, key: str) -> str | None:
        """A point of ``body``: a marker name, or [x, y, z] in body axes rel. the COM."""
        if isinstance(spec, str):
            k = self.marker(body, spec, path)
        else:
            idx = self.vec3(spec, path, [0.0, 0.0, 0.0])
            self.vec.append((key, lambda prm, _i=idx: np.array([prm.pv[i] for i in _i])))
            k = key
        if k is not None:
            self.attached(body, k, f"the point at {path}")
        return k

    def attached(self, body: BodyDef, key: str, what: str) -> None:
        """Record a point of ``body`` that a joint or force uses (checked for point masses)."""
        if body.point_mass:
            self.point_mass_attachments.append((body.name, key, what))

    def frame_recipes(self, name: str, axis_idx: tuple[int, ...], b1: BodyDef, b2: BodyDef
                      ) -> dict[str, str]:
        """Joint frame (u, v, w) from a global axis at the initial pose, in both bodies' axes."""
        def w_glob(prm: MBParams) -> Any:
            w = np.array([prm.pv[i] for i in axis_idx])
            return w / np.sqrt(np.sum(w * w))
        keys = {}
        for c, sel in (("u", 0), ("v", 1), ("w", 2)):
            def g(prm: MBParams, _sel: int = sel) -> Any:
                w = w_glob(prm)
                if _sel == 2:
                    return w
                return perpendicular_pair(w)[_sel]
            for tag, body in (("1", b1), ("2", b2)):
                keys[c + tag] = self.local_direction(body, f"j:{name}.{c}{tag}", g)
        return keys


def to_body(p0: Any, v: Any) -> Any:
    """A(p0)ᵀ v for a single quaternion p0 (4,) and vector v (3,)."""
    pc = np.array([p0[0], -p0[1], -p0[2], -p0[3]])
    return rotate(pc.reshape(4, 1), np.asarray(v).reshape(3, 1))[:, 0]
