"""CPU time (s) of the flexible weir (cases/tyrolean_weir_flexible.yaml): primal, primal + direct
and primal + adjoint sensitivities (6 design variables, 20 responses), each run once untimed first
(numba compilation and first-call costs excluded), then ``--repeats`` timed runs interleaved across
the modes; medians; for BENCHMARKS.md.

Usage: python scripts/bench_weir_flexible.py [--t-end 0.5] [--repeats 5]
(``--t-end 0`` times the whole cycle, until the event E1 ends it.)"""
from __future__ import annotations

import argparse
import copy
import statistics
import time
from dataclasses import replace
from pathlib import Path

import yaml

import dynsens
from dynsens.case.load import load_case_dict

CASE = Path(__file__).resolve().parents[1] / "cases" / "tyrolean_weir_flexible.yaml"


def cases(t_end: float) -> dict[str, dynsens.Case]:
    """The three runs by mode; ``t_end`` 0 keeps the case's window."""
    raw = yaml.safe_load(CASE.read_text(encoding="utf-8"))
    if t_end > 0:
        raw["integrator"]["t_end"] = t_end
    raw.pop("optimization")
    raw["output"]["history"] = "none"
    out = {}
    for mode in ("primal", "direct", "adjoint"):
        r = copy.deepcopy(raw)
        r["sensitivity"]["enabled"] = mode != "primal"
        case = load_case_dict(r)
        out[mode] = replace(case, plan=replace(case.plan, method="adjoint")) if mode == "adjoint" else case
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--t-end", type=float, default=0.5)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    runs = cases(args.t_end)
    times: dict[str, list[float]] = {m: [] for m in runs}
    steps = {}
    for mode, case in runs.items():                 # untimed: compilation, first calls
        steps[mode] = dynsens.run_case(case).counters["steps"]
    for _ in range(args.repeats):
        for mode, case in runs.items():
            t0 = time.process_time()
            dynsens.run_case(case)
            times[mode].append(time.process_time() - t0)
    med = {m: statistics.median(t) for m, t in times.items()}
    for mode, t in times.items():
        print(f"{mode:8s} steps {steps[mode]:6d}  CPU s {[round(x, 2) for x in t]}  median {med[mode]:.2f}")
    d, a, p = med["direct"], med["adjoint"], med["primal"]
    print(f"direct / primal {d / p:.2f}, adjoint / primal {a / p:.2f}, adjoint / direct {a / d:.2f}")


if __name__ == "__main__":
    main()
