"""Work-precision study: error of response values and gradients against wall time.

For a ladder of time steps and a set of gradient methods, every response value and
gradient is compared with a reference: the finest run with complex-step partials,
Richardson-extrapolated with the scheme's order (two finest steps, ratio 2) when the ladder
allows, else the finest run itself.  Methods:

``ddm-forward``, ``ddm-central``, ``ddm-complex``
    direct differentiation with forward / central / complex-step design partials;
``fd-forward``, ``fd-central``
    finite differences of the whole simulation (m + 1 and 2m runs, relative steps 1e-6 and 1e-4);
``cs``
    complex step of the whole simulation (m complex runs).

The runs are independent: they go to an executor (:mod:`dynsens.executor`), by default one
after the other in this process, because the wall times are part of the measurement and
runs sharing cores slow each other.  With ``workers``/``scheduler`` they run in parallel;
compare wall times only between runs made the same way.
"""
from __future__ import annotations

import csv
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

import yaml

from ..case.load import Case, load_case_dict
from ..errors import CaseError, Problem
from ..io.paths import atomic_path, atomic_write_text, safe_stem
from ..executor import cached_case, make_executor, remember_case
from ..simulation import run_case

log = logging.getLogger(__name__)

METHODS = ("ddm-forward", "ddm-central", "ddm-complex", "fd-forward", "fd-central", "cs")
FD_STEPS = {"fd-forward": 1e-6, "fd-central": 1e-4, "cs": 1e-20}


@dataclass
class Row:
    """One (Δt, method) run: values, gradients, wall time and errors per response."""

    dt: float
    method: str
    wall_time: float
    values: dict[str, float]
    gradients: dict[str, np.ndarray]
    value_error: dict[str, float]
    gradient_error: dict[str, float]


def _with(case: Case, overrides: list[str]) -> Case:
    raw = yaml.safe_load(case.text)
    return load_case_dict(raw, case.source, overrides)


def _evaluate(case: Case, method: str) -> tuple[dict[str, float], dict[str, np.ndarray], float]:
    t0 = time.perf_counter()
    if method.startswith("ddm-"):
        c = _with(case, [f"sensitivity.partials={method[4:]}"])
        res = run_case(c, history=())
        vals = {n: float(np.real(r.value)) for n, r in res.responses.items()}
        grads = {n: np.real(np.asarray(r.gradient)) for n, r in res.responses.items()}
        return vals, grads, time.perf_counter() - t0
    x0 = case.x0
    m = x0.size
    h = FD_STEPS[method] * np.where(np.abs(x0) > 0, np.abs(x0), case.scale)
    base = run_case(case, sensitivities=False, history=())
    vals = {n: float(np.real(r.value)) for n, r in base.responses.items()}
    grads = {n: np.zeros(m) for n in vals}
    for j in range(m):
        e = np.eye(m)[j]
        if method == "cs":
            r = run_case(case, x0 + 1j * h[j] * e, history=()).responses
            for n in vals:
                grads[n][j] = np.imag(r[n].value) / h[j]
        elif method == "fd-forward":
            r = run_case(case, x0 + h[j] * e, sensitivities=False, history=()).responses
            for n in vals:
                grads[n][j] = (np.real(r[n].value) - vals[n]) / h[j]
        else:
            rp = run_case(case, x0 + h[j] * e, sensitivities=False, history=()).responses
            rm = run_case(case, x0 - h[j] * e, sensitivities=False, history=()).responses
            for n in vals:
                grads[n][j] = np.real(rp[n].value - rm[n].value) / (2 * h[j])
    return vals, grads, time.perf_counter() - t0


# cost of a method in simulations per design variable (ddm: one run in all; an estimate)
_RUNS = {"fd-forward": 1.0, "fd-central": 2.0, "cs": 1.5}


def _evaluate_task(job: tuple[str, str, float, str]) -> tuple[dict[str, float], dict[str, np.ndarray], float]:
    """One rung of the ladder on a worker: (case text, source, Δt, method) -> values, gradients, wall time."""
    text, source, dt, method = job
    return _evaluate(_with(cached_case(text, source), [f"integrator.dt={dt}"]), method)


