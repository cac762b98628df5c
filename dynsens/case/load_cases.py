"""Named load cases: several transients of one model, each under its own loads, initial state
and time window (the scenarios of TACS / OpenMDAO).

A case declares them in a top-level mapping ``load_cases``, name -> {key path: value}; each
entry is the base case with those overrides applied (the ``--set`` mechanism), restricted to
the keys that define a load case::

    load_cases:
      impact: {model.loads[0].value: 40.0, integrator.t_end: 0.5}
      gust:   {model.loads[0].value: 10.0, model.initial.velocity: {u: 0.1}}

Responses are named ``<response>@<load case>``; a constraint over all load cases is their
maximum or Kreisselmeier-Steinhauser envelope (`aggregate_over_cases`), whose gradient follows
from each load case's own (adjoint or direct) gradient by the chain rule.
"""
from __future__ import annotations

import copy
import json
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..errors import CaseError, Problem, ProblemCollector
from .load import Case, load_case_dict
from .optimization import OptimizationSpec, validate_optimization
from .overrides import apply_overrides
from .yamltext import parse_yaml, read_case_text

#: key paths a load case may override (a prefix followed by '.', '[' or the end)
OVERRIDABLE = ("model.loads", "model.forces", "model.initial", "integrator.t_end", "integrator.dt")
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
SEPARATOR = "@"


def _overridable(key: str) -> bool:
    return any(key == p or key.startswith(p + ".") or key.startswith(p + "[") for p in OVERRIDABLE)


def split_load_cases(raw: dict, source: str = "<dict>") -> tuple[dict, dict[str, list[str]]]:
    """The base mapping (without ``load_cases``) and each load case's ``--set`` strings.

    Raises CaseError (file, key path, expected, found) for a malformed ``load_cases`` block.
    """
    base = copy.deepcopy(raw)
    spec = base.pop("load_cases", None)
    if spec is None:
        return base, {}
    problems: list[Problem] = []
    if not isinstance(spec, dict) or not spec:
        raise CaseError([Problem("load_cases", "expected a non-empty mapping name -> {key path: value}, "
                                               f"found {json.dumps(spec, default=str)}")], source)
    cases: dict[str, list[str]] = {}
    for name, entry in spec.items():
        path = f"load_cases.{name}"
        if not isinstance(name, str) or not _NAME.match(name):
            problems.append(Problem(path, f"expected a name of letters, digits and '_', found {name!r}"))
            continue
        if not isinstance(entry, dict):
            problems.append(Problem(path, "expected a mapping {key path: value}, "
                                          f"found {type(entry).__name__}"))
            continue
        sets = []
        for key, value in entry.items():
            if not isinstance(key, str) or not _overridable(key):
                problems.append(Problem(f"{path}.{key}", "expected a key path under "
                                        f"{', '.join(OVERRIDABLE)}, found {key!r} (not overridable "
                                        "by a load case)"))
                continue
            sets.append(f"{key}={json.dumps(value)}")
        cases[name] = sets
    if problems:
        raise CaseError(problems, source)
    return base, cases


#: a constraint on ``RESPONSE@all`` bounds the response in every load case (one constraint each)
ALL = "all"


@dataclass
class LoadCaseSet:
    """The load cases of one case: name -> validated `Case` (the same design variables).

    For `dynsens optimize` it stands in for a `Case`: the design (bounds, scale, units) of its
    load cases, the responses ``RESPONSE@LOADCASE`` and the validated ``optimization``.
    """

    source: str
    cases: dict[str, Case]
    text: str = ""     #: the whole case (with its ``load_cases``) as YAML, for the file header
    optimization: OptimizationSpec | None = None   #: objective and constraints on ``RESPONSE@LOADCASE``
    #: where `run` sends the load cases (an `dynsens.executor.Executor`; None: one after the other)
    executor: Any = field(default=None, repr=False, compare=False)

    @property
    def first(self) -> Case:
        """The first load case (its design is every load case's)."""
        return next(iter(self.cases.values()))

    @property
    def name(self) -> str:
        """The case's name (as the first load case's)."""
        return self.first.name

    @property
    def design(self) -> list:
        """The design variables (the same in every load case)."""
        return self.first.design

    design_names = property(lambda self: self.first.design_names, doc="Names of the design variables.")
    design_units = property(lambda self: self.first.design_units, doc="Units of the design variables.")
    lower = property(lambda self: self.first.lower, doc="Lower bounds (m,).")
    upper = property(lambda self: self.first.upper, doc="Upper bounds (m,).")
    scale = property(lambda self: self.first.scale, doc="Typical magnitudes of the design variables (m,).")
    x0 = property(lambda self: self.first.x0, doc="Initial design (m,).")

    @property
    def response_names(self) -> tuple[str, ...]:
        """All per-load-case responses, ``<response>@<load case>``."""
        return tuple(f"{r}{SEPARATOR}{n}" for n, c in self.cases.items() for r in c.response_names)

    @property
    def response_units(self) -> dict[str, str]:
        """Unit of every ``<response>@<load case>``."""
        return {f"{r}{SEPARATOR}{n}": u for n, c in self.cases.items() for r, u in c.response_units.items()}

    def case(self, name: str) -> Case:
        """The load case ``name``; CaseError naming the known ones otherwise."""
        if name not in self.cases:
            raise CaseError([Problem("load_cases", f"expected one of {', '.join(self.cases)}, "
                                                   f"found unknown load case {name!r}")], self.source)
        return self.cases[name]

    def run(self, x: np.ndarray, executor: Any = None) -> "LoadCaseRun":
        """Every load case at design ``x`` with sensitivities (for the optimizer), on ``executor``
        (default: the set's own)."""
        executor = executor or self.executor
        from ..executor import SerialExecutor, remember_case
        for case in self.cases.values():
            remember_case(case)
        args = [(c.text, c.source, np.asarray(x, dtype=float), True) for c in self.cases.values()]
        runs = (executor or SerialExecutor()).map(_load_case_responses, args)
        return LoadCaseRun({f"{r}{SEPARATOR}{n}": v for n, rs in zip(self.cases, runs) for r, v in rs.items()})


