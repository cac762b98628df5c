"""Compare the semi-analytical gradient with finite differences of the whole simulation.

The layout follows Table 1 of the paper: the direct-differentiation gradient of every
response and its wall time beside the finite-difference gradients for each relative
step h (Δx_j = h·|x_j|), their wall times and relative differences
‖∇_FD − ∇_SA‖ / ‖∇_SA‖.  Finite-difference runs are independent and are spread over
worker processes or a Dask cluster (:mod:`dynsens.executor`).
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np

from ..case.load import Case
from ..executor import Executor, cached_case, make_executor, remember_case
from ..simulation import run_case
from ..timeloop.step_sequence import replaying

SCHEMES = ("forward", "central", "complex")
#: accepted relative steps h per scheme, [smallest, largest): below 1e-15 a real step moves x by
#: a few rounding units (the difference is round-off), below 1e-100 a complex step's imaginary
#: parts can underflow on the way through the run; h >= 1 steps by |x| or more (across zero)
STEP_RANGE = {"forward": (1e-15, 1.0), "central": (1e-15, 1.0), "complex": (1e-100, 1.0)}
log = logging.getLogger(__name__)
DEFAULT_WORKERS = 2


@dataclass
class FDColumn:
    """Finite-difference gradients of all responses for one relative step."""

    step: float
    scheme: str
    gradients: dict[str, np.ndarray]
    wall_time: float          # serial-equivalent: sum of the wall times of the runs it needs (s)
    rel_diff: dict[str, float] = field(default_factory=dict)


@dataclass
class GradientReport:
    """Data of a gradient check; see :func:`to_markdown` and :func:`to_json`."""

    case_name: str
    design_names: tuple[str, ...]
    x: np.ndarray
    responses: tuple[str, ...]
    values: dict[str, float]
    semi_analytical: dict[str, np.ndarray]
    sa_wall_time: float
    primal_wall_time: float
    columns: list[FDColumn]
    missing: dict[str, str]
    fixed_time: tuple[str, ...] = ()
    replayed: bool = False     # the finite-difference runs replayed the accepted adaptive steps

    def best_rel_diff(self, name: str) -> float:
        """Smallest relative difference over the finite-difference columns."""
        vals = [c.rel_diff[name] for c in self.columns if np.isfinite(c.rel_diff.get(name, np.nan))]
        return min(vals) if vals else float("nan")

    def best_step(self, name: str) -> float:
        """The relative step h of the column with the smallest relative difference."""
        cols = [c for c in self.columns if np.isfinite(c.rel_diff.get(name, np.nan))]
        return min(cols, key=lambda c: c.rel_diff[name]).step if cols else float("nan")

    def failing(self, rtol: float) -> list[str]:
        """Responses whose best relative difference exceeds rtol (fixed-time gradients and
        missing responses are not compared: finite differences of the whole run measure the
        total derivative).  Raises ValueError for an rtol that is not a finite number > 0."""
        if isinstance(rtol, bool) or not isinstance(rtol, (int, float, np.floating)) or not 0 < rtol < np.inf:
            raise ValueError(f"rtol: expected a finite number > 0, found {rtol!r}")
        return [n for n in self.responses if n not in self.missing and n not in self.fixed_time
                and not self.best_rel_diff(n) <= rtol]

    def passes(self, rtol: float) -> bool:
        """True when every compared response's best relative difference is within rtol."""
        return not self.failing(rtol)


def _values(case: Case, x: np.ndarray, times: np.ndarray | None = None) -> tuple[dict[str, Any], float]:
    """Response values at x and the run's wall time (s); ``times``: replay these grid times."""
    if times is not None:
        case = replace(case, plan=replaying(case.plan, times))
    t0 = time.perf_counter()
    res = run_case(case, x, sensitivities=False, history=())
    return {k: v.value for k, v in res.responses.items()}, time.perf_counter() - t0


def _values_task(job: tuple[str, str, np.ndarray, np.ndarray | None]) -> tuple[dict[str, Any], float]:
    """One finite-difference run on a worker: (case text, case source, design, grid times to
    replay or None) -> values, wall time."""
    text, source, x, times = job
    return _values(cached_case(text, source), x, times)


def step_problem(step: float, scheme: str) -> str | None:
    """Why the relative step ``step`` is meaningless for ``scheme`` (see STEP_RANGE); None when fine."""
    low, high = STEP_RANGE[scheme]
    if np.isfinite(step) and low <= step < high:
        return None
    return f"expected relative steps in [{low:g}, {high:g}) for the {scheme} scheme, found {step!r}"


def rel_diff(fd: np.ndarray, sa: np.ndarray) -> float:
    """‖fd − sa‖ / ‖sa‖ (absolute difference when ‖sa‖ = 0)."""
    ref = float(np.linalg.norm(sa))
    d = float(np.linalg.norm(np.asarray(fd) - np.asarray(sa)))
    return d / ref if ref > 0 else d


