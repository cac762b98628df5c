"""The Python API: simulate, optimize and check gradients from a script or a notebook.

Each function takes a case as a loaded `Case`, a path to a YAML file or a
mapping (as a script builds it), plus overrides by key path, exactly like ``--set`` on the
command line::

    import dynsens
    sim = dynsens.simulate("cases/sdof_step.yaml", **{"integrator.t_end": 2.0})
    sim.values["q_end"], sim.gradients["q_end"]      # value (m) and d/d[m, c, k]

Keyword names may also use ``__`` for the dots (``integrator__t_end=2.0``).
"""
from __future__ import annotations

import copy
import json
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence, Union

import numpy as np
import yaml
from scipy.optimize import OptimizeResult as _ScipyResult

from .case.load import Case, load_case, load_case_dict
from .derivatives.gradcheck import GradientReport
from .derivatives.gradcheck import check_gradients as _check_gradients
from .timeloop.march import RunResult
from .optimize.verified import optimize_verified as _optimize_verified
from .optimize.store import read_history as _read_history
from .responses.base import ResponseValue
from .simulation import run_case
from .timeloop.stepping import HISTORY_FIELDS

CaseLike = Union[Case, str, Path, Mapping[str, Any]]

__all__ = ["CaseLike", "OptimizeResult", "Simulation", "as_case", "check_gradients", "optimize", "simulate"]


def _override_strings(overrides: Mapping[str, Any]) -> list[str]:
    """``{"integrator.dt": 5e-4}`` -> ``["integrator.dt=0.0005"]`` (values as YAML/JSON)."""
    out = []
    for key, value in overrides.items():
        if isinstance(value, np.ndarray):
            value = value.tolist()
        elif isinstance(value, np.generic):
            value = value.item()
        out.append(f"{key.replace('__', '.')}={json.dumps(value)}")
    return out


def _history_fields(history: Any) -> tuple[str, ...] | None:
    """``history`` as a tuple of state-history names, or ValueError naming what was found."""
    if history is None:
        return None
    expected = f"expected a sequence of names from {list(HISTORY_FIELDS)} (e.g. ('q', 'qd'); () for none)"
    if isinstance(history, (str, bytes)) or not isinstance(history, (list, tuple, set, frozenset)):
        raise ValueError(f"history: {expected}, found {history!r}")
    unknown = [h for h in history if h not in HISTORY_FIELDS]
    if unknown:
        raise ValueError(f"history: {expected}, found unknown {', '.join(map(repr, unknown))}")
    return tuple(history)


def _count(name: str, value: Any, minimum: int) -> int | None:
    """``value`` as an optional whole number >= ``minimum`` (maxiter, starts, ...), else ValueError."""
    if value is None:
        return None
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name}: expected a whole number >= {minimum} or None, found {value!r}")
    return int(value)


def _is_finite_number(v: Any) -> bool:
    """Whether ``v`` is a real finite number (not a bool, a string or NaN)."""
    return (not isinstance(v, (bool, np.bool_)) and isinstance(v, (int, float, np.number))
            and bool(np.isfinite(v)))


def _finite_numbers(name: str, values: Any, positive: bool = False) -> list[float]:
    """``values`` as a list of finite numbers (> 0 with ``positive``), else ValueError naming them."""
    what = f"a sequence of finite numbers{' > 0' if positive else ''}"
    if isinstance(values, (str, bytes, Mapping)) or not isinstance(values, (list, tuple, np.ndarray)):
        raise ValueError(f"{name}: expected {what}, found {values!r}")
    bad = [v for v in values if not _is_finite_number(v) or (positive and v <= 0)]
    if bad or not len(values):
        raise ValueError(f"{name}: expected {what}, found {values!r}")
    return [float(v) for v in values]


def _flag(name: str, value: Any) -> bool | None:
    """``value`` as an optional flag: None, True or False (a string such as "no" is no flag)."""
    if value is None or isinstance(value, (bool, np.bool_)):
        return None if value is None else bool(value)
    raise ValueError(f"{name}: expected True, False or None, found {value!r}")


