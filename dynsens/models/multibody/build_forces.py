"""The ``forces`` list of a multibody case, read into force elements by the laws their ``type``
selects (:mod:`.force_law`; part of :func:`.build.build_multibody`; problems collected with
their YAML paths), and the reading helpers the laws share."""
from __future__ import annotations

from typing import Any

from ...case_keys import allowed
from .._keys import check_keys, did_you_mean
from .bodies import BodyDef, Diff, Point
from .force_law import ForceElements, load_laws
from .spec import Reader

__all__ = ["Diff", "attachments", "point_on", "read_forces", "two_bodies"]


def point_on(rd: Reader, body: BodyDef, spec: Any, path: str, key: str) -> Point | None:
    """The point ``spec`` (a marker name; None: the COM) on ``body`` (None after a problem)."""
    k = rd.point_on(body, spec, path, key)
    return None if k is None else Point(body.index, k)


def two_bodies(rd: Reader, f: dict, fp: str) -> tuple[BodyDef, BodyDef] | None:
    """The bodies ``body_1`` and ``body_2`` an element connects (None after a problem)."""
    b1, b2 = rd.body(f.get("body_1"), f"{fp}.body_1"), rd.body(f.get("body_2"), f"{fp}.body_2")
    return None if b1 is None or b2 is None else (b1, b2)


def attachments(rd: Reader, f: dict, fp: str, name: str) -> tuple[BodyDef, Point, BodyDef, Point] | None:
    """The bodies an axial element connects and its points on them, ``point_1`` and ``point_2``."""
    bodies = two_bodies(rd, f, fp)
    if bodies is None:
        return None
    b1, b2 = bodies
    P1 = point_on(rd, b1, f.get("point_1"), f"{fp}.point_1", f"f:{name}.p1")
    P2 = point_on(rd, b2, f.get("point_2"), f"{fp}.point_2", f"f:{name}.p2")
    return None if P1 is None or P2 is None else (b1, P1, b2, P2)


def read_forces(rd: Reader, spec: Any, path: str, forces: list, cylinders: list, springs: list) -> None:
    """Read the ``forces`` list ``spec`` at ``path`` with the registered laws: hydraulic cylinders
    go to ``cylinders``, spring-dampers to ``springs``, all other elements to ``forces``;
    problems go to rd.problems."""
    if not isinstance(spec, list):
        rd.problems.add(path, "expected a list of force elements")
        return
    laws = load_laws()
    names: set[str] = set()
    out = ForceElements(forces, cylinders, springs)
    for i, f in enumerate(spec):
        fp = f"{path}[{i}]"
        if not isinstance(f, dict) or not isinstance(f.get("type"), str) or f["type"] not in laws:
            kind = f.get("type") if isinstance(f, dict) else f
            rd.problems.add(f"{fp}.type", f"unknown force type {kind!r}{did_you_mean(kind, laws)} "
                                          f"(known: {', '.join(laws)})")
            continue
        law = laws[f["type"]]
        name = str(f.get("name", f"{law.type}{i + 1}"))
        if name in names:
            rd.problems.add(f"{fp}.name", f"duplicate force name '{name}'")
        names.add(name)
        check_keys(f, fp, allowed(law.section), rd.problems)
        law.read(rd, f, fp, name, out)
