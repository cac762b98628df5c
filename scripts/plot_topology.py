"""Plot the topology a sizing optimization left: every bar drawn with a width proportional to its
area, the removed ones (area at the lower bound, /optimization/summary/removed) omitted.

    python scripts/plot_topology.py CASE.yaml OPT.h5 OUT.png [--family A]

For plane trusses (the ground structure, cases/ground_structure.yaml, also under load cases:
cases/ground_structure_two_loads.yaml) and the x-z view of 3D ones.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import h5py
import numpy as np
import yaml

from dynsens.case.load_cases import load_any_case

MAX_WIDTH = 6.0     # points, of the largest area


def topology(case_file: Path, opt_file: Path, family: str) -> tuple[list[tuple[np.ndarray, np.ndarray]],
                                                                    np.ndarray, int, int]:
    """The remaining bars' end points, their areas, and the counts of remaining and removed bars."""
    case = load_any_case(case_file)     # a case, or a set of load cases (the same design)
    raw = yaml.safe_load(Path(case_file).read_text())
    nodes = {k: np.asarray(v["coords"], dtype=float) for k, v in raw["model"]["nodes"].items()}
    ends = {e["name"]: e["nodes"] for e in raw["model"]["elements"] if e.get("type") == "bar"}
    with h5py.File(opt_file, "r") as f:
        s = f["optimization/summary"]
        best = list(s["start"][()]).index(int(s.attrs["best"]))
        x = np.asarray(s["x"][best], dtype=float)
        removed = {m.decode() if isinstance(m, bytes) else str(m) for m in s[f"removed/{family}"][()]}
    segs, areas = [], []
    for j, name in enumerate(case.design_names):
        if not name.startswith(family + "[") or name[len(family) + 1:-1] in removed:
            continue
        a, b = ends[name[len(family) + 1:-1]]
        segs.append((nodes[a], nodes[b]))
        areas.append(x[j])
    return segs, np.asarray(areas), len(segs), len(removed)


def main() -> None:
    """Write the plot."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", type=Path)
    ap.add_argument("opt", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--family", default="A")
    args = ap.parse_args()
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    segs, areas, kept, gone = topology(args.case, args.opt, args.family)
    fig, ax = plt.subplots(figsize=(10, 5))
    top = float(areas.max()) if areas.size else 1.0
    for (p, q), a in zip(segs, areas):
        k = 1 if p.size == 2 else 2       # plane: y; 3D: the x-z view
        ax.plot([p[0], q[0]], [p[k], q[k]], color="k", lw=max(MAX_WIDTH * a / top, 0.2),
                solid_capstyle="round")
    ax.set_aspect("equal")
    raw = yaml.safe_load(args.case.read_text(encoding="utf-8"))
    loads = f" under load cases {', '.join(raw['load_cases'])}" if raw.get("load_cases") else ""
    ax.set_title(f"{kept} members remain, {gone} removed{loads} (width ∝ area, largest {top:.4g})")
    ax.set_xlabel("x")
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"wrote {args.out}: {kept} members remain, {gone} removed")


if __name__ == "__main__":
    main()
