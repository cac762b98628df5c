"""Cost of the gradient: (primal + sensitivities) / primal, beside forward differences.

Runs, interleaved and repeated, on one core:
  primal           one simulation without sensitivities
  primal + DDM     one simulation with direct-differentiation sensitivities
  forward FD       m + 1 simulations without sensitivities
and prints median wall times and the ratios to the primal run.  Usage:

    python scripts/bench_sensitivity_cost.py [CASE.yaml ...] [--repeats 7] [--partials forward] [--no-fd]

(``--partials case`` keeps each case's own setting; ``--no-fd`` skips the m + 1 runs, for long cases.)
"""
from __future__ import annotations

import argparse
import platform
import statistics
import time
from pathlib import Path

import numpy as np

import dynsens
from dynsens.warmup import warm_case

ROOT = Path(__file__).resolve().parent.parent


def timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def bench(path: Path, repeats: int, partials: str, fd: bool = True) -> dict:
    # output.quantities=[]: the solver alone, as in the figures of BENCHMARKS.md (recording: bench_records.py)
    over = ["output.history=none", "output.quantities=[]"] + \
        ([] if partials == "case" else [f"sensitivity.partials={partials}"])
    case = dynsens.load_case(path, over)
    m = case.x0.size
    h = 1e-7 * np.maximum(np.abs(case.x0), case.scale)
    runs: dict[str, list[float]] = {"primal": [], "ddm": [], "fd": []}
    warm_case(case)  # numba compilation (real and complex) is never inside a measured time
    dynsens.run_case(case, sensitivities=False)  # warm-up (imports, caches)
    for _ in range(repeats):
        runs["primal"].append(timed(lambda: dynsens.run_case(case, sensitivities=False)))
        runs["ddm"].append(timed(lambda: dynsens.run_case(case, sensitivities=True)))
        if fd:
            runs["fd"].append(timed(lambda: [dynsens.run_case(case, case.x0 + h[j] * np.eye(m)[j],
                                                              sensitivities=False) for j in range(-1, m)]))
    med = {k: statistics.median(v) if v else float("nan") for k, v in runs.items()}
    counters_on = dynsens.run_case(case).counters
    counters_off = dynsens.run_case(case, sensitivities=False).counters
    return {"case": case.name, "m": m, "steps": case.plan.n_steps, **med,
            "ratio_ddm": med["ddm"] / med["primal"], "ratio_fd": med["fd"] / med["primal"],
            "on": counters_on, "off": counters_off}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("cases", nargs="*", default=[str(ROOT / "cases" / "duffing_chain.yaml")])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--partials", default="forward", choices=["forward", "central", "complex", "case"])
    ap.add_argument("--no-fd", action="store_true", help="skip the forward-difference runs")
    args = ap.parse_args()
    print(f"# dynsens {dynsens.__version__}, Python {platform.python_version()}, {platform.machine()}, "
          f"{time.strftime('%Y-%m-%d')}, median of {args.repeats}, partials = {args.partials}\n")
    print("| case | m | steps | primal [s] | primal + DDM [s] | ratio | forward FD (m+1 runs) [s] | ratio |")
    print("|---|---|---|---|---|---|---|---|")
    rows = [bench(Path(c), args.repeats, args.partials, not args.no_fd) for c in args.cases]
    for r in rows:
        print(f"| {r['case']} | {r['m']} | {r['steps']} | {r['primal']:.3f} | {r['ddm']:.3f} | "
              f"{r['ratio_ddm']:.2f} | {r['fd']:.3f} | {r['ratio_fd']:.2f} |")
    print("\nCounters (without / with sensitivities):\n")
    keys = ["newton_iterations", "factorizations", "residual_evaluations", "sensitivity_residual_evaluations",
            "solves", "solve_columns"]
    print("| case | " + " | ".join(keys) + " |")
    print("|---|" + "---|" * len(keys))
    for r in rows:
        print(f"| {r['case']} | " + " | ".join(f"{r['off'][k]} / {r['on'][k]}" for k in keys) + " |")


if __name__ == "__main__":
    main()
