"""Read and validate a case: every problem is collected with its YAML path, then raised once.

Top-level keys (see docs/case-files.md and docs/case-reference.md): ``name``, ``description``,
``design``, ``model``, ``integrator``, ``sensitivity``, ``output``, ``events``,
``responses``.
"""
from __future__ import annotations

import copy
import json
import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
import yaml

from ..errors import CaseError, Problem, ProblemCollector
from ..expressions.restricted import RESERVED_NAMES
from ..integrators.newmark import SCHEMES, Newmark, make_scheme
from ..timeloop.march import HISTORY_FIELDS, RunPlan, adjoint_obstacles
from ..case_keys import allowed
from ..models._keys import check_keys, did_you_mean
from ..models.base import Model, Output
from ..models.parameters import ParameterTable
from ..models.registry import build_model
from ..timeloop.records import QuantitySpec, Recorder
from ..responses.response_set import ResponseSet
from ..derivatives.partials import METHODS
from .derivative_keys import adjoint_problems, derivative_settings
from .step_keys import adaptive_settings
from ..solver.newton import NewtonSettings
from .checks import (bounds_problem, check_reference_types, check_start, reserved_message,
                     unused_design_variables)
from .families import design_with_families, fold_assigned_problems
from .optimization import OptimizationSpec, validate_optimization
from .overrides import apply_overrides
from .quantities import parse_quantities
from .responses_spec import read_events, read_number, read_responses
from .yamltext import parse_yaml, read_case_text

TOP_KEYS = allowed("case")
_DESIGN_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\[[A-Za-z0-9_]+\])?$")   # A or a family member A[diag7]


@dataclass(frozen=True)
class DesignVariable:
    """A design variable: name, initial value, bounds and scale (units of the case); ``unit``
    names that unit in summaries and plots."""

    name: str
    value: float
    lower: float
    upper: float
    scale: float
    unit: str = ""


@dataclass
class Case:
    """A validated case, ready to run."""

    source: str
    text: str
    name: str
    description: str
    design: list[DesignVariable]
    model: Model
    scheme: Newmark
    plan: RunPlan
    overrides: tuple[str, ...]
    _make_responses: Callable[[bool], ResponseSet]
    response_names: tuple[str, ...]
    event_names: tuple[str, ...]
    optimization: OptimizationSpec | None = None
    quantities: tuple[QuantitySpec, ...] = ()
    parameters: ParameterTable | None = None
    unused_design: tuple[str, ...] = ()

    @property
    def design_names(self) -> tuple[str, ...]:
        """Names of the design variables, in order."""
        return tuple(v.name for v in self.design)

    @property
    def design_units(self) -> tuple[str, ...]:
        """Units of the design variables (empty where the case names none)."""
        return tuple(v.unit for v in self.design)

    @property
    def response_units(self) -> dict[str, str]:
        """Unit of every response, by name."""
        return {r.name: r.unit for r in self._make_responses(False).responses}

    @property
    def x0(self) -> np.ndarray:
        """Initial design (m,)."""
        return np.array([v.value for v in self.design], dtype=float)

    @property
    def lower(self) -> np.ndarray:
        """Lower bounds (m,)."""
        return np.array([v.lower for v in self.design], dtype=float)

    @property
    def upper(self) -> np.ndarray:
        """Upper bounds (m,)."""
        return np.array([v.upper for v in self.design], dtype=float)

    @property
    def scale(self) -> np.ndarray:
        """Typical magnitudes of the design variables (m,)."""
        return np.array([v.scale for v in self.design], dtype=float)

    def new_response_set(self, record: bool = True) -> ResponseSet:
        """Fresh accumulators for one run (``record``: keep the recorded quantities)."""
        return self._make_responses(record)


def load_case(path: str | Path, overrides: list[str] | tuple[str, ...] = ()) -> Case:
    """Load, override and validate the case file at ``path``.

    Raises CaseError naming the file for a missing file, invalid YAML or any invalid entry.
    """
    path = Path(path)
    src = str(path)
    return load_case_text(read_case_text(path, src), src, overrides)


def load_case_text(text: str, source: str = "<string>", overrides: list[str] | tuple[str, ...] = ()) -> Case:
    """Validate a case given as YAML text (safe loading; duplicate keys, alias bombs and deep
    nesting are refused with their key paths)."""
    raw = parse_yaml(text, source)
    if not isinstance(raw, dict):
        raise CaseError(f"expected a mapping at the top level, found {type(raw).__name__}", source)
    return load_case_dict(raw, source, overrides, text=text)


