"""The model as drawn over time: points, line cells and their fields, rebuilt from a result file.

A result file stores the effective case (root attribute ``case``), the design of each run and
its state histories.  :func:`read_scene` rebuilds the model from that case, evaluates the
model's own outputs (the quantities a case can name) at every stored instant, and returns
:class:`Scene` parts that the ParaView writer (:mod:`dynsens.io.vtk`) and the animation
(:mod:`dynsens.animate`) both draw:

* a structural model: one part ``members``, its points the nodes (undeformed coordinates),
  its cells the bars and beams; point data ``displacement`` and (with the ``qd`` history)
  ``velocity``; cell data ``axial_force``, ``stress`` (a beam's extreme-fibre stress of
  largest magnitude), ``stress_ratio`` = max(σ/σ_t, −σ/σ_c) with the limits of the case's
  ``stress_ratio`` responses (the smallest of each, as the post-check reads them) and
  ``buckling_ratio`` = −N/P_E (bars with ``inertia``; NaN for the others);
* a multibody model: parts ``bodies`` (each body's centre of mass joined to each of its
  markers by a line, the ground's markers as points; cell data ``body``, the body's index, -1
  the ground), ``joints`` (the joint points, point data
  ``reaction_force`` and ``reaction_force_norm`` with the ``lam`` history), ``cylinders``
  (hydraulic cylinders as lines, cell data ``stroke``, and with the ``p`` history ``force``,
  ``pressure_1``, ``pressure_2``) and ``springs`` (``length``, ``force``).

Units are the case's own (e.g. mm, N, MPa).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import h5py
import numpy as np
import yaml

from ..errors import DynsensError, ProblemCollector
from ..models.base import StepState
from .series import read_series


class SceneError(DynsensError):
    """A result file that cannot be drawn (no case, no displacement history, unknown group)."""


@dataclass
class Part:
    """One mesh over time: N instants, P points, C cells (every cell a line or a vertex).

    points : (N, P, 3) coordinates (constant over time for a structure, whose motion is the
    ``displacement`` point data); lines : (L, 2) and vertices : (V,) point indices (cells are
    ordered lines first); point_data[name] : (N, P) or (N, P, 3); cell_data[name] : (N, C);
    cell_names : (C,) the element, body or joint each cell draws.
    """

    name: str
    points: np.ndarray
    lines: np.ndarray
    vertices: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    point_data: dict[str, np.ndarray] = field(default_factory=dict)
    cell_data: dict[str, np.ndarray] = field(default_factory=dict)
    cell_names: list[str] = field(default_factory=list)

    @property
    def n_cells(self) -> int:
        """Number of cells (lines, then vertices)."""
        return len(self.lines) + len(self.vertices)


@dataclass
class Scene:
    """A run drawn over time: ``time`` (N,) s, its parts, and what it is (``structure`` or
    ``mechanism``); ``label`` names the run (``""``, ``start`` or ``optimum``)."""

    kind: str
    time: np.ndarray
    parts: list[Part]
    label: str = ""
    case_name: str = ""

    def part(self, name: str) -> Part:
        """The part called ``name``."""
        return next(p for p in self.parts if p.name == name)


#: the runs an optimization file stores, by the label of their export
OPTIMIZATION_RUNS = {"start": "optimization/initial", "optimum": "optimization/optimum"}


def stored_runs(path: str | Path) -> dict[str, str]:
    """label -> HDF5 group of every run in the file that can be drawn: ``{"": "/"}`` for a
    simulation file, ``start`` and ``optimum`` for an optimization file."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(f"{path}: expected a dynsens result file, found no such file")
    try:
        with h5py.File(path, "r") as f:
            if "time" in f:
                return {"": "/"}
            runs = {label: g for label, g in OPTIMIZATION_RUNS.items() if g in f}
    except OSError as exc:
        raise SceneError(f"{path}: expected a dynsens result file (HDF5), found a file h5py cannot read "
                         f"({exc})") from None
    if not runs:
        raise SceneError(f"{path}: expected the time series of a run (/time of a simulation, or "
                         f"/optimization/optimum of an optimization), found none")
    return runs


