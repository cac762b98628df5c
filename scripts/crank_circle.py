"""The virtuous circle of lightweight design in a fast mechanism (issue 33): cases/crank_circle.yaml.

A slider crank at 300 rad/s whose connecting rod is a sized steel bar member and whose crank
carries a counterweight.  Three verified optimizations of the same objective (main-bearing force
+ 1000 N/kg of rod and counterweight, rod stress and buckling constrained):

* **joint**: the rod section and the counterweight together;
* **balanced**: the counterweight alone, for the start rod (the mechanism designed first);
* **then sized**: the rod section alone, for that counterweight (the structure sized second:
  the sequential design).

Then the designs are simulated over the case's two revolutions and tabulated (rod section and
mass, counterweight, peak bearing force, objective, stress and buckling ratios), with the
optimizations' iterations, simulations and wall times; ``OUT/table.md``, ``OUT/table.json`` and
the figure ``docs/crank_circle.png``.

Usage: python scripts/crank_circle.py [--out results/crank_circle] [--reuse] [--figure PATH]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import yaml

import dynsens
from virtuous_circle import bar_panels, optimize, table, with_fixed, write_tables

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "cases" / "crank_circle.yaml"
FIGURE = ROOT / "docs" / "crank_circle.png"


def raw_case() -> dict:
    """The shipped case as a mapping."""
    return yaml.safe_load(CASE.read_text(encoding="utf-8"))


def evaluate(x: dict[str, float]) -> dict[str, float]:
    """The crank at design ``x`` (both variables), without sensitivities: the table's quantities."""
    sim = dynsens.simulate(CASE, [x["A_rod"], x["m_cw"]], sensitivities=False)
    v, q = sim.values, sim.run.quantities
    row = {"A_rod_mm2": x["A_rod"] * 1e6, "rod_mass_kg": v["rod_mass"], "m_cw_kg": x["m_cw"],
           "peak_bearing_N": float(np.max(q["bearing_force"].value)), "f_N": v["f"],
           "stress": v["stress"], "buckling": v["buckling"],
           "feasible": bool(v["stress"] <= 1 + 1e-6 and v["buckling"] <= 1 + 1e-6)}
    return {k: (float(val) if not isinstance(val, bool) else val) for k, val in row.items()}


FORMAT = {"A_rod_mm2": ("rod section [mm²]", "{:.1f}"), "rod_mass_kg": ("rod mass [kg]", "{:.4f}"),
          "m_cw_kg": ("counterweight [kg]", "{:.3f}"), "peak_bearing_N": ("peak bearing force [N]", "{:,.0f}"),
          "f_N": ("objective f [N]", "{:,.0f}"), "stress": ("rod stress ratio", "{:.3f}"),
          "buckling": ("rod buckling ratio", "{:.3f}"), "feasible": ("feasible", "{}")}


def plot(rows: dict[str, dict], path: Path) -> None:
    """Four panels (rod mass, counterweight, peak bearing force, objective), one bar per design."""
    bar_panels(rows, (("rod_mass_kg", "rod mass [kg]", 1.0), ("m_cw_kg", "counterweight [kg]", 1.0),
                      ("peak_bearing_N", "peak bearing force [kN]", 1e3), ("f_N", "objective f [kN]", 1e3)),
               "Slider crank with a sized rod: start, balanced, then sized (sequential), joint optimum", path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "crank_circle")
    ap.add_argument("--reuse", action="store_true", help="take optimizations recorded in OUT")
    ap.add_argument("--figure", type=Path, default=FIGURE)
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    raw = raw_case()
    start = {v["name"]: float(v["value"]) for v in raw["design"]["variables"]}
    runs = {"joint": optimize("joint", raw, args.out, args.reuse, None)}
    runs["balanced"] = optimize("balanced", with_fixed(raw, {"A_rod": start["A_rod"]}), args.out, args.reuse, None)
    m_cw = runs["balanced"]["x"]["m_cw"]
    runs["then sized"] = optimize("then_sized", with_fixed(raw, {"m_cw": m_cw}), args.out, args.reuse, None)
    designs = {"start": start, "balanced": {**start, "m_cw": m_cw},
               "balanced, then sized": {"A_rod": runs["then sized"]["x"]["A_rod"], "m_cw": m_cw},
               "joint optimum": runs["joint"]["x"]}
    rows = {name: evaluate(x) for name, x in designs.items()}
    write_tables(args.out, table(rows, runs, FORMAT), {"designs": designs, "rows": rows, "runs": runs})
    plot(rows, args.figure)


if __name__ == "__main__":
    main()