def load_case_dict(raw: dict, source: str = "<dict>", overrides: list[str] | tuple[str, ...] = (),
                   text: str | None = None) -> Case:
    """Validate a case given as a mapping (as scripts build them)."""
    raw = _plain(copy.deepcopy(raw))
    if overrides:
        apply_overrides(raw, list(overrides), source)
        text = None
    if text is None:
        text = yaml.safe_dump(raw, sort_keys=False)
    if "load_cases" in raw:   # one transient per load case: `load_cases.load_case_set` splits them
        raise CaseError([Problem("load_cases", "expected a single-load-case case here, found named load "
                                 "cases: load them with dynsens.case.load_cases.load_case_set (the "
                                 "simulate, optimize and check-gradients commands run them; this "
                                 "command does not yet; see docs/load_cases.md)")], source)
    pc = ProblemCollector(source)
    check_keys(raw, "", TOP_KEYS, pc, required=("model", "integrator"))
    pc.problems = [type(p)(p.path.lstrip("."), p.message) for p in pc.problems]
    # a list or mapping where a name belongs would reach the builders' look-ups: stop here
    n_before = len(pc.problems)
    check_reference_types(raw, "", pc)
    if len(pc.problems) > n_before:
        pc.raise_if_any()
    # families of per-element variables expand into design variables and element keys first
    design, declared, assigned = design_with_families(raw, pc, _design)
    n_expanded = len(pc.problems)     # later problems at assigned keys are the families'
    # expressions may name every declared variable, even one whose entry has a problem
    # (that problem is reported once, not again at every use)
    table = ParameterTable(declared)
    table.nominal = {d.name: d.value for d in design}   # the initial design (redundant joints are found there)
    model = build_model(raw.get("model"), "model", table, pc)
    scheme, plan, event_location = _integrator(raw.get("integrator", {}), raw.get("sensitivity", {}),
                                               raw.get("output", {}), pc)
    outputs: list[Output] = []
    keys: list[str] = []

    def output_id(spec: Any, path: str) -> int | None:
        if model is None:  # the model's own problems are already listed
            return None
        key = json.dumps(spec, sort_keys=True, default=str)
        if key in keys:
            return keys.index(key)
        out = model.output(spec, path, pc)
        if out is None:
            return None
        outputs.append(out)
        keys.append(key)
        return len(outputs) - 1

    events, event_names = read_events(raw.get("events", []) or [], output_id, outputs, event_location, pc)
    factory, rnames = read_responses(raw.get("responses", []) or [], output_id, outputs, event_names,
                                 declared, model, plan, pc)
    output_spec = raw.get("output")
    quantities = parse_quantities(output_spec.get("quantities") if isinstance(output_spec, dict) else None,
                                  output_id, outputs, pc)
    optimization = validate_optimization(raw.get("optimization"), rnames, pc)
    if not pc.problems and model is not None and plan is not None:
        check_start(design, table, model, scheme, plan, pc)
    if plan is not None and not pc.problems:
        probe = ResponseSet(outputs, factory(), events, recorder=Recorder(quantities) if quantities else None)
        adjoint_problems(plan.method, adjoint_obstacles(plan, probe), pc)
    fold_assigned_problems(pc, assigned, n_expanded)
    pc.raise_if_any()
    assert model is not None and scheme is not None and plan is not None
    ev = events
    unused = unused_design_variables(table, raw.get("responses", []) or [])
    if unused:
        warnings.warn(f"{source}: design variable{'s' if len(unused) > 1 else ''} {', '.join(unused)} "
                      "used by no element, load, initial condition or response: "
                      f"{'their gradients are' if len(unused) > 1 else 'its gradient is'} zero by construction",
                      stacklevel=2)
    return Case(source=source, text=text, name=_case_name(raw.get("name"), source),
                description=str(raw.get("description", "")), design=design, model=model,
                scheme=scheme, plan=plan, overrides=tuple(overrides),
                _make_responses=lambda record: ResponseSet(
                    outputs, factory(), ev, recorder=Recorder(quantities) if record and quantities else None,
                    stack_parameters=model.stack_parameters),
                response_names=rnames, event_names=tuple(e.name for e in events),
                optimization=optimization, quantities=quantities, parameters=table, unused_design=unused)


def _case_name(name: Any, source: str) -> str:
    """The case's ``name:``; without one, or with one left empty (``name:`` is null, ``""`` or
    blanks), its file's stem (docs/commands.md), never ``None`` or ``case``."""
    if name is None or (isinstance(name, str) and not name.strip()):
        return Path(source).stem
    return str(name)