def _default_workers(workers: int | None) -> int | None:
    """``workers`` as given; when left to its default in a plain script (``python script.py``,
    whose ``__main__`` the ``spawn`` workers re-import, so an unguarded call would start
    processes while importing), one worker.  Pass ``workers`` explicitly (under an
    ``if __name__ == "__main__":`` guard) for parallel runs from a script."""
    import sys
    main = sys.modules.get("__main__")
    plain_script = main is not None and getattr(main, "__spec__", None) is None \
        and hasattr(main, "__file__")
    return 1 if workers is None and plain_script else workers


def as_case(case: CaseLike, overrides: Mapping[str, Any] | None = None) -> Case:
    """A validated `Case` from a case, a YAML path or a mapping, with ``overrides`` applied.

    Raises `CaseError` (file, key path, expected, found) for bad input.
    """
    sets = _override_strings(overrides or {})
    if isinstance(case, Case):
        if not sets:
            return case
        return load_case_dict(yaml.safe_load(case.text), case.source, sets)
    if isinstance(case, (str, Path)):
        return load_case(case, sets)
    if isinstance(case, Mapping):
        return load_case_dict(dict(case), "<dict>", sets)
    raise TypeError(f"expected a Case, a path or a mapping, found {type(case).__name__}")


def as_any_case(case: Any, overrides: Mapping[str, Any] | None = None) -> Any:
    """As `as_case`, but a case with named ``load_cases`` (a path, a mapping or a
    `~dynsens.case.load_cases.LoadCaseSet`) gives its `LoadCaseSet`, for `optimize`."""
    from .case.load_cases import LoadCaseSet, apply_overrides, has_load_cases, load_case_set, load_case_set_file
    sets = _override_strings(overrides or {})
    if isinstance(case, LoadCaseSet):
        if not sets:
            return case
        case = yaml.safe_load(case.text)
    if isinstance(case, (str, Path)) and has_load_cases(case):
        return load_case_set_file(case, sets)
    if isinstance(case, Mapping) and "load_cases" in case:
        raw = copy.deepcopy(dict(case))
        if sets:
            apply_overrides(raw, sets, "<dict>")
        return load_case_set(raw, "<dict>")
    return as_case(case, overrides)


@dataclass
class Simulation:
    """One simulation of a case: responses with gradients, histories and run statistics.

    Attributes
    ----------
    case
        The validated case that ran (overrides applied).
    x
        Design (m,), in the case's units; ``design_names`` names its entries.
    time
        (N,) time points of the stored histories (s, or the case's time unit).
    history
        State histories by field (``q``, ``qd``, ``qdd``, ``lam``, ``p``, ``pd``), each (N, n);
        ``labels[field]`` names their columns.
    responses
        Name -> `ResponseValue` (value, gradient, unit, missing).
    values, gradients, units
        The same as plain dicts (a missing response has value NaN).
    monitors
        Per-step diagnostics, e.g. constraint drift of mechanisms.
    counters
        Steps, Newton iterations, factorizations, solves, ...
    wall_time
        Seconds of this run (numba compilation excluded once the cache is warm).
    status, message
        ``completed`` / ``terminated`` and why.
    run
        The raw run record.
    """

    case: Case
    run: RunResult

    @property
    def x(self) -> np.ndarray:
        return np.real(self.run.x)

    @property
    def design_names(self) -> tuple[str, ...]:
        return self.case.design_names

    @property
    def time(self) -> np.ndarray:
        return self.run.time

    @property
    def history(self) -> dict[str, np.ndarray]:
        return self.run.history

    @property
    def labels(self) -> dict[str, list[str]]:
        return self.run.labels

    @property
    def monitors(self) -> dict[str, np.ndarray]:
        return self.run.monitors

    @property
    def responses(self) -> dict[str, ResponseValue]:
        return self.run.responses

    @property
    def values(self) -> dict[str, float]:
        return {n: (np.nan if r.missing else float(np.real(r.value))) for n, r in self.responses.items()}

    @property
    def gradients(self) -> dict[str, np.ndarray]:
        m = len(self.design_names)
        return {n: (np.full(m, np.nan) if r.gradient is None else np.real(np.asarray(r.gradient)))
                for n, r in self.responses.items()}

    @property
    def units(self) -> dict[str, str]:
        return {n: r.unit for n, r in self.responses.items()}

    @property
    def counters(self) -> dict[str, int]:
        return self.run.counters

    @property
    def wall_time(self) -> float:
        return self.run.wall_time

    @property
    def status(self) -> str:
        return self.run.status

    @property
    def message(self) -> str:
        return self.run.message

    def save(self, path: str | Path, *, overwrite: bool = False) -> Path:
        """Write the HDF5 result file (the layout of ``dynsens simulate``); returns its path."""
        from .io.hdf5 import write_result
        write_result(str(path), self.run, self.case, overwrite=overwrite)
        return Path(path)

    def __repr__(self) -> str:
        vals = ", ".join(f"{n}={v:.6g}" for n, v in self.values.items())
        return f"<Simulation {self.case.name}: {self.status}; {vals}>"


