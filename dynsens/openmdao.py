"""dynsens as an OpenMDAO component: a case's design variables in, its responses out.

One simulation per design point serves the values (``compute``) and the partials
(``compute_partials``): the run computes the responses' gradients with the case's own
derivative mode (``sensitivity.method``: direct, adjoint or auto), and the component keeps them
for the same inputs.  The partials are declared dense: a response of a dynamic run depends, in
general, on every design variable through the whole trajectory.

Units: a design variable's or response's unit becomes the OpenMDAO unit where OpenMDAO knows it
(``mm``, ``t``, ``MPa`` ...); otherwise the variable has no OpenMDAO unit and the case's unit is
in its description.  OpenMDAO forbids ``. * ? ! [ ]`` in names: a family member ``A[3]`` is the
variable ``A_3``; `input_names` maps the case's names to the component's.

Install with ``pip install 'dynsens[openmdao]'``.
"""
from __future__ import annotations

import re
from typing import Any, Mapping

import numpy as np

try:
    import openmdao.api as om
    from openmdao.utils.units import valid_units
except ImportError as exc:  # pragma: no cover - exercised by monkeypatching the import
    raise ImportError("dynsens.openmdao needs OpenMDAO: pip install 'dynsens[openmdao]'") from exc

from .api import as_case
from .case.load import Case
from .optimize.problem import simulate

__all__ = ["CaseComponent", "add_case_driver_variables", "openmdao_name"]


def openmdao_name(name: str) -> str:
    """A case name as an OpenMDAO variable name (``A[3]`` -> ``A_3``)."""
    return re.sub(r"_+$", "", re.sub(r"[.*?!\[\]]", "_", name)) or "_"


def _om_units(unit: str) -> str | None:
    """``unit`` when OpenMDAO knows it, else None (dimensionless or unknown)."""
    if not unit:
        return None
    try:
        return unit if valid_units(unit) else None
    except Exception:   # OpenMDAO evaluates the string; anything it cannot parse is unknown
        return None