def _plain(node: Any) -> Any:
    """The mapping with numpy scalars and arrays turned into plain Python (scripts build cases
    with numpy; the case text stored with the results must be plain YAML)."""
    if isinstance(node, dict):
        return {k: _plain(v) for k, v in node.items()}
    if isinstance(node, (list, tuple)):
        return [_plain(v) for v in node]
    if isinstance(node, np.ndarray):
        return _plain(node.tolist())
    if isinstance(node, np.generic):
        return node.item()
    return node


def _design(spec: Any, pc: ProblemCollector) -> tuple[list[DesignVariable], tuple[str, ...]]:
    if not check_keys(spec, "design", allowed("design"), pc):
        return [], ()
    out = []
    declared: list[str] = []
    variables = spec.get("variables", []) or []
    if not isinstance(variables, list):
        pc.add("design.variables", f"expected a list of variables, found {type(variables).__name__} "
                                   f"{variables!r}")
        return [], ()
    for i, v in enumerate(variables):
        p = f"design.variables[{i}]"
        if not check_keys(v, p, allowed("design.variable"), pc, required=("name", "value")):
            continue
        name = v.get("name")
        if not isinstance(name, str) or not _DESIGN_NAME.match(name):
            pc.add(f"{p}.name", f"expected an identifier (letters, digits, _), found {name!r}")
            continue
        if name in declared:
            pc.add(f"{p}.name", f"duplicate design variable {name!r}")
        if name in RESERVED_NAMES:
            pc.add(f"{p}.name", reserved_message(name))
            continue
        declared.append(name)
        value = read_number(v.get("value"), f"{p}.value", pc)
        lower = read_number(v.get("lower", -np.inf), f"{p}.lower", pc) if "lower" in v else -np.inf
        upper = read_number(v.get("upper", np.inf), f"{p}.upper", pc) if "upper" in v else np.inf
        scale = read_number(v.get("scale", 1.0), f"{p}.scale", pc, positive=True) if "scale" in v else None
        if value is None or lower is None or upper is None:
            continue
        why = bounds_problem(lower, upper)
        if why:
            pc.add(p, why)
            continue
        if not lower <= value <= upper:
            pc.add(f"{p}.value", f"{value} is outside the bounds [{lower}, {upper}]")
        if scale is None:
            scale = abs(value) if value != 0 else 1.0
        unit = v.get("unit", "")
        if not isinstance(unit, str):
            pc.add(f"{p}.unit", f"expected text such as 'mm', found {unit!r}")
            unit = ""
        out.append(DesignVariable(name, value, lower, upper, scale, unit))
    return out, tuple(declared)


def _integrator(spec: Any, sens: Any, output: Any, pc: ProblemCollector
                ) -> tuple[Newmark | None, RunPlan | None, str]:
    """(scheme, run plan, event location) from the ``integrator``, ``sensitivity`` and ``output``
    sections; the plan is None after a problem (reported to ``pc``)."""
    ok = check_keys(spec, "integrator", allowed("integrator"), pc, required=("dt", "t_end"))
    if sens is None:
        sens = {}
    ok &= check_keys(sens, "sensitivity", allowed("sensitivity"), pc)
    if output is None:
        output = {}
    ok &= check_keys(output, "output", allowed("output"), pc)
    if not ok:
        return None, None, "interpolate"
    # None: not given (the scheme's own value; a scheme refuses parameters it does not use)
    beta, gamma = _optional_number(spec, "beta", pc), _optional_number(spec, "gamma", pc)
    # a missing dt / t_end is already reported by check_keys
    dt = _optional_number(spec, "dt", pc, positive=True)
    t0 = read_number(spec.get("t0", 0.0), "integrator.t0", pc)
    t_end = _optional_number(spec, "t_end", pc)
    scheme = _scheme(spec, beta, gamma, pc)
    newton = _newton(spec.get("solver", {}) or {}, pc)
    if t0 is not None and t_end is not None and t_end <= t0:
        pc.add("integrator.t_end", f"must be greater than t0 = {t0}, found {t_end}")
    elif t0 is not None and t_end is not None and dt is not None and dt > t_end - t0:
        pc.add("integrator.dt", f"expected at most t_end - t0 = {t_end - t0:g} s (a run of at least one full "
                                f"step), found {dt:g} s")
    sensitivity = _sensitivity_plan(sens, pc)
    history = _history_plan(output, pc)
    cuts = spec.get("max_step_cuts", 6)
    if isinstance(cuts, bool) or not isinstance(cuts, int) or not 0 <= cuts <= 30:
        pc.add("integrator.max_step_cuts", f"expected an integer in [0, 30], found {cuts!r}")
        cuts = 6
    loc = spec.get("event_location", "interpolate")
    if loc not in ("interpolate", "step"):
        pc.add("integrator.event_location", f"expected interpolate or step, found {loc!r}")
    derivative = derivative_settings(sens, pc)
    adaptive = adaptive_settings(spec.get("adaptive"), dt, t0, t_end, scheme, pc)
    if None in (dt, t0, t_end) or pc.problems:
        return scheme, None, str(loc)
    assert t0 is not None and t_end is not None and dt is not None  # checked above
    plan = RunPlan(t0=t0, t_end=t_end, dt=dt, newton=newton, max_step_cuts=cuts, adaptive=adaptive,
                   **sensitivity, **history, **derivative)
    return scheme, plan, str(loc)


