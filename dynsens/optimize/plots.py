"""Plots of an optimization file: history of f, violation and KKT residual; the optimum's histories."""
from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from ..io.paths import atomic_path
from .problem import _fmt


# --------------------------------------------------------------------------------------
# plots
# --------------------------------------------------------------------------------------
def plot_files(path: str | Path, outdir: str | Path) -> list[Path]:
    """The files :func:`plot_optimization` may write for the optimization file ``path``."""
    stem = Path(path).stem
    return [Path(outdir) / f"{stem}_history.png", Path(outdir) / f"{stem}_optimum.png"]


def plot_optimization(path: str | Path, outdir: str | Path, max_lines: int = 8,
                      overwrite: bool = True) -> list[Path]:
    """PNG plots of an optimization file: the history and the best design's time histories.

    Writes ``<stem>_history.png`` (objective, max. constraint violation and KKT residual
    over the iterations of every start) and ``<stem>_optimum.png`` (the ``max_lines``
    largest displacement histories q(t) of the best design).  Returns the files written (each
    atomically; an existing one is replaced only with ``overwrite``).
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
            axes[0].plot(it, h["f"][()], "o-", ms=3, label=name.replace("_", " "))
            axes[1].semilogy(it, np.maximum(h["max_violation"][()], 1e-16), "o-", ms=3)
            axes[2].semilogy(it, np.maximum(h["kkt"][()], 1e-16), "o-", ms=3)
        axes[0].set_ylabel(objective)
        axes[1].set_ylabel("max. violation (scaled)")
        axes[2].set_ylabel("KKT residual (scaled)")
        axes[2].set_xlabel("iteration")
        axes[0].legend(fontsize=8)
        for ax in axes:
            ax.grid(True, alpha=0.3)
        fig.suptitle(f"{path.name}: optimization history")
        fig.tight_layout()
        p = outdir / f"{path.stem}_history.png"
        with atomic_path(p, overwrite) as tmp:
            fig.savefig(tmp, dpi=100, format="png")
        plt.close(fig)
        written.append(p)
        if "optimum" in opt and "q" in opt["optimum/state"]:
            t = opt["optimum/time"][()]
            q = opt["optimum/state/q"][()]
            labels = [lb.decode() if isinstance(lb, bytes) else lb for lb in opt["optimum/state"].attrs["q_labels"]]
            order = np.argsort(-np.max(np.abs(q), axis=0))[:max_lines]
            fig, ax = plt.subplots(figsize=(7, 4))
            for j in order:
                ax.plot(t, q[:, j], label=labels[j] if j < len(labels) else f"q[{j}]")
            ax.set_xlabel("t [s]")
            ax.set_ylabel("q")
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=8, ncol=2)
            ax.set_title(f"best design x = {_fmt(opt['optimum/x'][()])}")
            fig.tight_layout()
            p = outdir / f"{path.stem}_optimum.png"
            with atomic_path(p, overwrite) as tmp:
                fig.savefig(tmp, dpi=100, format="png")
            plt.close(fig)
            written.append(p)
    return written