def work_precision(case: Case, dts: list[float], methods: list[str], *, workers: int | None = None,
                   scheduler: str | None = None,
                   progress: Callable[[float, float, str], None] | None = None
                   ) -> tuple[list[Row], dict, dict]:
    """Run the ladder; returns the rows and the reference values and gradients.

    ``workers`` local processes (default 1: in this process, so that wall times are not
    shared) or the Dask ``scheduler`` at that address run the (Δt, method) pairs.
    ``progress(done, total, note)`` is called after every (Δt, method) run with the work done so
    far in estimated simulation-step units (a run costs ∝ 1/Δt).
    """
    if case.plan.adaptive is not None:
        raise CaseError([Problem("integrator.adaptive", "the convergence study varies integrator.dt, which with "
                                 "adaptive steps is only the first trial step: run it on the fixed grid "
                                 "(--set integrator.adaptive=null), or compare rtols as "
                                 "scripts/adaptive_report.py does")], case.source)
    dts = sorted(dts, reverse=True)
    from ..warmup import warm_case
    warm_case(case)  # compile first: no reported wall time includes numba compilation
    remember_case(case)
    m = case.x0.size
    pairs = [(dt, "ddm-complex") for dt in dts[-2:]] + [(dt, me) for dt in dts for me in methods]

    def cost(dt: float, method: str) -> float:
        return (1.0 + m * _RUNS.get(method, 0.2)) / dt
    total = sum(cost(dt, me) for dt, me in pairs)
    done = 0.0

    def tick(i: int) -> None:
        nonlocal done
        dt, method = pairs[i]
        done += cost(dt, method)
        log.info("convergence: Δt = %g s, %s done", dt, method)
        if progress is not None:
            progress(done, total, f"Δt = {dt:g} s, {method}")
    with make_executor(workers, scheduler, tasks=len(pairs), default_workers=1) as ex:
        outs = ex.map(_evaluate_task, [(case.text, case.source, dt, me) for dt, me in pairs], tick)
    n_ref = len(dts[-2:])
    refs = [(dt, vals, grads) for (dt, _), (vals, grads, _) in zip(pairs[:n_ref], outs[:n_ref])]
    (dt1, v1, g1), (dt2, v2, g2) = refs if len(refs) == 2 else (refs[0], refs[0])
    p = case.scheme.order
    richardson = extrapolated(dts)
    if richardson:
        f = 1.0 / (2.0 ** p - 1.0)
        ref_v = {n: v2[n] + (v2[n] - v1[n]) * f for n in v2}
        ref_g = {n: g2[n] + (g2[n] - g1[n]) * f for n in g2}
    else:
        ref_v, ref_g = v2, g2
    rows = []
    for (dt, method), (vals, grads, wall) in zip(pairs[n_ref:], outs[n_ref:]):
        value_error = {n: abs(vals[n] - ref_v[n]) / max(abs(ref_v[n]), 1e-300) for n in vals}
        gradient_error = {n: float(np.linalg.norm(grads[n] - ref_g[n]) / max(np.linalg.norm(ref_g[n]), 1e-300))
                          for n in grads}
        if not richardson and dt == dt2:
            # the reference is this run: its value (every method's) and its complex-step gradient
            # equal it by construction, an error of 0 that measures nothing (NaN: not shown, no order)
            value_error = dict.fromkeys(value_error, float("nan"))
            if method == "ddm-complex":
                gradient_error = dict.fromkeys(gradient_error, float("nan"))
        rows.append(Row(dt, method, wall, vals, grads, value_error, gradient_error))
    return rows, ref_v, ref_g


def extrapolated(dts: list[float]) -> bool:
    """Whether the reference of a ladder is Richardson-extrapolated: its two finest steps are
    in ratio 2 (else the reference is the finest run itself)."""
    finest = sorted(set(dts))[:2]
    return len(finest) == 2 and abs(finest[1] / finest[0] - 2.0) < 1e-9


def reference_note(dts: list[float]) -> str:
    """How the ladder's reference was made, in words (for the report and the command)."""
    finest = sorted(set(dts))[:2]
    if extrapolated(dts):
        return (f"the reference is Richardson-extrapolated from the two finest steps "
                f"(Δt = {finest[1]:g} and {finest[0]:g} s, complex-step partials)")
    return (f"the reference is the finest run itself (Δt = {finest[0]:g} s, complex-step partials), not "
            f"extrapolated: the two finest steps are not in ratio 2; the errors at Δt = {finest[0]:g} s are "
            "zero by construction and are not shown, nor used for an order")


def _error_text(error: float) -> str:
    """A relative error in the report; NaN marks the reference run's own (zero by construction)."""
    return "(reference)" if np.isnan(error) else f"{error:.2e}"


