"""What a study shows: each response against each design variable, and which variables matter.

Sensitivity measures (rows: responses, columns: design variables):

* ``gradient`` (with ``--gradients``): the mean over the designs of |∂r/∂x_j|·(upper_j − lower_j),
  the change of r that the gradient predicts over the whole range of x_j, divided by its
  sum over j (shares that add up to 1 per response);
* ``rank`` (always): |Spearman rank correlation| of x_j and r over the sample, a
  sampling-based measure that needs no gradients (monotone effects; interactions and
  non-monotone effects lower it).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .store import StudyTable


def _usable(table: StudyTable) -> np.ndarray:
    return ~table.failed


def sensitivity_summary(table: StudyTable) -> dict[str, np.ndarray]:
    """Normalized sensitivity measures (n_r, m): ``rank``, and ``gradient`` when the study has gradients."""
    from scipy.stats import spearmanr
    ok = _usable(table)
    nr, m = len(table.response_names), len(table.design_names)
    rank = np.full((nr, m), np.nan)
    for i in range(nr):
        rows = ok & np.isfinite(table.values[:, i])
        if rows.sum() < 3:
            continue
        for j in range(m):
            xj, ri = table.x[rows, j], table.values[rows, i]
            if np.ptp(xj) > 0 and np.ptp(ri) > 0:
                rank[i, j] = abs(spearmanr(xj, ri).statistic)
            else:
                rank[i, j] = 0.0
    out: dict[str, np.ndarray] = {}
    if table.gradients is not None:
        span = table.upper - table.lower
        g = np.abs(table.gradients[ok]) * span[None, None, :]          # (k, n_r, m)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.array([[np.nanmean(g[:, i, j]) if np.isfinite(g[:, i, j]).any() else np.nan
                              for j in range(m)] for i in range(nr)])
            total = np.nansum(mean, axis=1, keepdims=True)
            out["gradient"] = np.where(total > 0, mean / total, 0.0)
    out["rank"] = rank
    return out


def format_summary(table: StudyTable) -> str:
    """Plain-text table of the sensitivity measures (the largest per response marked with *)."""
    meas = sensitivity_summary(table)
    lines = []
    for kind, s in meas.items():
        title = ("gradient shares, mean |dr/dx_j|·range_j normalized per response" if kind == "gradient"
                 else "|Spearman rank correlation| of r and x_j")
        lines += [f"sensitivity ({title}):",
                  f"{'response':<16}" + "".join(f"{n:>14}" for n in table.design_names)]
        for i, r in enumerate(table.response_names):
            row = s[i]
            best = int(np.nanargmax(row)) if np.isfinite(row).any() else -1
            lines.append(f"{r:<16}" + "".join(
                f"{(f'{v:.3f}' + ('*' if j == best else ' ')) if np.isfinite(v) else '-':>14}"
                for j, v in enumerate(row)))
        lines.append("")
    return "\n".join(lines).rstrip()


def objective_and_feasibility(table: StudyTable) -> tuple[str, np.ndarray | None]:
    """The response to map over the design space (the case's objective, else the first
    response) and, when the case has constraints, which rows satisfy all of them."""
    from ..case.load import load_case_text
    spec = load_case_text(table.case_text, table.case_source).optimization
    if spec is None:
        return table.response_names[0], None
    feasible = ~table.failed
    for c in spec.constraints:
        v = table.values[:, table.response_names.index(c.response)]
        with np.errstate(invalid="ignore"):
            if c.lower is not None:
                feasible &= v >= c.lower
            if c.upper is not None:
                feasible &= v <= c.upper
    return spec.objective, feasible


def _plot_pairs(table: StudyTable, path: Path) -> None:
    """The objective over every pair of design variables; feasible designs filled."""
    import matplotlib.pyplot as plt
    names, m = table.design_names, len(table.design_names)
    obj, feasible = objective_and_feasibility(table)
    f = table.values[:, table.response_names.index(obj)]
    ok = ~table.failed & np.isfinite(f)
    pairs = [(a, b) for a in range(m) for b in range(a + 1, m)]
    cols = min(3, len(pairs))
    rows = -(-len(pairs) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.0 * cols + 1.0, 3.4 * rows), squeeze=False,
                             layout="constrained")
    vmin, vmax = (np.min(f[ok]), np.max(f[ok])) if ok.any() else (0, 1)
    best = None
    if feasible is not None and (feasible & ok).any():
        best = int(np.flatnonzero(feasible & ok)[np.argmin(f[feasible & ok])])
    for ax, (a, b) in zip(axes.ravel(), pairs):
        filled = ok if feasible is None else ok & feasible
        sc = ax.scatter(table.x[filled, a], table.x[filled, b], c=f[filled], vmin=vmin, vmax=vmax, s=28)
        if feasible is not None:
            hollow = ok & ~feasible
            ax.scatter(table.x[hollow, a], table.x[hollow, b], c=f[hollow], vmin=vmin, vmax=vmax, s=28,
                       marker="x")
        if best is not None:
            ax.plot(table.x[best, a], table.x[best, b], "*", ms=14, mfc="none", mec="r")
        ax.plot(table.x[table.failed, a], table.x[table.failed, b], "s", mfc="none", mec="C3", ms=6)
        ax.set(xlabel=names[a], ylabel=names[b])
        ax.grid(True, alpha=0.3)
    for ax in axes.ravel()[len(pairs):]:
        ax.axis("off")
    fig.colorbar(sc, ax=axes.ravel().tolist(), label=obj)
    note = "" if feasible is None else " (dots: all constraints met, x: violated, red star: best feasible)"
    fig.suptitle(f"{obj} over the design space{note}", fontsize=10)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def study_plot_files(outdir: str | Path) -> list[Path]:
    """The files :func:`plot_study` may write in ``outdir``."""
    return [Path(outdir) / f"study_{kind}.png" for kind in ("responses", "sensitivity", "pairs")]


def plot_study(table: StudyTable, outdir: str | Path) -> list[Path]:
    """``study_responses.png`` (every response over every variable; short lines show the local
    gradient at each design), ``study_sensitivity.png`` and, for two or more design
    variables, ``study_pairs.png`` (the objective over each pair); returns the files written."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    names, rnames = table.design_names, table.response_names
    nr, m = len(rnames), len(names)
    ok = _usable(table)
    fig, axes = plt.subplots(nr, m, figsize=(3.1 * m, 2.0 * nr + 0.6), squeeze=False, sharex="col",
                             layout="constrained")
    span = table.upper - table.lower
    for i, r in enumerate(rnames):
        rows = ok & np.isfinite(table.values[:, i])
        unit = table.response_units.get(r, "")
        for j, n in enumerate(names):
            ax = axes[i, j]
            xj, ri = table.x[rows, j], table.values[rows, i]
            ax.plot(xj, ri, "o", ms=3.5, color="C0")
            if table.gradients is not None:
                d = table.gradients[rows, i, j]
                h = 0.04 * (span[j] if np.isfinite(span[j]) and span[j] > 0 else np.ptp(xj) or 1.0)
                for a, b, s in zip(xj, ri, d):
                    if np.isfinite(s):
                        ax.plot([a - h, a + h], [b - s * h, b + s * h], "-", color="C1", lw=1.0)
            if (~ok).any():
                for a in table.x[~ok, j]:
                    ax.axvline(a, color="C3", lw=0.6, alpha=0.5)
            if j == 0:
                ax.set_ylabel(f"{r}" + (f" [{unit}]" if unit else ""), fontsize=8)
            if i == nr - 1:
                ax.set_xlabel(n, fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(True, alpha=0.3)
    extra = (" Orange: local slope ∂r/∂x_j." if table.gradients is not None else "") + \
        (" Red lines: failed designs." if (~ok).any() else "")
    fig.suptitle(f"{Path(table.case_source).stem}: {int(ok.sum())} designs ({table.sample}).{extra}", fontsize=10)
    files = [out / "study_responses.png"]
    fig.savefig(files[0], dpi=90)
    plt.close(fig)

    meas = sensitivity_summary(table)
    fig, axes = plt.subplots(1, len(meas), figsize=(1.3 * m * len(meas) + 3.0, 0.42 * nr + 1.6), squeeze=False)
    for ax, (kind, s) in zip(axes[0], meas.items()):
        ax.imshow(np.nan_to_num(s), cmap="viridis", vmin=0, vmax=1, aspect="auto")
        for (i, j), v in np.ndenumerate(s):
            ax.text(j, i, "-" if not np.isfinite(v) else f"{v:.2f}", ha="center", va="center", fontsize=7,
                    color="w" if (np.isfinite(v) and v < 0.6) else "k")
        ax.set_xticks(range(m), names, fontsize=8, rotation=30)
        ax.set_yticks(range(nr), rnames, fontsize=8)
        ax.set_title("share of mean |∂r/∂x_j|·range_j" if kind == "gradient" else "|Spearman ρ(x_j, r)|",
                     fontsize=9)
    fig.tight_layout()
    files.append(out / "study_sensitivity.png")
    fig.savefig(files[1], dpi=100)
    plt.close(fig)
    if len(names) >= 2:
        files.append(out / "study_pairs.png")
        _plot_pairs(table, files[2])
    return files
