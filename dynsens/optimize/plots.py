"""Plots of an optimization file: history of f, violation and KKT residual; design variables and
constraints against their bounds in units; recorded quantities at the start and the optimum."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Sequence

import h5py
import numpy as np

from ..io.series import read_series
from ..plots import Run, plot_runs
from ..timeloop.records import RecordedQuantity
from ..io.paths import atomic_path


# --------------------------------------------------------------------------------------
# plots
# --------------------------------------------------------------------------------------
def plot_files(path: str | Path, outdir: str | Path, load_cases: Sequence[str] = ()) -> list[Path]:
    """The files :func:`plot_optimization` may write for the optimization file ``path`` (of a
    case with ``load_cases``: one optimum plot per load case)."""
    stem = Path(path).stem
    runs = [f"optimum_{n}" for n in load_cases] or ["optimum"]
    return [Path(outdir) / f"{stem}_{kind}.png" for kind in ("history", "design", "constraints", *runs)]


def plot_optimization(path: str | Path, outdir: str | Path, max_lines: int = 8,
                      overwrite: bool = True) -> list[Path]:
    """PNG plots of an optimization file: the history and the best design's time histories.

    Writes ``<stem>_history.png`` (objective, max. constraint violation and KKT residual
    over the iterations of every start), ``<stem>_design.png`` (each design variable over the
    iterations with its bounds, in its unit), ``<stem>_constraints.png`` (each constrained
    response over the iterations against its bound, in its unit) and ``<stem>_optimum.png``
    (the recorded quantities at the start and at the optimum, with events; without recorded
    quantities the ``max_lines`` largest coordinate histories q(t) of the best design); with
    load cases one ``<stem>_optimum_<load case>.png`` per load case, from its runs in
    ``/optimization/load_cases/<name>/``.
    Returns the files written (each atomically; an existing one is replaced only with
    ``overwrite``).
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    path, outdir = Path(path), Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    written = []
    with h5py.File(path, "r") as f:
        opt = f["optimization"]
        objective = str(opt.attrs["objective"])
        fig, axes = plt.subplots(3, 1, figsize=(7, 8), sharex=True)
        for name in sorted(k for k in opt if k.startswith("start_")):
            if "history" not in opt[name]:
                continue
            h = opt[name]["history"]
            it = h["iteration"][()]
            line = axes[0].plot(it, h["f"][()], "o-", ms=3, label=name.replace("_", " "))[0]
            for ax, key in ((axes[1], "max_violation"), (axes[2], "kkt")):
                _positive_on_log(ax, it, h[key][()], line.get_color())
        axes[0].set_ylabel(objective)
        axes[1].set_ylabel("max. violation (scaled)")
        axes[2].set_ylabel("KKT residual (scaled)")
        axes[2].set_xlabel("iteration")
        axes[0].legend(fontsize=8)
        if any(t.get_label() == ZERO_LABEL for t in axes[1].get_lines()):
            axes[1].legend(fontsize=7)
        for ax in axes:
            ax.grid(True, alpha=0.3)
        fig.suptitle(f"{path.name}: optimization history")
        fig.tight_layout()
        p = outdir / f"{path.stem}_history.png"
        with atomic_path(p, overwrite) as tmp:
            fig.savefig(tmp, dpi=100, format="png")
        plt.close(fig)
        written.append(p)
        written += _bounds_plots(f, path, outdir, plt)
        if "load_cases" in opt:        # each load case's start and optimum runs
            for name in opt["load_cases"]:
                p_run = _runs_plot(f, opt["load_cases"][name], path, outdir / f"{path.stem}_optimum_{name}.png",
                                   f"load case {name}", max_lines, overwrite, plt)
                written += [p_run] if p_run is not None else []
        else:
            p_run = _runs_plot(f, opt, path, outdir / f"{path.stem}_optimum.png", "", max_lines, overwrite, plt)
            written += [p_run] if p_run is not None else []
    return written


ZERO_LABEL = "zero (feasible / converged)"