def simulate(case: CaseLike, x: Sequence[float] | np.ndarray | None = None, *,
             sensitivities: bool | None = None, history: Sequence[str] | None = None,
             **overrides: Any) -> Simulation:
    """Simulate ``case`` at design ``x`` (default: the case's initial design).

    Parameters
    ----------
    case
        A `Case`, a path to a case file or a mapping.
    x
        Design values (m,) in the case's units, in the order of ``design.variables``.
    sensitivities
        Override ``sensitivity.enabled`` (False: primal run only, no gradients).
    history
        Which state histories to keep (``("q", "qd")``, ``()`` for none).
    **overrides
        Case entries by key path, as ``--set`` (``**{"integrator.dt": 5e-4}``
        or ``integrator__dt=5e-4``).

    Returns
    -------
    Simulation
        Responses (``values``, ``gradients``, ``units``), histories and run statistics.
    """
    fields, flag = _history_fields(history), _flag("sensitivities", sensitivities)   # before any work
    c = as_case(case, overrides)
    xx = None if x is None else np.asarray(x)
    if xx is not None and xx.shape != (len(c.design_names),):
        raise ValueError(f"x: expected {len(c.design_names)} values for {list(c.design_names)}, "
                         f"found shape {xx.shape}")
    run = run_case(c, xx, sensitivities=flag, history=fields)
    return Simulation(c, run)


class OptimizeResult(_ScipyResult):
    """Result of `optimize`, with scipy's names (a dict with attribute access).

    ``x`` (optimum, case units), ``fun`` (objective there, its unit), ``jac`` (∂f/∂x there,
    objective unit per design unit), ``nit`` (the optimizer's iterations), ``nfev`` (simulations),
    ``success``, ``status`` (the optimizer's exit code), ``message``; and ``feasible``,
    ``max_violation`` (scaled), ``constraints`` (name -> value of the constrained response),
    ``design_names``, ``starts`` (one dict per start), ``history`` (the best start's
    per-iteration arrays), ``path`` (the OPT.h5 file, None when run in memory), ``verification``
    (the optimum's verification, None when not run) and ``verified`` (whether it passed).
    """


