"""Reading the ``events`` and ``responses`` sections of a case (and the plain numbers every
section reads): each entry checked against the key table, problems collected with their key
paths, responses returned as makers so that each run gets fresh accumulators."""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ..case_keys import RESPONSE_TYPES, allowed
from ..errors import ProblemCollector
from ..expressions.restricted import RESERVED_NAMES, ExpressionError, compile_expression
from ..timeloop.march import RunPlan
from ..models._keys import check_keys, did_you_mean
from ..models.parameters import finite_float, number_text
from ..models.base import Model, Output
from ..responses.base import EventSpec, EventTime, ExpressionIntegral, Response, TimeIntegral, ValueAt
from ..responses.final import Combination, StructuralMass
from ..responses.types import load_response_types, response_type_names
from .aggregates import AGGREGATE_TYPES, aggregate_maker
from .checks import reserved_message
from .member_checks import beam_names, interaction_maker
from .quantities import component_index, missing_component

_IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def read_number(value: Any, path: str, pc: ProblemCollector, *, positive: bool = False,
                nonnegative: bool = False) -> float | None:
    """A plain finite number (or a constant expression such as '1/3') found at ``path``; with
    ``positive`` it must be > 0, with ``nonnegative`` >= 0."""
    if isinstance(value, str):
        try:
            value = compile_expression(value, set()).evaluate({})
        except ExpressionError:
            pc.add(path, f"expected a number or a constant expression such as '1/3', found {value!r}")
            return None
    elif isinstance(value, bool) or not isinstance(value, (int, float)):
        found = "nothing" if value is None else f"{type(value).__name__} {value!r}"
        pc.add(path, f"expected a number, found {found}")
        return None
    v = finite_float(value)
    if v is None or (positive and v <= 0) or (nonnegative and v < 0):
        what = "positive " if positive else "non-negative " if nonnegative else ""
        pc.add(path, f"expected a {what}finite number, found {number_text(value)}")
        return None
    return v


def quantity_component(out: Output, comp: Any, path: str, pc: ProblemCollector) -> int | None:
    if comp is None:
        if len(out.labels) != 1:
            pc.add(path, f"the quantity has {len(out.labels)} components {list(out.labels)}: name one with 'component'")
            return None
        return 0
    i = component_index(out.labels, comp)
    if i is None:
        pc.add(path, missing_component(out.labels, comp))
    return i


def quantity_and_component(r: dict, p: str, ctx: "ResponseContext") -> tuple[int, int] | None:
    """The output id and component index that the entry ``r`` (at key path ``p``) names with its
    ``quantity`` and ``component`` keys; None (problems recorded) when either is wrong."""
    oid = ctx.output_id(r.get("quantity"), f"{p}.quantity")
    if oid is None:
        return None
    comp = quantity_component(ctx.outputs[oid], r.get("component"), f"{p}.component", ctx.pc)
    if comp is None:
        return None
    return oid, comp


def read_events(spec: Any, output_id: Callable, outputs: list[Output], default_loc: str,
            pc: ProblemCollector) -> tuple[list[EventSpec], list[str]]:
    if not isinstance(spec, list):
        pc.add("events", "expected a list")
        return [], []
    events = []
    names: list[str] = []
    for i, ev in enumerate(spec):
        p = f"events[{i}]"
        if not check_keys(ev, p, allowed("event"),
                          pc, required=("name", "quantity", "value")):
            continue
        ename = ev.get("name")
        if not isinstance(ename, str) or not _IDENT.match(ename):
            pc.add(f"{p}.name", f"expected an identifier (letters, digits, _), found {ename!r}")
        elif ename in names:
            pc.add(f"{p}.name", f"expected each event name once, found {ename!r} again "
                                f"(events[{names.index(ename)}] has it)")
        names.append(str(ename))
        oid = output_id(ev.get("quantity"), f"{p}.quantity")
        level = read_number(ev.get("value"), f"{p}.value", pc)
        direction = ev.get("direction", "either")
        if direction not in ("rising", "falling", "either"):
            pc.add(f"{p}.direction", f"expected rising, falling or either, found {direction!r}")
        if ev.get("action", "terminate") != "terminate":
            pc.add(f"{p}.action", f"only 'terminate' is supported, found {ev.get('action')!r}")
        loc = ev.get("location", default_loc)
        if loc not in ("interpolate", "step"):
            pc.add(f"{p}.location", f"expected interpolate or step, found {loc!r}")
        if oid is None or level is None:
            continue
        comp = quantity_component(outputs[oid], ev.get("component"), f"{p}.component", pc)
        if comp is not None:
            events.append(EventSpec(str(ename), oid, comp, level, direction, loc))
    return events, names


