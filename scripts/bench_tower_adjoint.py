"""Gradient cost of the 204-member tower (cases/tower_sizing.yaml): primal, direct
differentiation and the adjoint, side by side in one process (medians of --repeats,
interleaved; a warm-up run of each first, so no compilation or first-call cost is timed).

Usage: python scripts/bench_tower_adjoint.py [--repeats 3] [--partials forward]
"""
from __future__ import annotations

import argparse
import copy
import statistics
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import dynsens

CASE = Path(__file__).resolve().parent.parent / "cases" / "tower_sizing.yaml"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--partials", default="forward", choices=("forward", "central", "complex"))
    args = ap.parse_args()
    case = dynsens.load_case(CASE, [f"sensitivity.partials={args.partials}"])

    def variant(method: str | None) -> dynsens.Case:
        c = copy.copy(case)
        c.plan = replace(case.plan, sensitivities=method is not None, method=method or "direct")
        return c
    variants = {"primal": variant(None), "direct": variant("direct"), "adjoint": variant("adjoint")}
    times: dict[str, list[float]] = {k: [] for k in variants}
    results = {}
    for name, c in variants.items():                      # warm-up
        results[name] = dynsens.run_case(c, history=())
    for _ in range(args.repeats):
        for name, c in variants.items():
            t0 = time.perf_counter()
            results[name] = dynsens.run_case(c, history=())
            times[name].append(time.perf_counter() - t0)
    primal = statistics.median(times["primal"])
    worst = max(float(np.max(np.abs(results["adjoint"].responses[n].gradient - r.gradient))
                      / max(float(np.max(np.abs(r.gradient))), 1e-300))
                for n, r in results["direct"].responses.items() if r.gradient is not None)
    m, steps = case.x0.size, results["primal"].counters["steps"]
    print(f"tower_sizing: m = {m} design variables, {len(results['direct'].responses)} responses, "
          f"{steps} steps, partials {args.partials}, medians of {args.repeats}")
    print("| run | wall time [s] | / primal |")
    print("|---|---|---|")
    for name in variants:
        med = statistics.median(times[name])
        print(f"| {name} | {med:.3f} | {med / primal:.2f} |")
    print(f"largest relative difference adjoint vs direct over the gradients: {worst:.2e}")
    auto = dynsens.run_case(variant("auto"), history=())
    print(f"auto picks {auto.method}: {auto.method_reason}")


if __name__ == "__main__":
    main()
