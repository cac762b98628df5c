"""Cost of the run-time checks: the runaway monitor and the sensitivities' non-finite check.

Runs shipped cases with the checks on and off (off: the monitor's ``observe`` and the direct
mode's block check replaced by no-ops), the variants taken in turn within each repeat so that a
busy machine loads them alike; a warm-up run first keeps numba compilation out of the timing.
Prints the median wall time per step of each variant and their difference.

Usage: python scripts/bench_runtime_checks.py [--repeats 7] [--cases sdof_step duffing_chain]
"""
from __future__ import annotations

import argparse
import statistics
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--cases", nargs="+", default=["sdof_step", "duffing_chain", "slider_crank"])
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    from dynsens import runaway
    from dynsens.case.load import load_case
    from dynsens.derivatives import direct
    from dynsens.simulation import run_case

    on = (runaway.RunawayMonitor.observe, direct.check_block)

    def switch(enabled: bool) -> None:
        runaway.RunawayMonitor.observe = on[0] if enabled else (lambda self, t, step, s: None)  # type: ignore
        direct.check_block = on[1] if enabled else (lambda *a: None)  # type: ignore

    print(f"{'case':16s} {'steps':>7s} {'checks on':>12s} {'checks off':>12s} {'difference':>12s}  (us/step)")
    for name in args.cases:
        case = load_case(ROOT / "cases" / f"{name}.yaml")
        run_case(case)                                    # warm-up (compilation, first calls)
        times: dict[bool, list[float]] = {True: [], False: []}
        steps = 1
        for _ in range(args.repeats):
            for enabled in (True, False):
                switch(enabled)
                t0 = time.perf_counter()
                res = run_case(case)
                times[enabled].append(time.perf_counter() - t0)
                steps = max(1, res.counters["steps"])
        switch(True)
        a, b = (statistics.median(times[e]) / steps * 1e6 for e in (True, False))
        print(f"{name:16s} {steps:7d} {a:12.1f} {b:12.1f} {a - b:12.1f}")


if __name__ == "__main__":
    main()