# an integral reads one quantity's component, or an expression of several quantities
_INTEGRAL_OF_QUANTITY = tuple(k for k in allowed("response.integral") if k not in ("expression", "symbols"))
_INTEGRAL_OF_EXPRESSION = tuple(k for k in allowed("response.integral") if k not in ("quantity", "component"))


def _expression_integral(r: dict, p: str, name: str, unit: str, output_id: Callable, outputs: list[Output],
                         pc: ProblemCollector) -> Callable[[], Response] | None:
    """``{type: integral, expression: "x**2 + 0.1*F**2", symbols: {x: {quantity, component}, ...}}``."""
    check_keys(r, p, _INTEGRAL_OF_EXPRESSION, pc, required=("symbols",))
    syms = r.get("symbols")
    if not isinstance(syms, dict) or not syms:
        pc.add(f"{p}.symbols", "expected a mapping symbol -> {quantity: ..., component: ...}")
        return None
    table: list[tuple[str, int, int]] = []
    for sname, sspec in syms.items():
        sp = f"{p}.symbols.{sname}"
        if not isinstance(sname, str) or not _IDENT.match(sname) or \
                not check_keys(sspec, sp, ("quantity", "component"), pc, required=("quantity",)):
            if not isinstance(sname, str) or not _IDENT.match(sname):
                pc.add(sp, f"expected an identifier as the symbol, found {sname!r}")
            continue
        oid = output_id(sspec.get("quantity"), f"{sp}.quantity")
        comp = None if oid is None else quantity_component(outputs[oid], sspec.get("component"), f"{sp}.component", pc)
        if comp is not None:
            table.append((sname, oid, comp))   # type: ignore[arg-type]
    try:
        expr = compile_expression(str(r.get("expression")), set(syms))
    except ExpressionError as exc:
        pc.add(f"{p}.expression", f"{exc} (an integrand names its symbols)")
        return None
    if len(table) != len(syms):
        return None
    symbols = list(table)

    def make() -> Response:
        return ExpressionIntegral(name, expr, symbols, unit)
    return make


def _modal(r: dict, p: str, name: str, kind: str, unit: str, model: Model | None, plan: RunPlan | None,
           design_names: tuple[str, ...], pc: ProblemCollector) -> Callable[[], Response] | None:
    """``type: frequency`` / ``type: buckling_factor`` (:mod:`dynsens.analysis.modal_responses`)."""
    from ..analysis.modal_responses import ModalResponse, ModelSubject
    from ..models.structural.model import StructuralModel
    check_keys(r, p, allowed(f"response.{kind}"), pc)
    n0 = len(pc.problems)
    count = r.get("modes", 1)
    if not isinstance(count, int) or isinstance(count, bool) or count < 1:
        pc.add(f"{p}.modes", f"expected an integer >= 1, found {count!r}")
    rho = read_number(r["rho"], f"{p}.rho", pc, positive=True) if r.get("rho") is not None else None
    if isinstance(count, int) and count > 1 and r.get("rho") is None:
        pc.add(f"{p}.rho", f"required with modes: {count} (the KS minimum's parameter)")
    load_time = read_number(r["load_time"], f"{p}.load_time", pc) if r.get("load_time") is not None else None
    if model is not None and not isinstance(model, StructuralModel):
        pc.add(f"{p}.type", f"a {kind} response needs a structural model, found {type(model).__name__}")
    if len(pc.problems) > n0 or model is None or plan is None:
        return None
    default_unit = "Hz" if kind == "frequency" else "-"

    def make() -> Response:
        # the response analyses the design the run is at; the scales only size the matrices'
        # complex steps of a variable that is zero there
        m = len(design_names)
        subject = ModelSubject(model, f"response {name!r}", plan, np.zeros(m), np.ones(m))
        return ModalResponse(name, kind, int(count), rho, subject, design_names, unit or default_unit, load_time)
    return make