class CaseComponent(om.ExplicitComponent):
    """An ``ExplicitComponent`` that simulates a dynsens case.

    Options
    -------
    case : a `Case`, a path to a case file or a mapping.
    overrides : overrides by key path, as ``--set`` (``{"integrator.t_end": 0.02}``).
    responses : the responses to output (default: the optimization section's objective and
        constraints, or every response of a case without one).

    Attributes
    ----------
    n_simulations
        Simulations run so far (one per distinct design point).
    counters
        Run statistics of the last simulation (steps, solves, backward solves, ...).
    input_names, output_names
        Case name -> component variable name.
    """

    def initialize(self) -> None:
        self.options.declare("case", desc="dynsens case: Case, path or mapping")
        self.options.declare("overrides", default=None, allow_none=True, types=dict,
                             desc="overrides by key path, as --set")
        self.options.declare("responses", default=None, allow_none=True, types=(list, tuple),
                             desc="responses to output (default: objective and constraints)")
        self.n_simulations = 0
        self.counters: dict[str, int] = {}
        self._cache: tuple[bytes, dict[str, float], dict[str, np.ndarray]] | None = None

    @property
    def case(self) -> Case:
        """The validated case (overrides applied), loaded once."""
        if getattr(self, "_case", None) is None:
            self._case = as_case(self.options["case"], self.options["overrides"])
        return self._case

    def _response_list(self) -> list[str]:
        case = self.case
        chosen = self.options["responses"]
        if chosen is None:
            spec = case.optimization
            chosen = list(case.response_names) if spec is None else \
                list(dict.fromkeys([spec.objective] + [c.response for c in spec.constraints]))
        unknown = [r for r in chosen if r not in case.response_names]
        if unknown:
            raise ValueError(f"{case.source}: responses {unknown} are not in the case "
                             f"(responses: {', '.join(case.response_names)})")
        return list(chosen)

    def setup(self) -> None:
        case = self.case
        self.input_names = {n: openmdao_name(n) for n in case.design_names}
        self.output_names = {n: openmdao_name(n) for n in self._response_list()}
        for mapping, kind in ((self.input_names, "design variables"), (self.output_names, "responses")):
            if len(set(mapping.values())) != len(mapping):
                raise ValueError(f"{case.source}: {kind} collide once made OpenMDAO names: {mapping}")
        for j, (name, var) in enumerate(self.input_names.items()):
            unit = case.design_units[j]
            self.add_input(var, val=case.x0[j], units=_om_units(unit),
                           desc=f"{name} [{unit}] in [{case.lower[j]:g}, {case.upper[j]:g}]")
        units = case.response_units
        for name, var in self.output_names.items():
            self.add_output(var, val=0.0, units=_om_units(units[name]), desc=f"{name} [{units[name]}]")
        # dense: every response of a transient run depends on every design variable
        self.declare_partials(list(self.output_names.values()), list(self.input_names.values()))

    def _design(self, inputs: Any) -> np.ndarray:
        return np.array([float(inputs[v][0]) for v in self.input_names.values()])

    def _evaluate(self, x: np.ndarray) -> tuple[dict[str, float], dict[str, np.ndarray]]:
        """Values and gradients at ``x``: from the cache, or from one simulation."""
        key = x.tobytes()
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1], self._cache[2]
        res, message, _ = simulate(self.case, x)
        self.n_simulations += 1
        if res is None:
            raise om.AnalysisError(f"{self.case.source} at {dict(zip(self.case.design_names, x))}: {message}")
        self.counters = dict(res.counters)
        values, grads = {}, {}
        for name in self.output_names:
            r = res.responses[name]
            if r.missing or r.gradient is None:
                raise om.AnalysisError(f"{self.case.source}: response '{name}' has no value or gradient "
                                       f"({r.missing or 'sensitivities disabled'})")
            values[name] = float(np.real(r.value))
            grads[name] = np.real(np.asarray(r.gradient, dtype=complex))
        self._cache = (key, values, grads)
        return values, grads

    def compute(self, inputs: Any, outputs: Any) -> None:
        values, _ = self._evaluate(self._design(inputs))
        for name, var in self.output_names.items():
            outputs[var] = values[name]

    def compute_partials(self, inputs: Any, partials: Any) -> None:
        _, grads = self._evaluate(self._design(inputs))
        for name, var in self.output_names.items():
            for j, xv in enumerate(self.input_names.values()):
                partials[var, xv] = grads[name][j]


def add_case_driver_variables(group: Any, path: str, component: CaseComponent, *,
                              objective: bool = True, ref: Mapping[str, float] | None = None) -> None:
    """Add ``component``'s design variables (with the case's bounds), its case's objective and
    constraints to ``group`` (usually ``problem.model``; call before ``problem.setup()``).

    Parameters
    ----------
    path
        The component's path in ``group`` (e.g. ``"truss"``).
    objective
        Add the optimization section's objective (False for a second load case whose
        constraints only count).
    ref
        Response name -> reference value (its unit) that scales the objective; default 1.

    Scaling follows ``dynsens optimize``: a bounded design variable maps to [0, 1], an unbounded
    one to x/scale; a constraint bound b ≠ 0 divides its response by |b|.
    """
    case = component.case
    spec = case.optimization
    if spec is None:
        raise ValueError(f"{case.source} has no 'optimization' section")
    for j, name in enumerate(case.design_names):
        lo, up = case.lower[j], case.upper[j]
        bounded = np.isfinite(lo) and np.isfinite(up)
        group.add_design_var(f"{path}.{openmdao_name(name)}",
                             lower=lo if np.isfinite(lo) else None, upper=up if np.isfinite(up) else None,
                             ref0=lo if bounded else 0.0, ref=up if bounded else case.scale[j])
    if objective:
        group.add_objective(f"{path}.{openmdao_name(spec.objective)}", ref=(ref or {}).get(spec.objective, 1.0))
    for c in spec.constraints:
        bound = c.upper if c.upper is not None else c.lower
        scale = abs(float(bound)) if bound else 1.0
        target = f"{path}.{openmdao_name(c.response)}"
        if c.lower is not None and c.upper is not None and c.lower == c.upper:
            group.add_constraint(target, equals=c.upper, ref=scale)
        else:
            group.add_constraint(target, lower=c.lower, upper=c.upper, ref=scale)

