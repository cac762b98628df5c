"""Case entries of the member checks that depend on the kind of element: which elements a
response names and of what kind they are (beams, bars, springs, dampers), and the beam-column
``interaction_ratio`` (:mod:`dynsens.responses.member_stability`), built as a
:class:`dynsens.responses.sizing.FormAggregate`.

A response on an element kind it does not support is one problem, naming the response, the
kind and its elements, at the response's ``elements`` key (or ``type`` when it names none).
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from ..case_keys import allowed
from ..errors import ProblemCollector
from ..responses.member_stability import MEMBER_COMPONENTS, interaction_forms
from ..models._keys import check_keys, did_you_mean
from ..models.base import Model, Output
from ..responses.base import Response
from ..responses.sizing import FormAggregate, FormTerm
from .aggregates import OutputId, how_and_rho, positive

#: element kinds as messages name them, with the model attributes that list their names
_KIND_LISTS = (("bar", ("bar_names",)), ("beam", ("beams.names", "frames.names")),
               ("spring", ("spring_names",)), ("damper", ("damper_names", "nl_dampers.names")))


def element_kinds(model: Model | None) -> dict[str, str]:
    """Element name -> kind (bar, beam, spring, damper) of a model's structural elements (none for
    a model without them), read from its public name lists."""
    kinds: dict[str, str] = {}
    for kind, attrs in _KIND_LISTS:
        for attr in attrs:
            obj: Any = model
            for part in attr.split("."):
                obj = getattr(obj, part, None)
            for name in obj or ():
                kinds.setdefault(str(name), kind)
    return kinds


def beam_names(model: Model | None) -> tuple[str, ...]:
    """The names of a model's beams (plane and 3D), in the model's order."""
    return tuple(n for n, k in element_kinds(model).items() if k == "beam")


def members_of_kind(elements: Any, wanted: str, response: str, kind: str, path: str, model: Model | None,
                    pc: ProblemCollector) -> list[str] | None:
    """The elements a response ``kind`` (named ``response``, entry at ``path``) names, all of kind
    ``wanted`` (``all``: every one of them); otherwise one problem saying which kinds it got."""
    kinds = element_kinds(model)
    of_kind = [n for n, k in kinds.items() if k == wanted]
    if elements == "all":
        if not of_kind:
            pc.add(f"{path}.type", f"{kind} of response {response!r} applies to {wanted}s; "
                                   f"the model ({type(model).__name__}) has none")
            return None
        return of_kind
    names = elements if isinstance(elements, list) else [elements]
    if not names or not all(isinstance(n, str) for n in names):
        pc.add(f"{path}.elements", f"expected all, an element name or a non-empty list of them, found {elements!r}")
        return None
    unknown = [n for n in names if n not in kinds]
    for n in unknown:
        pc.add(f"{path}.elements", f"unknown element {n!r}{did_you_mean(n, list(kinds))}")
    others: dict[str, list[str]] = {}
    for n in names:
        if n in kinds and kinds[n] != wanted:
            others.setdefault(kinds[n], []).append(n)
    if others:
        found = " or ".join(f"{k}s ({', '.join(v[:5])}{' ...' if len(v) > 5 else ''})" for k, v in others.items())
        pc.add(f"{path}.elements", f"{kind} of response {response!r} applies to {wanted}s, not to {found}")
    return None if unknown or others else list(names)


def interaction_maker(name: str, r: dict, path: str, output_id: OutputId, outputs: list[Output],
                      model: Model | None, pc: ProblemCollector) -> Callable[[], Response] | None:
    """``interaction_ratio``: the beam-column interaction u of every named beam at both ends,
    aggregated (KS or sampled maximum) over the beams and the run."""
    check_keys(r, path, allowed("response.interaction_ratio"), pc, required=("yield_stress",))
    n0 = len(pc.problems)
    how, rho = how_and_rho(r, path, pc)
    fy = positive(r["yield_stress"], f"{path}.yield_stress", pc) if "yield_stress" in r else None
    K = positive(r.get("effective_length_factor", 1.0), f"{path}.effective_length_factor", pc)
    phi = positive(r.get("resistance_factor", 1.0), f"{path}.resistance_factor", pc)
    if phi is not None and phi > 1:
        pc.add(f"{path}.resistance_factor", f"expected a factor in (0, 1] (LRFD: 0.9), found {phi}")
    members = members_of_kind(r.get("elements", "all"), "beam", name, "interaction_ratio", path, model, pc)
    if len(pc.problems) > n0 or members is None or fy is None or K is None or phi is None:
        return None
    picked = [output_id({"element": members, "kind": q}, f"{path}.elements") for q in ("buckling", "stress")]
    if any(o is None for o in picked):
        return None
    term = member_form_term([(o, outputs[o]) for o in picked if o is not None], members,
                            interaction_forms(K, fy, phi))
    return lambda: FormAggregate(name, term, how, str(r.get("unit", "-")), rho=rho)


def member_columns(labels: list[tuple[str, ...]], members: list[str]) -> np.ndarray:
    """Columns (n_m, 6) of each member's (b_y, b_z, σ₁⁺, σ₁⁻, σ₂⁺, σ₂⁻) among the labels of a
    buckling and a stress output placed side by side (a plane beam's one b taken twice)."""
    owner = [lab.split(".", 1)[0] for labs in labels for lab in labs]
    cols = []
    for m in members:
        mine = [i for i, o in enumerate(owner) if o == m]
        b, s = mine[:-4], mine[-4:]
        cols.append([b[0], b[-1], *s])
    out = np.array(cols, dtype=int).reshape(-1, MEMBER_COMPONENTS)
    return out


def member_form_term(outs: list[tuple[int, Output]], members: list[str], forms: np.ndarray) -> FormTerm:
    """The :class:`FormTerm` of ``forms`` (F, 6) on every member, reading the buckling and
    stress outputs ``outs`` ((id, output), (id, output))."""
    columns = member_columns([o.labels for _, o in outs], members)
    parts = tuple((oid, np.arange(len(o.labels))) for oid, o in outs)
    return FormTerm(parts, columns, np.broadcast_to(forms, (len(members),) + forms.shape).copy())