@dataclass
class ResponseContext:
    """What every response reader needs besides its entry: the loader's outputs, the events, the
    design and the model, the problems, and the names read so far (this response's last)."""

    output_id: Callable
    outputs: list[Output]
    event_names: list[str]
    design_names: tuple[str, ...]
    model: Model | None
    plan: RunPlan | None
    pc: ProblemCollector
    names: list[str]


Maker = Callable[[], Response]


def _value(r: dict, p: str, name: str, unit: str, ctx: ResponseContext) -> Maker | None:
    """``type: value``: a quantity's component at the end, at a time or at an event."""
    pc, plan = ctx.pc, ctx.plan
    check_keys(r, p, allowed("response.value"), pc, required=("quantity",))
    oid = ctx.output_id(r.get("quantity"), f"{p}.quantity")
    deriv = r.get("derivative", "total")
    if deriv not in ("total", "fixed_time"):
        pc.add(f"{p}.derivative", f"expected total or fixed_time, found {deriv!r}")
    time = read_number(r["time"], f"{p}.time", pc) if "time" in r else None
    if time is not None and plan is not None and not plan.t0 <= time <= plan.t_end:
        pc.add(f"{p}.time", f"{time} is outside the simulated interval [{plan.t0}, {plan.t_end}] s")
    event = r.get("event")
    if event is not None and event not in ctx.event_names:
        pc.add(f"{p}.event", f"unknown event {event!r}{did_you_mean(event, ctx.event_names)}")
    at = r.get("at", "end")
    if at != "end":
        pc.add(f"{p}.at", f"expected 'end' (use 'time: T' or 'event: NAME' otherwise), found {at!r}")
    if oid is None:
        return None
    comp = quantity_component(ctx.outputs[oid], r.get("component"), f"{p}.component", pc)
    if comp is None:
        return None
    u = unit or ctx.outputs[oid].unit
    return lambda: ValueAt(name, oid, comp, u, time=time, event=event, fixed_time=(deriv == "fixed_time"))


def _aggregate(r: dict, p: str, name: str, unit: str, ctx: ResponseContext) -> Maker | None:
    """The aggregates over time and components (:mod:`.aggregates`)."""
    return aggregate_maker(name, str(r.get("type")), r, p, ctx.output_id, ctx.outputs, ctx.pc,
                           beams=beam_names(ctx.model))


def _interaction(r: dict, p: str, name: str, unit: str, ctx: ResponseContext) -> Maker | None:
    """``type: interaction_ratio``: the beam-column check (:mod:`.member_checks`)."""
    return interaction_maker(name, r, p, ctx.output_id, ctx.outputs, ctx.model, ctx.pc)


def _integral(r: dict, p: str, name: str, unit: str, ctx: ResponseContext) -> Maker | None:
    """``type: integral`` of a quantity's component, or of an expression of quantities."""
    if "expression" in r:
        return _expression_integral(r, p, name, unit, ctx.output_id, ctx.outputs, ctx.pc)
    check_keys(r, p, _INTEGRAL_OF_QUANTITY, ctx.pc, required=("quantity",))
    found = quantity_and_component(r, p, ctx)
    if found is None:
        return None
    oid, comp = found
    u = unit or f"{ctx.outputs[oid].unit}*s"
    return lambda: TimeIntegral(name, oid, comp, u)


def _event_time(r: dict, p: str, name: str, unit: str, ctx: ResponseContext) -> Maker | None:
    """``type: event_time`` / ``end_time``."""
    kind = r.get("type")
    check_keys(r, p, allowed(f"response.{kind}"), ctx.pc, required=("event",) if kind == "event_time" else ())
    event = r.get("event")
    if kind == "event_time" and event not in ctx.event_names:
        ctx.pc.add(f"{p}.event", f"unknown event {event!r}{did_you_mean(event, ctx.event_names)}")
    return lambda: EventTime(name, event)


