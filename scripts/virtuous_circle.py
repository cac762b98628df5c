"""The virtuous circle of lightweight design on the weir with a flexible rack (issue 33).

Three optimizations, each verified by ``dynsens optimize``'s own check (the optimum re-run at half
the step and on a longer window):

* **joint**: cases/tyrolean_weir_flexible.yaml as shipped: geometry, pump flow and the two bar
  sections together, every member constraint and the paper's three;
* **rigid**: cases/tyrolean_weir.yaml, the rigid mechanism alone (Table 1's problem);
* **sizing**: the rack's sections alone, in the flexible model, for the rigid optimum's geometry
  and pump flow (the sequential design: mechanism first, then its members for its loads).

Then four designs are simulated in the flexible model over the whole cycle: the start, the rigid
optimum with the rack as started, the rigid optimum with the rack sized for it (sequential) and
the joint optimum.  Printed (and written to ``OUT/table.md``, ``OUT/table.json``): rack mass,
peak joint force (largest |F| of the joints Z, A, B, P over the cycle), peak piston-side pressure,
cleaning time t_F, the objective, the largest member stress and buckling ratios, the paper's
constraints, feasibility, and each optimization's iterations, simulations and wall time.  The
plot goes to ``docs/virtuous_circle.png``.

Usage: python scripts/virtuous_circle.py [--out results/virtuous_circle] [--reuse] [--maxiter N] [--only NAME]
[--resume]
(``--reuse`` takes an optimization already recorded in OUT/<name>.json instead of running it.)
"""
from __future__ import annotations

import argparse
import copy
import json
import re
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

import dynsens

ROOT = Path(__file__).resolve().parents[1]
FLEXIBLE = ROOT / "cases" / "tyrolean_weir_flexible.yaml"
RIGID = ROOT / "cases" / "tyrolean_weir.yaml"
FIGURE = ROOT / "docs" / "virtuous_circle.png"
GEOMETRY = ("theta_AZ", "l_AZ", "l_BZ", "V_S")        # the mechanism's variables (both cases)
SECTIONS = ("A_ZL", "A_BL")
BARS = ("ZL", "BL")
JOINTS = ("reaction_Z", "reaction_A", "reaction_B", "reaction_P")
MEMBER_RATIOS = tuple(f"{kind}_{bar}" for kind in ("stress", "buckling") for bar in BARS)
PAPER = ("g1", "g2", "g3")


def flexible_raw() -> dict:
    """The shipped flexible case as a mapping."""
    return yaml.safe_load(FLEXIBLE.read_text(encoding="utf-8"))


def with_fixed(raw: dict, fixed: dict[str, float]) -> dict:
    """``raw`` with the design variables ``fixed`` (name -> value) made constants: removed from
    ``design.variables`` and their names replaced by their values in every expression string."""
    out = copy.deepcopy(raw)
    out["design"]["variables"] = [v for v in out["design"]["variables"] if v["name"] not in fixed]
    patterns = [(re.compile(rf"\b{re.escape(k)}\b"), f"({v!r})") for k, v in fixed.items()]

    def subst(node: Any) -> Any:
        if isinstance(node, str):
            for pat, val in patterns:
                node = pat.sub(val, node)
            return node
        if isinstance(node, list):
            return [subst(n) for n in node]
        if isinstance(node, dict):
            return {k: (v if k == "design" else subst(v)) for k, v in node.items()}
        return node
    return subst(out)


