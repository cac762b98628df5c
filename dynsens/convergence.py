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
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import yaml

from .case.load import Case, load_case_dict
from .executor import cached_case, make_executor, remember_case
from .simulation import run_case

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
        grads = {n: np.real(r.gradient) for n, r in res.responses.items()}
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


def _evaluate_task(job: tuple[str, str, float, str]) -> tuple[dict[str, float], dict[str, np.ndarray], float]:
    """One rung of the ladder on a worker: (case text, source, Δt, method) -> values, gradients, wall time."""
    text, source, dt, method = job
    return _evaluate(_with(cached_case(text, source), [f"integrator.dt={dt}"]), method)


def work_precision(case: Case, dts: list[float], methods: list[str], *, workers: int | None = None,
                   scheduler: str | None = None) -> tuple[list[Row], dict, dict]:
    """Run the ladder; returns the rows and the reference values and gradients.

    ``workers`` local processes (default 1: in this process, so that wall times are not
    shared) or the Dask ``scheduler`` at that address run the (Δt, method) pairs.
    """
    dts = sorted(dts, reverse=True)
    remember_case(case)
    pairs = [(dt, "ddm-complex") for dt in dts[-2:]] + [(dt, m) for dt in dts for m in methods]
    with make_executor(workers, scheduler, tasks=len(pairs), default_workers=1) as ex:
        outs = ex.map(_evaluate_task, [(case.text, case.source, dt, m) for dt, m in pairs])
    n_ref = len(dts[-2:])
    refs = [(dt, vals, grads) for (dt, _), (vals, grads, _) in zip(pairs[:n_ref], outs[:n_ref])]
    (dt1, v1, g1), (dt2, v2, g2) = refs if len(refs) == 2 else (refs[0], refs[0])
    p = case.scheme.order
    ratio = dt1 / dt2 if dt2 < dt1 else 1.0
    if abs(ratio - 2.0) < 1e-9:
        f = 1.0 / (ratio ** p - 1.0)
        ref_v = {n: v2[n] + (v2[n] - v1[n]) * f for n in v2}
        ref_g = {n: g2[n] + (g2[n] - g1[n]) * f for n in g2}
    else:
        ref_v, ref_g = v2, g2
    rows = []
    for (dt, method), (vals, grads, wall) in zip(pairs[n_ref:], outs[n_ref:]):
        rows.append(Row(dt, method, wall, vals, grads,
                        {n: abs(vals[n] - ref_v[n]) / max(abs(ref_v[n]), 1e-300) for n in vals},
                        {n: float(np.linalg.norm(grads[n] - ref_g[n]) / max(np.linalg.norm(ref_g[n]), 1e-300))
                         for n in grads}))
    return rows, ref_v, ref_g


def observed_order(rows: list[Row], response: str, method: str = "ddm-complex", what: str = "value") -> float:
    """Slope of log(error) over log(Δt) for the coarser half of the ladder (before round-off)."""
    pts = [(r.dt, (r.value_error if what == "value" else r.gradient_error)[response])
           for r in rows if r.method == method]
    pts = [(d, e) for d, e in pts if e > 0]
    pts = sorted(pts, reverse=True)[: max(2, len(pts) - 1)]
    if len(pts) < 2:
        return float("nan")
    d, e = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(d, e, 1)[0])


def write_report(case: Case, rows: list[Row], outdir: str | Path) -> list[Path]:
    """Markdown and CSV tables and two log-log plots per response; returns the files written."""
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    names = list(rows[0].values)
    files = []
    csv_path = out / f"{case.name}_work_precision.csv"
    with open(csv_path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["dt", "method", "wall_time_s", "response", "value", "value_rel_error", "gradient_rel_error"])
        for r in rows:
            for n in names:
                w.writerow([r.dt, r.method, f"{r.wall_time:.4f}", n, r.values[n],
                            f"{r.value_error[n]:.3e}", f"{r.gradient_error[n]:.3e}"])
    files.append(csv_path)
    lines = [f"# Work-precision study: `{case.name}` (scheme {case.scheme.name}, order {case.scheme.order})", "",
             "Relative errors against the reference (finest Δt, complex-step partials, Richardson-extrapolated).", ""]
    first = rows[0].method
    for n in names:
        lines += [f"## {n}", "", f"Observed order (value, {first}): {observed_order(rows, n, first):.2f}; "
                  f"gradient: {observed_order(rows, n, first, what='gradient'):.2f}", "",
                  "| Δt [s] | method | wall time [s] | value error | gradient error |", "|---|---|---|---|---|"]
        for r in rows:
            lines.append(f"| {r.dt:g} | {r.method} | {r.wall_time:.3f} | {r.value_error[n]:.2e} | "
                         f"{r.gradient_error[n]:.2e} |")
        lines.append("")
    md = out / f"{case.name}_work_precision.md"
    md.write_text("\n".join(lines), encoding="utf-8")
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
                       label=f"value (order {observed_order(rows, n, methods[0]):.2f})")
        axes[0].set(xlabel="Δt [s]", ylabel="relative error", title=f"{case.name}: {n}")
        axes[1].set(xlabel="wall time [s]", ylabel="gradient relative error", title="error vs. run time")
        for ax in axes:
            ax.grid(True, which="both", alpha=0.3)
            ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        axes[0].legend(fontsize=7)
        fig.tight_layout()
        png = out / f"{case.name}_{n}_work_precision.png"
        fig.savefig(png, dpi=110)
        plt.close(fig)
        files.append(png)
    return files