def _mass(r: dict, p: str, name: str, unit: str, ctx: ResponseContext) -> Maker | None:
    """``type: mass``: the model's structural mass."""
    check_keys(r, p, allowed("response.mass"), ctx.pc)
    if ctx.model is not None and type(ctx.model).structural_mass is Model.structural_mass:
        ctx.pc.add(f"{p}.type", f"model type {type(ctx.model).__name__} defines no structural mass")
    return lambda: StructuralMass(name, unit or "mass")


def _modal_entry(r: dict, p: str, name: str, unit: str, ctx: ResponseContext) -> Maker | None:
    """``type: frequency`` / ``buckling_factor``."""
    return _modal(r, p, name, str(r.get("type")), unit, ctx.model, ctx.plan, ctx.design_names, ctx.pc)


def _expression(r: dict, p: str, name: str, unit: str, ctx: ResponseContext) -> Maker | None:
    """``type: expression`` of earlier responses and design variables."""
    check_keys(r, p, allowed("response.expression"), ctx.pc, required=("expression",))
    try:
        expr = compile_expression(str(r.get("expression")), set(ctx.names[:-1]) | set(ctx.design_names))
    except ExpressionError as exc:
        ctx.pc.add(f"{p}.expression", f"{exc} (an expression may use earlier responses and design variables)")
        return None
    design_names = ctx.design_names
    return lambda: Combination(name, expr, unit, design_names)


#: the readers of the types whose sections are in :mod:`dynsens.case_keys.general`, registered in
#: :mod:`dynsens.responses.types.builtin` (in the order of ``RESPONSE_TYPES``)
READERS: dict[str, Callable[[dict, str, str, str, ResponseContext], "Maker | None"]] = {
    "value": _value, **{k: _aggregate for k in AGGREGATE_TYPES}, "interaction_ratio": _interaction,
    "integral": _integral, "event_time": _event_time, "end_time": _event_time, "mass": _mass,
    "frequency": _modal_entry, "buckling_factor": _modal_entry, "expression": _expression,
}
assert tuple(READERS) == RESPONSE_TYPES


def _name_and_unit(r: dict, p: str, ctx: ResponseContext) -> tuple[str, str] | None:
    """The response's name (registered in ``ctx.names``) and unit, or None (no usable name)."""
    pc, names, name = ctx.pc, ctx.names, r.get("name")
    if not isinstance(name, str) or not _IDENT.match(name):
        pc.add(f"{p}.name", f"expected an identifier, found {name!r}")
        return None
    if name in names or name in ctx.design_names:
        pc.add(f"{p}.name", f"{name!r} is already a response or design variable name")
    elif name in RESERVED_NAMES:
        pc.add(f"{p}.name", reserved_message(name))
    # register the name first: a later expression using it must not report it again
    names.append(name)
    unit = r.get("unit", "")
    if not isinstance(unit, str):
        pc.add(f"{p}.unit", f"expected text such as 'N' or 'm*s' (quote a number: '1'), found {unit!r}")
        unit = ""
    return name, unit


def read_responses(spec: Any, output_id: Callable, outputs: list[Output], event_names: list[str],
               design_names: tuple[str, ...], model: Model | None, plan: RunPlan | None,
               pc: ProblemCollector) -> tuple[Callable[[], list[Response]], tuple[str, ...]]:
    """The ``responses`` section: a factory of fresh responses and their names (problems in ``pc``)."""
    if not isinstance(spec, list):
        pc.add("responses", "expected a list")
        spec = []
    registry = load_response_types()
    known = response_type_names()
    makers: list[Maker] = []
    ctx = ResponseContext(output_id, outputs, event_names, design_names, model, plan, pc, [])
    for i, r in enumerate(spec):
        p = f"responses[{i}]"
        if not isinstance(r, dict):
            pc.add(p, f"expected a mapping, found {r!r}")
            continue
        named = _name_and_unit(r, p, ctx)
        if named is None:
            continue
        kind = r.get("type")
        rtype = registry.get(kind) if isinstance(kind, str) else None
        if rtype is None:
            pc.add(f"{p}.type", f"unknown response type {kind!r}{did_you_mean(kind, known)} "
                                f"(known: {', '.join(known)})")
            continue
        maker = rtype.read(r, p, named[0], named[1], ctx)
        if maker is not None:
            makers.append(maker)
    return (lambda: [mk() for mk in makers]), tuple(ctx.names)