def optimize(name: str, case: Any, out: Path, reuse: bool, maxiter: int | None, resume: bool = False) -> dict:
    """One verified optimization (or its record with ``reuse``): x by name, objective,
    iterations, simulations, verdicts and wall time (s).  With ``resume``, a recorded optimum that
    did not pass the verification is optimized again from its x (the case's verification rounds
    then tighten the failing bounds); iterations, simulations and wall time add up."""
    record = out / f"{name}.json"
    before = json.loads(record.read_text()) if record.exists() else None
    if before is not None and (reuse or (resume and before["verified"])):
        return dict(before)
    start = before["x"] if resume and before is not None else None
    t0 = time.perf_counter()
    res = dynsens.optimize(case, out / f"{name}_opt.h5", overwrite=True, maxiter=maxiter, x0=start)
    rec = {"x": dict(zip(res.design_names, map(float, res.x))), "fun": float(res.fun), "nit": int(res.nit),
           "nfev": int(res.nfev), "success": bool(res.success), "feasible": bool(res.feasible),
           "verified": res.verified, "wall_s": time.perf_counter() - t0, "message": res.message}
    rec.update(round_totals(out / f"{name}_opt.h5"))
    if start is not None:
        rec.update(nit=rec["nit"] + before["nit"], nfev=rec["nfev"] + before["nfev"],
                   wall_s=rec["wall_s"] + before["wall_s"], resumed_from=before)
    record.write_text(json.dumps(rec, indent=1))
    return rec


def round_totals(path: Path) -> dict[str, int]:
    """Iterations and simulations summed over the verification rounds recorded in ``path``
    (``/verification/rounds``: the optimization re-run with tightened bounds); empty for one round
    (the result's own counts are then the totals)."""
    import h5py
    with h5py.File(path, "r") as f:
        if "verification/rounds" not in f:
            return {}
        r = f["verification/rounds"]
        return {"nit": int(np.sum(r["nit"][()])), "nfev": int(np.sum(r["n_sim"][()])), "rounds": int(len(r["nit"][()]))}


def evaluate(x: dict[str, float]) -> dict[str, float]:
    """The flexible weir at design ``x`` (every variable of the shipped case), whole cycle,
    without sensitivities: the table's quantities."""
    sim = dynsens.simulate(FLEXIBLE, [x[v["name"]] for v in flexible_raw()["design"]["variables"]],
                           sensitivity__enabled=False, output__history=["q"])
    q, v = sim.run.quantities, sim.values
    row = {"rack_mass_t": v["rack_mass"], "peak_joint_force_N": max(float(np.max(q[j].value)) for j in JOINTS),
           "peak_pressure_MPa": float(np.max(q["pressure_1"].value)), "t_F_s": v["t_F"], "f_N": v["f"],
           "max_stress_ratio": max(v[f"stress_{b}"] for b in BARS),
           "max_buckling_ratio": max(v[f"buckling_{b}"] for b in BARS)}
    row.update({g: v[g] for g in PAPER})
    row["feasible"] = bool(all(v[g] <= 1e-6 for g in PAPER) and all(v[r] <= 1.0 + 1e-6 for r in MEMBER_RATIOS))
    return {k: (float(val) if not isinstance(val, bool) else val) for k, val in row.items()}


FORMAT = {"rack_mass_t": ("rack mass [t]", "{:.4f}"), "peak_joint_force_N": ("peak joint force [N]", "{:,.0f}"),
          "peak_pressure_MPa": ("peak pressure p1 [MPa]", "{:.2f}"), "t_F_s": ("cleaning time t_F [s]", "{:.3f}"),
          "f_N": ("objective f [N]", "{:,.0f}"), "max_stress_ratio": ("largest stress ratio", "{:.3f}"),
          "max_buckling_ratio": ("largest buckling ratio", "{:.3f}"), "g1": ("g1", "{:+.4f}"),
          "g2": ("g2", "{:+.4f}"), "g3": ("g3", "{:+.4f}"), "feasible": ("feasible", "{}")}