Values = dict[str, Any]
#: per scheme: the number of runs of one derivative (at x + δ, and x − δ for central differences,
#: δ = h·ref along one design variable) and its difference quotient from those runs ((values,
#: wall time) each) and the unperturbed values
_QUOTIENTS: dict[str, tuple[int, Callable[[list[tuple[Values, float]], Values, str, float], Any]]] = {
    "forward": (1, lambda runs, base, n, hj: np.real(runs[0][0][n] - base[n]) / hj),
    "central": (2, lambda runs, base, n, hj: np.real(runs[0][0][n] - runs[1][0][n]) / (2 * hj)),
    "complex": (1, lambda runs, base, n, hj: np.imag(runs[0][0][n]) / hj),
}


def check_gradients(case: Case, steps: list[float], scheme: str = "forward", *,
                    x: np.ndarray | None = None, workers: int | None = None, scheduler: str | None = None,
                    executor: Executor | None = None,
                    progress: Callable[[int, int], None] | None = None) -> GradientReport:
    """Semi-analytical vs finite-difference gradients at design ``x`` (default x0).

    The finite-difference runs go to ``executor`` when given, else to ``workers`` local
    processes (default 2; 1 runs them here) or the Dask ``scheduler`` at that address.
    ``progress(done, total)`` is called after every simulation (the semi-analytical and the
    primal run, then each finite-difference run as it finishes).
    """
    _check_steps(steps, scheme)
    x = case.x0 if x is None else np.asarray(x, dtype=float)
    m = x.size
    from ..warmup import warm_case
    warm_case(case)  # compile first: no reported wall time includes numba compilation
    t0 = time.perf_counter()
    sa_run = run_case(case, x, sensitivities=True, history=())
    sa_time = time.perf_counter() - t0
    n_runs = 2 + len(steps) * m * _QUOTIENTS[scheme][0]
    done = [0]

    def tick(what: str) -> None:
        done[0] += 1
        log.info("gradient check: %s done (%d of %d simulations)", what, done[0], n_runs)
        if progress is not None:
            progress(done[0], n_runs)
    tick(f"semi-analytical run ({sa_time:.2f} s)")
    # adaptive steps: the gradient is that of the procedure along the accepted steps (held fixed
    # as the design varies), so the finite-difference runs replay them
    times = sa_run.time if case.plan.adaptive is not None else None
    names = tuple(sa_run.responses)
    missing = {n: r.missing for n, r in sa_run.responses.items() if r.missing}
    sa = {n: np.real(r.gradient) if r.gradient is not None else np.full(m, np.nan)
          for n, r in sa_run.responses.items()}
    base_vals, primal_time = _values(case, x, times)
    tick(f"primal run ({primal_time:.2f} s)")
    ref = np.where(np.abs(x) > 0, np.abs(x), case.scale)
    jobs = [xj for h in steps for j in range(m) for xj in _fd_designs(x, j, h * ref[j], scheme)]
    remember_case(case)                       # in-process runs reuse the loaded case
    tasks = [(case.text, case.source, xj, times) for xj in jobs]

    def fd_done(k: int) -> None:
        tick(f"finite-difference run {k + 1}")
    if executor is not None:
        outs = executor.map(_values_task, tasks, fd_done)
    else:
        with make_executor(workers, scheduler, tasks=len(tasks), default_workers=DEFAULT_WORKERS) as ex:
            outs = ex.map(_values_task, tasks, fd_done)
    per = _QUOTIENTS[scheme][0]
    columns = []
    for k, h in enumerate(steps):
        runs = outs[k * m * per:(k + 1) * m * per]
        col = _fd_column(h, scheme, [runs[j * per:(j + 1) * per] for j in range(m)], h * ref, names,
                         base_vals, primal_time)
        col.rel_diff = {n: (rel_diff(col.gradients[n], sa[n]) if n not in missing else float("nan")) for n in names}
        columns.append(col)
    fixed = tuple(n for n, r in sa_run.responses.items() if r.kind == "fixed_time")
    return GradientReport(case.name, case.design_names, x, names,
                          {n: float(np.real(sa_run.responses[n].value)) for n in names}, sa, sa_time,
                          primal_time, columns, missing, fixed, times is not None)


def _fd_designs(x: np.ndarray, j: int, hj: float, scheme: str) -> list[np.ndarray]:
    """The designs the ``scheme``'s derivative along variable j with the step hj runs at."""
    dx = np.zeros(x.size, dtype=complex if scheme == "complex" else float)
    dx[j] = (1j if scheme == "complex" else 1.0) * hj
    return [x + dx, x - dx][:_QUOTIENTS[scheme][0]]