def read_scene(path: str | Path, group: str = "/", label: str = "") -> Scene:
    """The run stored in ``group`` of result file ``path`` as a :class:`Scene`."""
    from ..case.load import load_case_text
    from ..models.multibody.model import MultibodyModel
    from ..models.structural.model import StructuralModel
    path = Path(path)
    with h5py.File(path, "r") as f:
        text = f.attrs.get("case")
        if group not in f:
            raise SceneError(f"{path}: expected the group {group}, found none")
        g = f[group]
        series = read_series(g)
        x = g["x"][()] if "x" in g else (f["design/values"][()] if "design/values" in f else np.zeros(0))
    if not text:
        raise SceneError(f"{path}: expected the case in the root attribute 'case', found none")
    text = text.decode() if isinstance(text, bytes) else str(text)
    state = series.get("state", {})
    if "q" not in state:
        raise SceneError(f"{path}: expected the displacement history {group.rstrip('/')}/state/q to draw the "
                         f"model, found {'the histories ' + ', '.join(state) if state else 'no state history'} "
                         "(run the case with output.history: [q, qd, lam, p], e.g. "
                         "--set 'output.history=[q,qd,lam,p]'; simulate --vtk/--animate add them)")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")       # the run already warned about its case
        case = load_case_text(text, f"{path}:case")
    model = case.model
    params = model.parameters(np.asarray(x, dtype=float))
    time = np.asarray(series["time"], dtype=float)
    raw = yaml.safe_load(text) or {}
    if isinstance(model, StructuralModel):
        parts = [_members(model, case, raw, state, params, time)]
        kind = "structure"
    elif isinstance(model, MultibodyModel):
        parts = _mechanism(model, state, params, time)
        kind = "mechanism"
    else:
        raise SceneError(f"{path}: expected a structural or multibody model, found {type(model).__name__}")
    return Scene(kind, time, parts, label, case.name)


def _states(state: dict[str, np.ndarray], n: int) -> list[StepState]:
    """One StepState per stored instant (histories that were not stored are zeros)."""
    q = np.real(state["q"])
    empty = np.zeros((n, 0))
    cols = [q, state.get("qd", np.zeros_like(q)), state.get("qdd", np.zeros_like(q)),
            state.get("lam", empty), state.get("p", empty), state.get("pd", empty)]
    return [StepState(*(np.real(c[k]) for c in cols)) for k in range(n)]


def _series(model: Any, spec: dict, time: np.ndarray, states: list[StepState], params: Any) -> np.ndarray:
    """(N, k) values of the model's output ``spec`` at every stored instant."""
    pc = ProblemCollector("scene")
    out = model.output(spec, "quantity", pc)
    pc.raise_if_any()
    assert out is not None
    return np.array([np.real(np.asarray(out.fn(t, s, params), dtype=complex)).reshape(-1)
                     for t, s in zip(time, states)]).reshape(len(time), -1)