def _runs_plot(f: h5py.File, group: h5py.Group, path: Path, out: Path, what: str, max_lines: int,
               overwrite: bool, plt: Any) -> Path | None:
    """The recorded quantities of ``group``'s ``initial`` and ``optimum`` runs (without recorded
    quantities, the ``max_lines`` largest coordinates at the optimum) into ``out``; None when
    ``group`` holds neither.  ``what`` names the load case in the title ("" for none)."""
    of = f" ({what})" if what else ""
    runs = [r for r in (_stored_run(group, "initial", "start"), _stored_run(group, "optimum", "optimum"))
            if r is not None and r.quantities]
    if len(runs) == 2:
        return plot_runs(runs, out, f"{path.name}{of}: recorded quantities at the start (solid) and the "
                                    "optimum (dashed)")
    if not ("optimum" in group and "state" in group["optimum"] and "q" in group["optimum/state"]):
        return None
    t = group["optimum/time"][()]
    q = group["optimum/state/q"][()]
    labels = [lb.decode() if isinstance(lb, bytes) else lb for lb in group["optimum/state"].attrs["q_labels"]]
    order = np.argsort(-np.max(np.abs(q), axis=0))[:max_lines]
    fig, ax = plt.subplots(figsize=(7, 4))
    for j in order:
        ax.plot(t, q[:, j], label=labels[j] if j < len(labels) else f"q[{j}]")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("coordinates q (case units)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, ncol=2)
    ax.set_title(f"the {len(order)} largest coordinates at the optimum{of} (no recorded quantities)\n"
                 + _named_design(f, group["optimum/x"][()]), fontsize=8)
    fig.tight_layout()
    with atomic_path(out, overwrite) as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    return out


def _positive_on_log(ax: Any, it: np.ndarray, v: np.ndarray, colour: str) -> None:
    """v over the iterations on a log axis: positive values as a line, exact zeros (a feasible
    point, no violation) as hollow markers on the axis floor, not as a clamped number."""
    v = np.asarray(v, dtype=float)
    pos = v > 0
    ax.semilogy(np.where(pos, it, np.nan), np.where(pos, v, np.nan), "o-", ms=3, color=colour)
    zero = np.isfinite(v) & ~pos
    if zero.any():
        ax.plot(it[zero], np.full(int(zero.sum()), 0.02), "o", ms=4, mfc="none", color=colour,
                transform=ax.get_xaxis_transform(), label=ZERO_LABEL, clip_on=False)


def _named_design(f: h5py.File, x: np.ndarray, at_most: int = 6) -> str:
    """'A1 = 12.3 mm², A2 = ...' of a design vector, with names and units from the file."""
    names = [n.decode() if isinstance(n, bytes) else str(n) for n in f["design/names"][()]]
    units = json.loads(f["optimization"].attrs.get("design_units", "[]")) or [""] * len(names)
    parts = [f"{n} = {v:.4g}" + (f" {u}" if u else "") for n, v, u in zip(names, x, units)]
    more = f", … ({len(parts) - at_most} more)" if len(parts) > at_most else ""
    return "best design: " + ", ".join(parts[:at_most]) + more


def _stored_run(opt: h5py.Group, group: str, name: str) -> Run | None:
    """A run stored by the optimizer (``/optimization/initial`` or ``/optimum``) for plot_runs."""
    if group not in opt:
        return None
    d = read_series(opt[group])
    qs = {k: RecordedQuantity(k, d["units"].get(k, ""), d["labels"].get(k, k), d["time"], v,
                              components=tuple(d["components"].get(k, ())))
          for k, v in d["quantities"].items()}
    events = json.loads(opt[group].attrs.get("events", "{}"))
    return Run(name, qs, {k: float(v) for k, v in events.items()})


def _bounds_plots(f: h5py.File, path: Path, outdir: Path, plt: Any) -> list[Path]:
    """Design variables and constrained responses over the iterations against their bounds."""
    opt = f["optimization"]
    names = [n.decode() if isinstance(n, bytes) else str(n) for n in f["design/names"][()]]
    lower, upper = f["design/lower"][()], f["design/upper"][()]
    dunits = json.loads(opt.attrs.get("design_units", "[]")) or [""] * len(names)
    runits = json.loads(opt.attrs.get("response_units", "{}"))
    rnames = json.loads(opt.attrs["response_names"])
    cons = json.loads(opt.attrs["constraints"])
    starts = [(k, opt[k]["history"]) for k in sorted(k for k in opt if k.startswith("start_"))
              if "history" in opt[k]]
    written = []

    def panel_grid(n: int) -> tuple[Any, Any]:
        fig, axes = plt.subplots(n, 1, figsize=(7, 1.9 * n + 0.8), sharex=True, squeeze=False)
        return fig, axes[:, 0]

    def save(fig: Any, axes: Any, suffix: str, title: str) -> None:
        axes[-1].set_xlabel("iteration")
        for ax in axes:
            ax.grid(True, alpha=0.3)
        axes[0].legend(fontsize=7)
        fig.suptitle(f"{path.name}: {title}", fontsize=10)
        fig.tight_layout()
        p = outdir / f"{path.stem}_{suffix}.png"
        fig.savefig(p, dpi=100)
        plt.close(fig)
        written.append(p)

    if names and starts:
        fig, axes = panel_grid(len(names))
        for j, (ax, n) in enumerate(zip(axes, names)):
            for k, h in starts:
                ax.plot(h["iteration"][()], h["x"][:, j], "o-", ms=3, label=k.replace("_", " "))
            for b, lab in ((lower[j], "lower bound"), (upper[j], "upper bound")):
                if np.isfinite(b):
                    ax.axhline(b, color="k", ls="--", lw=0.8, label=lab if j == 0 else None)
            ax.set_ylabel(f"{n} [{dunits[j]}]" if j < len(dunits) and dunits[j] else n)
        save(fig, axes, "design", "design variables and their bounds")
    if cons and starts:
        fig, axes = panel_grid(len(cons))
        for ax, c in zip(axes, cons):
            i = rnames.index(c["response"])
            for k, h in starts:
                ax.plot(h["iteration"][()], h["responses"][:, i], "o-", ms=3, label=k.replace("_", " "))
            op = {"upper": "<=", "lower": ">=", "eq": "=="}[c["kind"]]
            ax.axhline(c["bound"], color="r", ls="--", lw=0.9, label="bound")
            unit = runits.get(c["response"], "")
            ax.set_ylabel(f"{c['response']} [{unit}]" if unit else c["response"])
            ax.set_title(f"{c['response']} {op} {c['bound']:g} {unit}".strip(), fontsize=8)
        save(fig, axes, "constraints", "constrained responses against their bounds")
    return written