def _check_steps(steps: list[float], scheme: str) -> None:
    """ValueError unless ``scheme`` is known and every relative step is meaningful for it."""
    if scheme not in SCHEMES:
        raise ValueError(f"scheme {scheme!r}: expected one of {', '.join(SCHEMES)}")
    for h in steps:
        why = step_problem(h, scheme)
        if why:
            raise ValueError(f"steps: {why}")


def _fd_column(h: float, scheme: str, runs: list[list[tuple[Values, float]]], hs: np.ndarray,
               names: tuple[str, ...], base: Values, primal_time: float) -> FDColumn:
    """The finite-difference gradients for the relative step h from the runs of each design
    variable j (at the absolute steps hs[j]); the wall time is the serial sum of the runs (and
    the primal run a forward difference shares)."""
    quotient = _QUOTIENTS[scheme][1]
    grads = {n: np.zeros(len(runs)) for n in names}
    wall = 0.0 if scheme != "forward" else primal_time
    for j, at_j in enumerate(runs):
        for _, tj in at_j:
            wall += tj
        for n in names:
            grads[n][j] = quotient(at_j, base, n, hs[j])
    return FDColumn(h, scheme, grads, wall)


def _vec(v: np.ndarray) -> str:
    return "[" + ", ".join(f"{a:.6g}" for a in v) + "]"


def to_markdown(rep: GradientReport) -> str:
    """Table-1 layout: rows are the gradients, columns SA and FD per step."""
    head = ["", "semi-analytical"] + [f"{c.scheme} h = {c.step:g}" for c in rep.columns]
    lines = [f"Gradient check of `{rep.case_name}` at x = {_vec(rep.x)} "
             f"({', '.join(rep.design_names)})", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head),
             "| wall time [s] | " + f"{rep.sa_wall_time:.3f}" + "".join(
                 f" | {c.wall_time:.3f}" for c in rep.columns) + " |"]
    for n in rep.responses:
        if n in rep.missing:         # no value, no gradient: said below, not printed as NaN
            lines.append(f"| ∇{n} | missing" + " | –" * len(rep.columns) + " |")
            continue
        lines.append(f"| ∇{n} | {_vec(rep.semi_analytical[n])}" + "".join(
            f" | {_vec(c.gradients[n])}" for c in rep.columns) + " |")
        lines.append(f"| rel. diff. ∇{n} | – " + "".join(
            f" | {c.rel_diff[n]:.2e}" for c in rep.columns) + " |")
    lines += ["", f"Primal-only run: {rep.primal_wall_time:.3f} s; primal + sensitivities: "
                  f"{rep.sa_wall_time:.3f} s (ratio {rep.sa_wall_time / max(rep.primal_wall_time, 1e-12):.2f}). "
                  "Finite-difference wall times are serial-equivalent (sum over the runs each column needs)."]
    for n, why in rep.missing.items():
        lines.append(f"- `{n}` is missing: {why}")
    if rep.replayed:
        lines.append("- Adaptive steps: the finite-difference runs replay the accepted steps of the "
                     "semi-analytical run, whose gradient is exact along that sequence (step sizes held "
                     "fixed as the design varies); runs that chose their own steps would add the "
                     "step-selection effect, of the size of the local error tolerance.")
    for n in rep.fixed_time:
        lines.append(f"- `∇{n}` holds the event time fixed (as the paper's Table 1 does for the stroke); "
                     "finite differences of the whole run move the event, so they measure the total "
                     "derivative and are not expected to agree (not counted by --rtol).")
    return "\n".join(lines) + "\n"


def _null_if_missing(values: dict[str, Any], missing: dict[str, str]) -> dict[str, Any]:
    """``values`` with None (JSON null) for the missing responses (their NaN is no JSON)."""
    return {n: None if n in missing else v for n, v in values.items()}


def to_json(rep: GradientReport) -> dict[str, Any]:
    """Plain JSON-serializable form of the report (a missing response's entries are null)."""
    miss = rep.missing
    return {
        "case": rep.case_name, "design_names": list(rep.design_names), "x": rep.x.tolist(),
        "values": _null_if_missing(rep.values, miss),
        "semi_analytical": _null_if_missing({n: v.tolist() for n, v in rep.semi_analytical.items()}, miss),
        "semi_analytical_wall_time_s": rep.sa_wall_time, "primal_wall_time_s": rep.primal_wall_time,
        "columns": [{"step": c.step, "scheme": c.scheme, "wall_time_s": c.wall_time,
                     "gradients": _null_if_missing({n: v.tolist() for n, v in c.gradients.items()}, miss),
                     "rel_diff": _null_if_missing(c.rel_diff, miss)} for c in rep.columns],
        "missing": rep.missing, "fixed_time": list(rep.fixed_time), "replayed_adaptive_steps": rep.replayed,
    }