@dataclass
class LoadCaseRun:
    """The responses of every load case at one design, keyed ``<response>@<load case>``."""

    responses: dict[str, Any]


def _load_case_responses(arg: tuple[str, str, np.ndarray, bool]) -> dict[str, Any]:
    """Executor task: one load case (travelling as its YAML text) at one design: its responses
    (values, gradients when ``sensitivities``)."""
    from ..executor import cached_case
    from ..simulation import run_case
    text, source, x, sensitivities = arg
    return dict(run_case(cached_case(text, source), x, sensitivities=sensitivities, history=()).responses)


def _optimization(spec: Any, cases: dict[str, Case], source: str) -> OptimizationSpec | None:
    """The ``optimization`` section over load cases: the objective names ``RESPONSE@LOADCASE``;
    a constraint on ``RESPONSE@all`` becomes one constraint per load case."""
    if spec is None:
        return None
    names = tuple(f"{r}{SEPARATOR}{n}" for n, c in cases.items() for r in c.response_names)
    over_all = {f"{r}{SEPARATOR}{ALL}" for c in cases.values() for r in c.response_names}
    pc = ProblemCollector(source)
    opt = validate_optimization(spec, names + tuple(sorted(over_all)), pc)
    if opt is not None and opt.objective in over_all:
        pc.add("optimization.objective", f"expected one load case's response (RESPONSE@LOADCASE, one of "
                                         f"{', '.join(names)}), found {opt.objective!r} (all load cases: "
                                         "a constraint only)")
    pc.raise_if_any()
    assert opt is not None
    constraints = []
    for c in opt.constraints:
        response, _, at = c.response.rpartition(SEPARATOR)
        constraints += ([replace(c, response=f"{response}{SEPARATOR}{n}") for n in cases] if at == ALL else [c])
    return replace(opt, constraints=tuple(constraints))


def load_case_set(raw: dict, source: str = "<dict>") -> LoadCaseSet:
    """Validate every load case of ``raw`` (each the base case with its overrides applied).

    A case without ``load_cases`` gives a single load case named after the case.
    """
    base, sets = split_load_cases(raw, source)
    if not sets:
        case = load_case_dict(base, source)
        return LoadCaseSet(source, {case.name: case})
    # the optimization names responses over load cases (`q_ks@impact`): read by `LoadCaseSet`, not per load case
    optimization = base.pop("optimization", None)
    cases = {}
    for name, overrides in sets.items():
        try:
            cases[name] = load_case_dict(base, f"{source} (load case {name})", overrides)
        except CaseError as exc:   # name the load case's key path in every problem
            raise CaseError([Problem(f"load_cases.{name}: {p.path}", p.message) for p in exc.problems],
                            source) from None
    first = next(iter(cases.values()))
    for name, c in cases.items():
        if [d.name for d in c.design] != [d.name for d in first.design]:
            raise CaseError([Problem(f"load_cases.{name}", "expected the same design variables in every "
                                     "load case")], source)
    return LoadCaseSet(source, cases, yaml.safe_dump(raw, sort_keys=False), _optimization(optimization, cases, source))


def has_load_cases(path: str | Path) -> bool:
    """Whether the case file at ``path`` declares ``load_cases`` (False for an unreadable file:
    the single-case loader then reports it)."""
    try:
        raw = parse_yaml(read_case_text(Path(path), str(path)), str(path))
    except CaseError:
        return False
    return isinstance(raw, dict) and "load_cases" in raw


