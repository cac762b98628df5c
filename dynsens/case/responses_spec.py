"""Reading the ``events`` and ``responses`` sections of a case (and the plain numbers every
section reads): each entry checked against the key table, problems collected with their key
paths, responses returned as makers so that each run gets fresh accumulators."""
from __future__ import annotations

import re
from typing import Any, Callable

import numpy as np

from ..case_keys import RESPONSE_TYPES, allowed
from ..errors import ProblemCollector
from ..expressions import RESERVED_NAMES, ExpressionError, compile_expression
from ..march import RunPlan
from ..models._keys import check_keys, did_you_mean
from ..models.parameters import finite_float, number_text
from ..models.base import Model, Output
from ..responses import EventSpec, EventTime, ExpressionIntegral, Response, TimeIntegral, ValueAt
from ..responses_final import Combination, StructuralMass
from .aggregates import AGGREGATE_TYPES, aggregate_maker
from .checks import reserved_message
from .quantities import component_index

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


def _component(out: Output, comp: Any, path: str, pc: ProblemCollector) -> int | None:
    if comp is None:
        if len(out.labels) != 1:
            pc.add(path, f"the quantity has {len(out.labels)} components {list(out.labels)}: name one with 'component'")
            return None
        return 0
    i = component_index(out.labels, comp)
    if i is None:
        pc.add(path, f"component {comp!r} not found (components: {list(out.labels)})")
    return i


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
        comp = _component(outputs[oid], ev.get("component"), f"{p}.component", pc)
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
        comp = None if oid is None else _component(outputs[oid], sspec.get("component"), f"{sp}.component", pc)
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
    from ..models.structural import StructuralModel
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


def read_responses(spec: Any, output_id: Callable, outputs: list[Output], event_names: list[str],
               design_names: tuple[str, ...], model: Model | None, plan: RunPlan | None,
               pc: ProblemCollector) -> tuple[Callable[[], list[Response]], tuple[str, ...]]:
    if not isinstance(spec, list):
        pc.add("responses", "expected a list")
        spec = []
    makers: list[Callable[..., Response]] = []  # called without arguments
    names: list[str] = []
    for i, r in enumerate(spec):
        p = f"responses[{i}]"
        if not isinstance(r, dict):
            pc.add(p, f"expected a mapping, found {r!r}")
            continue
        name, kind = r.get("name"), r.get("type")
        if not isinstance(name, str) or not _IDENT.match(name):
            pc.add(f"{p}.name", f"expected an identifier, found {name!r}")
            continue
        if name in names or name in design_names:
            pc.add(f"{p}.name", f"{name!r} is already a response or design variable name")
        elif name in RESERVED_NAMES:
            pc.add(f"{p}.name", reserved_message(name))
        # register the name first: a later expression using it must not report it again
        names.append(name)
        unit = r.get("unit", "")
        if not isinstance(unit, str):
            pc.add(f"{p}.unit", f"expected text such as 'N' or 'm*s' (quote a number: '1'), found {unit!r}")
            unit = ""
        if kind == "value":
            check_keys(r, p, allowed("response.value"), pc,
                       required=("quantity",))
            oid = output_id(r.get("quantity"), f"{p}.quantity")
            deriv = r.get("derivative", "total")
            if deriv not in ("total", "fixed_time"):
                pc.add(f"{p}.derivative", f"expected total or fixed_time, found {deriv!r}")
            time = read_number(r["time"], f"{p}.time", pc) if "time" in r else None
            if time is not None and plan is not None and not plan.t0 <= time <= plan.t_end:
                pc.add(f"{p}.time", f"{time} is outside the simulated interval [{plan.t0}, {plan.t_end}] s")
            event = r.get("event")
            if event is not None and event not in event_names:
                pc.add(f"{p}.event", f"unknown event {event!r}{did_you_mean(event, event_names)}")
            at = r.get("at", "end")
            if at != "end":
                pc.add(f"{p}.at", f"expected 'end' (use 'time: T' or 'event: NAME' otherwise), found {at!r}")
            if oid is None:
                continue
            comp = _component(outputs[oid], r.get("component"), f"{p}.component", pc)
            u = unit or outputs[oid].unit
            makers.append(lambda n=name, o=oid, c=comp, u=u, tm=time, e=event, f=(deriv == "fixed_time"):
                          ValueAt(n, o, c, u, time=tm, event=e, fixed_time=f))
        elif kind in AGGREGATE_TYPES:
            maker = aggregate_maker(name, kind, r, p, output_id, outputs, pc)
            if maker is not None:
                makers.append(maker)
        elif kind == "integral" and "expression" in r:
            made = _expression_integral(r, p, name, unit, output_id, outputs, pc)
            if made is not None:
                makers.append(made)
        elif kind == "integral":
            check_keys(r, p, _INTEGRAL_OF_QUANTITY, pc, required=("quantity",))
            oid = output_id(r.get("quantity"), f"{p}.quantity")
            if oid is None:
                continue
            comp = _component(outputs[oid], r.get("component"), f"{p}.component", pc)
            u = unit or f"{outputs[oid].unit}*s"
            makers.append(lambda n=name, o=oid, c=comp, u=u: TimeIntegral(n, o, c, u))
        elif kind in ("event_time", "end_time"):
            check_keys(r, p, allowed(f"response.{kind}"), pc,
                       required=("event",) if kind == "event_time" else ())
            event = r.get("event")
            if kind == "event_time" and event not in event_names:
                pc.add(f"{p}.event", f"unknown event {event!r}{did_you_mean(event, event_names)}")
            makers.append(lambda n=name, e=event: EventTime(n, e))
        elif kind == "mass":
            check_keys(r, p, allowed("response.mass"), pc)
            if model is not None and type(model).structural_mass is Model.structural_mass:
                pc.add(f"{p}.type", f"model type {type(model).__name__} defines no structural mass")
            makers.append(lambda n=name, u=unit or "mass": StructuralMass(n, u))
        elif kind in ("frequency", "buckling_factor"):
            maker = _modal(r, p, name, kind, unit, model, plan, design_names, pc)
            if maker is not None:
                makers.append(maker)
        elif kind == "expression":
            check_keys(r, p, allowed("response.expression"), pc, required=("expression",))
            try:
                expr = compile_expression(str(r.get("expression")), set(names[:-1]) | set(design_names))
            except ExpressionError as exc:
                pc.add(f"{p}.expression", f"{exc} (an expression may use earlier responses and design variables)")
                continue
            makers.append(lambda n=name, e=expr, u=unit: Combination(n, e, u, design_names))
        else:
            pc.add(f"{p}.type", f"unknown response type {kind!r}{did_you_mean(kind, RESPONSE_TYPES)} "
                                f"(known: {', '.join(RESPONSE_TYPES)})")
    return (lambda: [mk() for mk in makers]), tuple(names)