# ------------------------------------------------------------------ structures
def _members(model: Any, case: Any, raw: dict, state: dict[str, np.ndarray], params: Any,
             time: np.ndarray) -> Part:
    from ..postcheck import stress_limits
    n = len(time)
    pv = np.real(np.asarray(params["pv"]))
    names = list(model.node_names)
    X = np.zeros((len(names), 3))
    for i, nm in enumerate(names):
        X[i, :model.dim] = pv[np.asarray(model.node_coords[nm])]
    member_names = list(model.bar_names) + list(model.beams.names) + list(model.frames.names)
    ends: dict[str, tuple[int, int]] = {}
    for k, el in enumerate((raw.get("model") or {}).get("elements") or []):
        nodes = el.get("nodes") if isinstance(el, dict) else None
        if isinstance(nodes, list) and len(nodes) == 2:     # (an unnamed element's name as the builder gives it)
            ends[str(el.get("name", f"{el.get('type')}{k}"))] = (names.index(nodes[0]), names.index(nodes[1]))
    member_names = [m for m in member_names if m in ends]
    if not member_names:
        raise SceneError(f"{case.source}: expected bars or beams between nodes to draw, found none "
                         "(springs, dampers and masses on degrees of freedom are not drawn)")
    lines = np.array([ends[m] for m in member_names], dtype=int).reshape(-1, 2)
    states = _states(state, n)
    index = {d: i for i, d in enumerate(model.dof_names)}

    def nodal(field_: np.ndarray) -> np.ndarray:
        out = np.zeros((n, len(names), 3))
        for i, nm in enumerate(names):
            for a, axis in enumerate("xyz"[:model.dim]):
                if f"{nm}.{axis}" in index:
                    out[:, i, a] = np.real(field_[:, index[f"{nm}.{axis}"]])
        return out

    point_data = {"displacement": nodal(state["q"])}
    if "qd" in state:
        point_data["velocity"] = nodal(state["qd"])
    force = np.full((n, len(member_names)), np.nan)
    stress = np.full((n, len(member_names)), np.nan)
    sig_t, sig_c = stress_limits(case)
    ratio = np.full((n, len(member_names)), -np.inf)
    col = {m: j for j, m in enumerate(member_names)}
    families = [(list(model.bar_names), 1, 1, 0), (list(model.beams.names), 3, 4, 0),
                (list(model.frames.names), 6, 4, 0)]
    for fam, n_force, n_stress, i_axial in families:
        fam = [m for m in fam if m in col]
        if not fam:
            continue
        js = [col[m] for m in fam]
        F = _series(model, {"element": fam, "kind": "force"}, time, states, params).reshape(n, len(fam), n_force)
        S = _series(model, {"element": fam, "kind": "stress"}, time, states, params).reshape(n, len(fam), n_stress)
        force[:, js] = F[:, :, i_axial]
        pick = np.argmax(np.abs(S), axis=2)[..., None]
        stress[:, js] = np.take_along_axis(S, pick, axis=2)[..., 0]
        if sig_t:
            ratio[:, js] = np.maximum(ratio[:, js], (S / sig_t).max(axis=2))
        if sig_c:
            ratio[:, js] = np.maximum(ratio[:, js], (-S / sig_c).max(axis=2))
    cell_data = {"axial_force": force, "stress": stress}
    if sig_t or sig_c:
        cell_data["stress_ratio"] = np.where(np.isfinite(ratio), ratio, np.nan)
    braced = [m for m, inertia in zip(model.bar_names, model.bar_I) if inertia >= 0 and m in col]
    if braced:
        buckling = np.full((n, len(member_names)), np.nan)
        buckling[:, [col[m] for m in braced]] = _series(model, {"element": braced, "kind": "buckling"},
                                                        time, states, params)
        cell_data["buckling_ratio"] = buckling
    return Part("members", np.broadcast_to(X, (n,) + X.shape), lines, point_data=point_data,
                cell_data=cell_data, cell_names=member_names)


# ------------------------------------------------------------------ mechanisms
def _mechanism(model: Any, state: dict[str, np.ndarray], params: Any, time: np.ndarray) -> list[Part]:
    """The bodies (markers joined to the centre of mass), the joints (with their reaction forces
    when the multipliers were stored), the cylinders and the springs of a mechanism."""
    motion = _Motion(state, params, len(time))
    series = lambda spec: _series(model, spec, time, motion.states, params)
    parts = [_bodies(model, motion)]
    joints = _joints(model, motion, "lam" in state, series)
    if joints is not None:
        parts.append(joints)
    # a cylinder's force reads its pressures: without them, its stroke only
    cylinder_kinds = ("stroke", "force", "pressure_1", "pressure_2") if "p" in state else ("stroke",)
    for label, elements, kinds in (("cylinders", model.cylinders, cylinder_kinds),
                                   ("springs", model.springs, ("length", "force"))):
        if elements:
            parts.append(_axial(label, elements, kinds, motion, series))
    return parts