def _optional_number(spec: dict, key: str, pc: ProblemCollector, *, positive: bool = False) -> float | None:
    """``integrator.KEY`` read as a number, or None when it is not given (or not one: reported)."""
    return read_number(spec[key], f"integrator.{key}", pc, positive=positive) if key in spec else None


def _scheme(spec: dict, beta: float | None, gamma: float | None, pc: ProblemCollector) -> Newmark | None:
    """The time-integration scheme ``integrator.scheme`` with its parameters, or None after a problem."""
    scheme_name = spec.get("scheme", "newmark")
    if scheme_name not in SCHEMES:
        pc.add("integrator.scheme", f"unknown scheme {scheme_name!r}{did_you_mean(scheme_name, SCHEMES)} "
                                    f"(known: {', '.join(SCHEMES)})")
        return None
    if (beta is None and "beta" in spec) or (gamma is None and "gamma" in spec):
        return None                                     # an unreadable beta or gamma: already reported
    try:
        alpha = _optional_number(spec, "alpha", pc)
        rho = _optional_number(spec, "rho_inf", pc)
        return make_scheme(str(scheme_name), beta, gamma, alpha=alpha, rho_inf=rho)
    except ValueError as exc:
        pc.add("integrator", str(exc))
        return None


def _newton(solver: Any, pc: ProblemCollector) -> NewtonSettings:
    """The Newton–Raphson tolerances ``integrator.solver`` (the defaults after a problem)."""
    newton = NewtonSettings()
    if not check_keys(solver, "integrator.solver", allowed("integrator.solver"), pc):
        return newton
    rtol = read_number(solver.get("rtol", newton.rtol), "integrator.solver.rtol", pc, positive=True)
    atol = read_number(solver.get("atol", newton.atol), "integrator.solver.atol", pc, nonnegative=True)
    mi = solver.get("max_iterations", newton.max_iterations)
    if isinstance(mi, bool) or not isinstance(mi, int) or mi < 1:   # YAML true is no count
        pc.add("integrator.solver.max_iterations", f"expected a positive integer, found {mi!r}")
        mi = newton.max_iterations
    if rtol is not None and atol is not None:
        newton = NewtonSettings(rtol, atol, mi)
    return newton


def _sensitivity_plan(sens: dict, pc: ProblemCollector) -> dict[str, Any]:
    """The run plan's fields from the ``sensitivity`` section: whether, and how the partials are made."""
    enabled = sens.get("enabled", True)
    if not isinstance(enabled, bool):
        pc.add("sensitivity.enabled", f"expected true or false, found {enabled!r}")
    partials = sens.get("partials", "forward")
    if partials not in METHODS:
        pc.add("sensitivity.partials", f"expected one of {', '.join(METHODS)}, found {partials!r}"
                                       f"{did_you_mean(partials, METHODS)}")
    step = sens.get("step")
    if step is not None:
        step = read_number(step, "sensitivity.step", pc, positive=True)
    matrix = sens.get("matrix", "reuse")
    if matrix not in ("converged", "reuse"):
        pc.add("sensitivity.matrix", f"expected converged or reuse, found {matrix!r}")
    return dict(sensitivities=bool(enabled), partials=str(partials), partials_step=step,
                sensitivity_matrix=str(matrix))


def _history_plan(output: dict, pc: ProblemCollector) -> dict[str, Any]:
    """The run plan's fields from the ``output`` section: the state and sensitivity histories kept."""
    hist = output.get("history", ["q", "qd", "qdd"])
    if hist in (None, "none", False):
        hist = []
    if hist == "all":
        hist = list(HISTORY_FIELDS)
    if not isinstance(hist, list) or any(h not in HISTORY_FIELDS for h in hist):
        pc.add("output.history", f"expected a list from {list(HISTORY_FIELDS)}, 'all' or 'none', found {hist!r}")
        hist = []
    sh = output.get("sensitivity_history", False)
    if not isinstance(sh, bool):
        pc.add("output.sensitivity_history", f"expected true or false, found {sh!r}")
    return dict(history=tuple(hist), sensitivity_history=bool(sh))
