"""The README's pictures of a moving model: the weir's animation and the tower's worst instant.

    python scripts/make_view_figures.py [--out docs] [--work results/views]

* ``docs/tyrolean_weir.gif``: ``cases/tyrolean_weir.yaml`` at its case design, the cleaning
  stroke (bodies, joints, the cylinder), at most 120 frames;
* ``docs/tower_stress_ratio.png``: ``cases/tower_sizing.yaml`` at the optimum recorded in
  ``cases/records/tower_sizing_optimum.yaml``, members coloured by stress ratio at the instant
  of the largest ratio.

The result files go to ``--work`` (they can be opened with ``dynsens export ... --vtk DIR``).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import yaml

from dynsens.animate import animate, render_frame, worst_instant
from dynsens.case.load import load_case
from dynsens.io.hdf5 import write_result
from dynsens.io.scene import read_scene
from dynsens.simulation import run_case

ROOT = Path(__file__).resolve().parents[1]
HISTORIES = ("q", "qd", "lam", "p")


def simulate(case_file: Path, out: Path, x: np.ndarray | None = None) -> Path:
    """Run the case (no sensitivities) at design x with the histories a drawing reads."""
    case = load_case(case_file)
    result = run_case(case, x, sensitivities=False, history=HISTORIES)
    write_result(out, result, case, overwrite=True)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=ROOT / "docs")
    ap.add_argument("--work", type=Path, default=ROOT / "results" / "views")
    args = ap.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    weir = simulate(ROOT / "cases" / "tyrolean_weir.yaml", args.work / "tyrolean_weir.h5")
    gif = animate(weir, args.out / "tyrolean_weir.gif", overwrite=True, max_frames=120, fps=15)
    print(f"{gif}: {gif.stat().st_size / 1e6:.2f} MB")

    record = yaml.safe_load((ROOT / "cases" / "records" / "tower_sizing_optimum.yaml").read_text())
    case = load_case(ROOT / "cases" / "tower_sizing.yaml")
    x = np.array([record["design"][name] for name in case.design_names])
    tower = simulate(ROOT / "cases" / "tower_sizing.yaml", args.work / "tower_optimum.h5", x)
    scene = read_scene(tower, label="optimum")
    k = worst_instant(scene)
    png = render_frame(scene, k, args.out / "tower_stress_ratio.png", overwrite=True)
    ratio = np.nanmax(scene.parts[0].cell_data["stress_ratio"][k])
    print(f"{png}: t = {scene.time[k]:.4g} s, largest stress ratio {ratio:.3f}")


if __name__ == "__main__":
    main()