def format_order(order: float) -> str:
    """An observed order, or why there is none."""
    return f"{order:.2f}" if np.isfinite(order) else "n/a (needs errors at two steps)"


def observed_order(rows: list[Row], response: str, method: str = "ddm-complex", what: str = "value") -> float:
    """Slope of log(error) over log(Δt) for the coarser half of the ladder (before round-off)."""
    pts = [(r.dt, (r.value_error if what == "value" else r.gradient_error)[response])
           for r in rows if r.method == method]
    pts = [(d, e) for d, e in pts if e > 0]           # NaN (the reference run itself) is left out too
    pts = sorted(pts, reverse=True)[: max(2, len(pts) - 1)]
    if len(pts) < 2:
        return float("nan")
    d, e = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(d, e, 1)[0])


def report_files(case: Case, outdir: str | Path) -> list[Path]:
    """The files :func:`write_report` writes for ``case`` (named from the case name, kept inside
    ``outdir`` whatever the name holds): CSV, markdown, one PNG per response."""
    out, stem = Path(outdir), safe_stem(case.name)
    return ([out / f"{stem}_work_precision.csv", out / f"{stem}_work_precision.md"]
            + [out / f"{stem}_{safe_stem(n)}_work_precision.png" for n in case.response_names])


def write_report(case: Case, rows: list[Row], outdir: str | Path, overwrite: bool = True) -> list[Path]:
    """Markdown and CSV tables and two log-log plots per response; returns the files written
    (each atomically; an existing file is replaced only with ``overwrite``)."""
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    names = list(rows[0].values)
    files = []
    planned = report_files(case, out)
    csv_path = planned[0]
    with atomic_path(csv_path, overwrite) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["dt", "method", "wall_time_s", "response", "value", "value_rel_error", "gradient_rel_error"])
        for r in rows:
            for n in names:
                w.writerow([r.dt, r.method, f"{r.wall_time:.4f}", n, r.values[n],
                            f"{r.value_error[n]:.3e}", f"{r.gradient_error[n]:.3e}"])
    files.append(csv_path)
    lines = [f"# Work-precision study: `{case.name}` (scheme {case.scheme.name}, order {case.scheme.order})", "",
             f"Relative errors against the reference: {reference_note([r.dt for r in rows])}. "
             "Wall times exclude numba compilation (the kernels are compiled before the first timed run).", ""]
    first = rows[0].method
    for n in names:
        lines += [f"## {n}", "", f"Observed order (value, {first}): {format_order(observed_order(rows, n, first))}; "
                  f"gradient: {format_order(observed_order(rows, n, first, what='gradient'))}", "",
                  "| Δt [s] | method | wall time [s] | value error | gradient error |", "|---|---|---|---|---|"]
        for r in rows:
            lines.append(f"| {r.dt:g} | {r.method} | {r.wall_time:.3f} | {_error_text(r.value_error[n])} | "
                         f"{_error_text(r.gradient_error[n])} |")
        lines.append("")
    md = atomic_write_text(planned[1], "\n".join(lines), overwrite)
    files.append(md)
    import matplotlib
    import matplotlib.ticker
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    methods = list(dict.fromkeys(r.method for r in rows))
    for n in names:
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
        for mth in methods:
            rr = [r for r in rows if r.method == mth]
            axes[0].loglog([r.dt for r in rr], [max(r.gradient_error[n], 1e-17) for r in rr], "o-", label=mth)
            axes[1].loglog([r.wall_time for r in rr], [max(r.gradient_error[n], 1e-17) for r in rr], "o-", label=mth)
        rr = [r for r in rows if r.method == methods[0]]
        axes[0].loglog([r.dt for r in rr], [max(r.value_error[n], 1e-17) for r in rr], "k--",
                       label=f"value (order {format_order(observed_order(rows, n, methods[0]))})")
        axes[0].set(xlabel="Δt [s]", ylabel="relative error", title=f"{case.name}: {n}")
        axes[1].set(xlabel="wall time [s]", ylabel="gradient relative error", title="error vs. run time")
        for ax in axes:
            ax.grid(True, which="both", alpha=0.3)
            ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        axes[0].legend(fontsize=7)
        fig.tight_layout()
        png = out / f"{safe_stem(case.name)}_{safe_stem(n)}_work_precision.png"
        with atomic_path(png, overwrite) as tmp:
            fig.savefig(tmp, dpi=110, format="png")
        plt.close(fig)
        files.append(png)
    return files