class _Motion:
    """The stored motion of a mechanism: its points' tracks over all instants."""

    def __init__(self, state: dict[str, np.ndarray], params: Any, n: int):
        self.n = n
        self.q = np.real(state["q"])
        self.qd = np.real(state.get("qd", np.zeros_like(self.q)))
        self.params = params
        self.states = _states(state, n)

    def track(self, pt: Any) -> np.ndarray:
        """(N, 3) positions of a point fixed in a body, all instants in one batched evaluation (the
        columns of the context are the instants; a fresh context, as its cache is keyed by id)."""
        from ..models.multibody.bodies import Ctx
        ctx = Ctx(self.q.T, self.qd.T, np.zeros_like(self.q.T), self.params, 0.0)
        return np.real(np.broadcast_to(pt.kin(ctx)[0], (3, self.n)).T)

    def com(self, b: int) -> np.ndarray:
        """(N, 3) positions of body b's centre of mass."""
        return self.q[:, 7 * b:7 * b + 3]


def _bodies(model: Any, motion: _Motion) -> Part:
    """Each body as lines from its centre of mass to its markers (a vertex when it has none);
    the ground's markers as vertices; cell data ``body`` (the body's index, -1 the ground)."""
    from ..models.multibody.bodies import GROUND, Point
    from ..models.multibody.spec import Reader
    pts: list[np.ndarray] = []
    lines: list[tuple[int, int]] = []
    vertices: list[int] = []
    cell_names: list[str] = []
    for body in model.bodies:
        c = len(pts)
        pts.append(motion.com(body.index))
        for m in body.markers:
            lines.append((c, len(pts)))
            cell_names.append(f"{body.name}.{m}")
            pts.append(motion.track(Point(body.index, Reader.marker_key(body, m))))
        if not body.markers:
            vertices.append(c)
    for m in model.ground.markers:
        vertices.append(len(pts))
        pts.append(motion.track(Point(GROUND, Reader.marker_key(model.ground, m))))
    cell_names += [f"{b.name}" for b in model.bodies if not b.markers] + [f"ground.{m}" for m in model.ground.markers]
    # which body each cell draws (0, 1, ... in the case's order; -1 the ground), to colour by
    body_of = [b.index for b in model.bodies for _ in b.markers] + \
        [b.index for b in model.bodies if not b.markers] + [-1] * len(model.ground.markers)
    n = motion.n
    return Part("bodies", _stack(pts, n), np.array(lines, dtype=int).reshape(-1, 2),
                np.array(vertices, dtype=int), cell_names=cell_names,
                cell_data={"body": np.broadcast_to(np.array(body_of, dtype=float), (n, len(body_of)))})


def _joints(model: Any, motion: _Motion, with_reactions: bool, series: Callable[[dict], np.ndarray]
            ) -> Part | None:
    """The joints (not the driving constraints) as vertices at their points, with their reaction
    forces when ``with_reactions``; None for a mechanism without one."""
    from ..models.multibody.bodies import GROUND
    joints = [jt for jt in model.joints if jt.kind != "driving"]
    if not joints:
        return None
    where = [motion.track(jt.point_2) if jt.point_2 is not None
             else motion.com(jt.body_2 if jt.body_2 != GROUND else jt.body_1) for jt in joints]
    part = Part("joints", _stack(where, motion.n), np.zeros((0, 2), dtype=int), np.arange(len(joints)),
                cell_names=[jt.name for jt in joints])
    if with_reactions:
        f = np.stack([series({"joint": jt.name, "kind": "reaction_force"}) for jt in joints], axis=1)
        part.point_data = {"reaction_force": f, "reaction_force_norm": np.linalg.norm(f, axis=2)}
    return part


def _axial(label: str, elements: list, kinds: tuple[str, ...], motion: _Motion,
           series: Callable[[dict], np.ndarray]) -> Part:
    """Axial elements (cylinders, springs) as lines between their end points, with their
    quantities ``kinds`` as cell data."""
    ends = [p for el in elements for p in (motion.track(el.d.b), motion.track(el.d.a))]
    data = {k: np.stack([series({"element": el.name, "kind": k})[:, 0] for el in elements], axis=1) for k in kinds}
    return Part(label, _stack(ends, motion.n), np.arange(2 * len(elements)).reshape(-1, 2),
                cell_data=data, cell_names=[el.name for el in elements])


def _stack(points: list[np.ndarray], n: int) -> np.ndarray:
    """(N, P, 3) from P arrays (N, 3)."""
    return np.stack(points, axis=1) if points else np.zeros((n, 0, 3))
