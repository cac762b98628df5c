"""A sparse structural model with 10 000 DOFs and m = 10 design variables, 1 000 steps with
sensitivities (the issue's target: under a minute).  Median of --repeats runs.

The model is the Duffing chain of scripts/make_cases.py with N = 10 000 masses; its linear
stiffness is split into 10 design variables, each shared by 1 000 consecutive springs.
Usage: python scripts/bench_large.py [--n 10000] [--steps 1000] [--repeats 3]
"""
from __future__ import annotations

import argparse
import statistics
import time

import dynsens
from make_cases import duffing_chain


def large_case(n: int, steps: int, groups: int = 10) -> dynsens.Case:
    """The chain with ``groups`` stiffness design variables, dt = 1 ms, ``steps`` steps."""
    d = duffing_chain(n, t_end=steps * 1e-3)
    d["design"]["variables"] = [{"name": f"k_{g}", "value": 1000.0, "lower": 100.0, "upper": 1e4}
                                for g in range(groups)]
    springs = [el for el in d["model"]["elements"] if el["type"] == "spring"]
    for i, el in enumerate(springs):
        el["k"] = f"k_{i * groups // len(springs)}"
        el["k3"] = 1.0e6
    for el in d["model"]["elements"]:
        if el["type"] == "mass":
            el["mass"] = 1.0
        if el["type"] == "damper":
            el["c"] = 2.0
    d["output"] = {"history": "none"}
    d["responses"] = [r for r in d["responses"] if r["name"] in ("tip_end", "tip_ks")]
    return dynsens.load_case_dict(d)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=10000)
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    case = large_case(args.n, args.steps)
    print(f"n = {case.model.traits.n_q} DOFs, sparse = {case.model.traits.sparse}, m = {case.x0.size}, "
          f"{case.plan.n_steps} steps")
    times = {True: [], False: []}
    for _ in range(args.repeats):
        for sens in (False, True):
            t0 = time.perf_counter()
            res = dynsens.run_case(case, sensitivities=sens)
            times[sens].append(time.perf_counter() - t0)
    print(f"primal: median {statistics.median(times[False]):.1f} s; primal + sensitivities: median "
          f"{statistics.median(times[True]):.1f} s (runs {', '.join(f'{t:.1f}' for t in times[True])})")
    print("counters (with sensitivities):", res.counters)


if __name__ == "__main__":
    main()