def optimize(case: CaseLike, output: str | Path | None = None, *, x0: Mapping[str, float] | None = None,
             starts: int | None = None, seed: int | None = None, maxiter: int | None = None,
             ftol: float | None = None, workers: int | None = None, scheduler: str | None = None,
             overwrite: bool = False, resume: bool = False, verify: bool | None = None,
             **overrides: Any) -> OptimizeResult:
    """Minimize the case's objective subject to its constraints (the case's optimization.method,
    SLSQP by default; exact gradients).

    Parameters
    ----------
    case
        A case with an ``optimization`` section (Case, path or mapping); a case with named
        ``load_cases`` optimizes over them (``RESPONSE@CASE``, docs/load_cases.md).
    output
        OPT.h5 to write as ``dynsens optimize -o`` does; None runs in memory (the file is
        kept in a temporary directory for the run and removed afterwards).
    x0
        Start values by design-variable name, replacing the case's initial design.
    starts, seed, maxiter, ftol, workers, scheduler, overwrite, resume
        As the command's options.
    verify
        Run the optimum again at a refined step and on a longer window (default: the
        case's ``optimization.verification.enabled``, on); the result's ``verification`` holds
        `Verification` (None when not run), ``verified`` its verdict.
    **overrides
        Case entries by key path, as ``--set``.

    Returns
    -------
    OptimizeResult
        scipy's names for the best start; see `OptimizeResult`.
    """
    if ftol is not None and not (isinstance(ftol, (int, float)) and not isinstance(ftol, bool)
                                 and np.isfinite(ftol) and ftol > 0):
        raise ValueError(f"ftol: expected a finite number > 0, found {ftol!r}")
    if resume and output is None:
        raise ValueError("resume=True continues the run recorded in an output file: give output")
    maxiter, starts, seed = _count("maxiter", maxiter, 1), _count("starts", starts, 1), _count("seed", seed, 0)
    workers = _count("workers", workers, 1)
    if x0 is not None:
        if not isinstance(x0, Mapping):
            raise ValueError(f"x0: expected a mapping of design-variable names to start values, found {x0!r}")
        bad = {k: v for k, v in x0.items() if not _is_finite_number(v)}
        if bad:
            raise ValueError(f"x0: expected a finite start value for each design variable, found {bad}")
    c = as_any_case(case, overrides)
    tmp = tempfile.TemporaryDirectory(prefix="dynsens-opt-") if output is None else None
    path = Path(tmp.name if tmp is not None else ".") / "opt.h5" if output is None else Path(output)
    try:
        res, verification = _optimize_verified(c, path, verify=verify, starts=starts, seed=seed, x0=x0,
                                               maxiter=maxiter, ftol=ftol, workers=_default_workers(workers),
                                               scheduler=scheduler, resume=resume, overwrite=overwrite)
        best = res.best_outcome
        hist = _read_history(path, best.index)
    finally:
        if tmp is not None:
            tmp.cleanup()
    problem = res.problem
    jac = np.full(len(c.design_names), np.nan)
    if len(hist.get("x", ())):
        # the recorded iterate at the optimum: ∂f_s/∂u -> ∂f/∂x (f = f_s·f_ref, x = lower + u·dx/du)
        gap = np.max(np.abs(hist["x"] - best.x) / problem.dx_du, axis=1)
        k = int(np.argmin(gap))
        if gap[k] <= 1e-12 and np.all(np.isfinite(hist["grad_f"][k])):
            jac = hist["grad_f"][k] * problem.f_ref / problem.dx_du
    constrained = {t.response for t in problem.constraints}
    resp = dict(zip(problem.response_names, np.asarray(best.responses, dtype=float)))
    return OptimizeResult(
        x=np.asarray(best.x, dtype=float), fun=float(best.f), jac=jac, nit=int(best.nit),
        nfev=int(best.n_sim), success=bool(best.success), status=int(best.status), message=str(best.message),
        feasible=bool(best.feasible), max_violation=float(best.max_violation),
        constraints={n: float(resp[n]) for n in problem.response_names if n in constrained},
        design_names=c.design_names,
        starts=[{"x_start": o.x_start, "x": o.x, "fun": o.f, "success": o.success, "feasible": o.feasible,
                 "nit": o.nit, "nfev": o.n_sim, "message": o.message} for o in res.starts],
        history=hist, path=None if tmp is not None else path, verification=verification,
        verified=None if verification is None else verification.passed)


def check_gradients(case: CaseLike, steps: Sequence[float] = (1e-3, 1e-4, 1e-5, 1e-6), scheme: str = "forward",
                    *, x: Sequence[float] | np.ndarray | None = None, workers: int | None = None,
                    **overrides: Any) -> GradientReport:
    """The semi-analytical gradient beside finite differences of the whole simulation.

    ``steps`` are relative (Δx_j = h·|x_j|, or h·scale_j at x_j = 0); ``scheme`` is ``forward``,
    ``central`` or ``complex``.  The report holds ``semi_analytical`` and ``columns`` (one per
    step, with ``gradients`` and ``rel_diff``); ``report.passes(rtol)`` is the command's exit test
    and `to_markdown` its table.
    """
    steps = _finite_numbers("steps", steps, positive=True)
    c = as_case(case, overrides)
    return _check_gradients(c, steps, scheme, x=None if x is None else np.asarray(x, dtype=float),
                            workers=_default_workers(workers))