def load_any_text(text: str, source: str) -> Any:
    """The case in YAML ``text``: a `LoadCaseSet` when it declares ``load_cases``, else a `Case`."""
    from .load import load_case_text
    raw = parse_yaml(text, source)
    if isinstance(raw, dict) and "load_cases" in raw:
        cases = load_case_set(raw, source)
        cases.text = text
        return cases
    return load_case_text(text, source)


def load_any_case(path: str | Path, overrides: list[str] | tuple[str, ...] = ()) -> Any:
    """The case file at ``path``: a `LoadCaseSet` when it declares ``load_cases``, else a `Case`."""
    from .load import load_case
    return load_case_set_file(path, overrides) if has_load_cases(path) else load_case(path, overrides)


def load_case_set_file(path: str | Path, overrides: list[str] | tuple[str, ...] = ()) -> LoadCaseSet:
    """Load the case file at ``path`` with its load cases; ``--set`` overrides apply to the base
    case (before the load cases' own)."""
    src = str(path)
    text = read_case_text(Path(path), src)
    raw = parse_yaml(text, src)
    if not isinstance(raw, dict):
        raise CaseError(f"expected a mapping at the top level, found {type(raw).__name__}", src)
    if overrides:
        apply_overrides(raw, list(overrides), src)
    cases = load_case_set(raw, src)
    if not overrides:
        cases.text = text
    return cases


def _simulate_load_case(arg: tuple[str, str, bool | None]) -> Any:
    """Executor task: the whole run (histories, responses, gradients) of one load case."""
    from ..executor import cached_case
    from ..simulation import run_case
    text, source, sensitivities = arg
    return run_case(cached_case(text, source), sensitivities=sensitivities)


def simulate_load_cases(cases: LoadCaseSet, *, sensitivities: bool | None = None,
                        executor: Any = None) -> dict[str, Any]:
    """Run every load case at its initial design: name -> its `SimulationResult` (as
    `dynsens.simulation.run_case` of that load case; ``sensitivities`` overrides the case's).

    With an `dynsens.executor.Executor` the load cases run in parallel, with the same numbers.
    """
    from ..executor import SerialExecutor, remember_case
    for case in cases.cases.values():
        remember_case(case)
    args = [(c.text, c.source, sensitivities) for c in cases.cases.values()]
    return dict(zip(cases.cases, (executor or SerialExecutor()).map(_simulate_load_case, args)))


def evaluate_load_cases(cases: LoadCaseSet, x: np.ndarray, *, sensitivities: bool = True,
                        executor: Any = None) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Run every load case at design ``x``; values and gradients keyed ``<response>@<load case>``.

    The load cases are independent transients: with an `dynsens.executor.Executor` they run in
    parallel (local processes or Dask), each with its own adjoint or direct gradient.
    """
    from ..executor import SerialExecutor, remember_case
    args = []
    for case in cases.cases.values():
        remember_case(case)   # the serial path re-uses the loaded case, no re-parse
        args.append((case.text, case.source, x, sensitivities))
    results = (executor or SerialExecutor()).map(_load_case_responses, args)
    values: dict[str, Any] = {}
    grads: dict[str, np.ndarray] = {}
    for name, responses in zip(cases.cases, results):
        for r, v in responses.items():
            values[f"{r}{SEPARATOR}{name}"] = v.value
            if v.gradient is not None:
                grads[f"{r}{SEPARATOR}{name}"] = np.asarray(v.gradient)
    return values, grads


def aggregate_over_cases(values: dict[str, Any], grads: dict[str, np.ndarray], response: str,
                         load_cases: list[str], how: str = "ks", rho: float = 50.0,
                         ) -> tuple[Any, np.ndarray | None]:
    """The maximum or KS envelope of ``response`` over ``load_cases``, and its gradient.

    KS(g) = g_max + ln(sum_i exp(rho (g_i - g_max))) / rho (an upper bound of max g_i, at most
    ln(n)/rho above it). The shift by g_max uses the real part so that a complex-step run
    differentiates through it.
    """
    keys = [f"{response}{SEPARATOR}{c}" for c in load_cases]
    missing = [k for k in keys if k not in values]
    if missing:
        raise KeyError(f"expected responses {', '.join(keys)}, found no {', '.join(missing)}")
    g = np.array([values[k] for k in keys])
    have_grad = all(k in grads for k in keys)
    G = np.array([grads[k] for k in keys]) if have_grad else None
    if how == "max":
        i = int(np.argmax(np.real(g)))
        return g[i], (G[i] if G is not None else None)
    if how != "ks":
        raise ValueError(f"expected how 'ks' or 'max', found {how!r}")
    gmax = np.max(np.real(g))
    w = np.exp(rho * (g - gmax))
    ks = gmax + np.log(np.sum(w)) / rho
    if G is None:
        return ks, None
    return ks, (w / np.sum(w)) @ G