def table(rows: dict[str, dict], runs: dict[str, dict], fmt: dict[str, tuple[str, str]] = FORMAT) -> str:
    """The markdown tables: the designs (columns) with the quantities ``fmt`` (key -> label,
    format), and the optimizations' costs (iterations and simulations summed over their
    verification rounds)."""
    names = list(rows)
    lines = ["| | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]
    for key, (label, f) in fmt.items():
        lines.append(f"| {label} | " + " | ".join(f.format(rows[n][key]) for n in names) + " |")
    lines += ["", "| optimization | rounds | iterations | simulations | wall [s] | feasible | verified |",
              "|---|---|---|---|---|---|---|"]
    for name, r in runs.items():
        lines.append(f"| {name} | {r.get('rounds', 1)} | {r['nit']} | {r['nfev']} | {r['wall_s']:.0f} | "
                     f"{r['feasible']} | {r['verified']} |")
    return "\n".join(lines)


def write_tables(out: Path, text: str, record: dict) -> None:
    """Print the markdown ``text`` and write it to OUT/table.md, ``record`` to OUT/table.json."""
    print(text)
    (out / "table.md").write_text(text + "\n")
    (out / "table.json").write_text(json.dumps(record, indent=1))


def bar_panels(rows: dict[str, dict], panels: tuple[tuple[str, str, float], ...], title: str, path: Path,
               marks: dict[str, float] | None = None) -> None:
    """One panel per (key, label, divisor) of ``panels``, one bar per design of ``rows``; a dashed
    line at ``marks[key]`` where given (a bound); written atomically to ``path``."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    names = list(rows)
    fig, axes = plt.subplots(1, len(panels), figsize=(3.4 * len(panels) + 0.4, 3.8))
    for ax, (key, label, divisor) in zip(axes, panels):
        ax.bar(range(len(names)), [rows[n][key] / divisor for n in names],
               color=["0.6", "tab:blue", "tab:orange", "tab:green"][:len(names)])
        ax.set_xticks(range(len(names)), names, rotation=30, ha="right", fontsize=8)
        ax.set_title(label, fontsize=10)
        if marks and key in marks:
            ax.axhline(marks[key], color="k", lw=0.8, ls="--")
    fig.suptitle(title)
    fig.tight_layout()
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)


def plot(rows: dict[str, dict], path: Path) -> None:
    """Four panels (rack mass, peak joint force, peak pressure, cleaning time), one bar per design;
    the paper's g3 (t_F <= 8 s) dashed."""
    bar_panels(rows, (("rack_mass_t", "rack mass [t]", 1.0), ("peak_joint_force_N", "peak joint force [kN]", 1e3),
                      ("peak_pressure_MPa", "peak pressure p1 [MPa]", 1.0), ("t_F_s", "cleaning time t_F [s]", 1.0)),
               "Weir with a flexible rack: start, rigid optimum, sequential sizing, joint optimum", path,
               marks={"t_F_s": 8.0})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "virtuous_circle")
    ap.add_argument("--reuse", action="store_true", help="take optimizations recorded in OUT")
    ap.add_argument("--resume", action="store_true",
                    help="optimize a recorded optimum that failed its verification again, from its x")
    ap.add_argument("--maxiter", type=int, default=None, help="iteration limit of each optimization")
    ap.add_argument("--figure", type=Path, default=FIGURE)
    ap.add_argument("--only", action="append", choices=("joint", "rigid", "sizing"),
                    help="run (or reuse) only these optimizations and stop (repeatable; sizing needs rigid)")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    raw = flexible_raw()
    start = {v["name"]: float(v["value"]) for v in raw["design"]["variables"]}
    wanted = args.only or ["joint", "rigid", "sizing"]
    runs = {}
    if "joint" in wanted:
        runs["joint"] = optimize("joint", FLEXIBLE, args.out, args.reuse, args.maxiter, args.resume)
    if "rigid" in wanted or "sizing" in wanted:
        runs["rigid"] = optimize("rigid", RIGID, args.out, args.reuse or "rigid" not in wanted, args.maxiter,
                                 args.resume)
    if "sizing" in wanted:
        geometry = {k: runs["rigid"]["x"][k] for k in GEOMETRY}
        runs["sizing"] = optimize("sizing", with_fixed(raw, geometry), args.out, args.reuse, args.maxiter,
                                  args.resume)
    if args.only:
        return
    geometry = {k: runs["rigid"]["x"][k] for k in GEOMETRY}
    designs = {"start": start,
               "rigid optimum": {**start, **geometry},
               "rigid, then sized": {**start, **geometry, **runs["sizing"]["x"]},
               "joint optimum": runs["joint"]["x"]}
    rows = {name: evaluate(x) for name, x in designs.items()}
    write_tables(args.out, table(rows, runs), {"designs": designs, "rows": rows, "runs": runs})
    plot(rows, args.figure)


if __name__ == "__main__":
    main()
