"""Cost of recording a case's quantities (``output.quantities``): the same run with and without.

Runs ``run_case`` interleaved and repeated in one process (after a warm-up of both variants, so
compilation is never timed), with and without sensitivities, and prints the median wall times
and their ratio.  Usage:

    python scripts/bench_records.py [CASE.yaml ...] [--repeats 3]
"""
from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import dynsens

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="*", default=[str(ROOT / "cases" / "tyrolean_weir.yaml")])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    print("| case | sensitivities | quantities | without recording [s] | with [s] | ratio |")
    print("|---|---|---|---|---|---|")
    for path in args.cases:
        case = dynsens.load_case(path, ["output.history=none"])
        for sens in (False, True):
            for rec in (False, True):                      # warm-up: compile both paths
                dynsens.run_case(case, sensitivities=sens, record=rec)
            times: dict[bool, list[float]] = {False: [], True: []}
            for _ in range(args.repeats):
                for rec in (False, True):
                    t0 = time.perf_counter()
                    dynsens.run_case(case, sensitivities=sens, record=rec)
                    times[rec].append(time.perf_counter() - t0)
            off, on = statistics.median(times[False]), statistics.median(times[True])
            print(f"| {Path(path).stem} | {'yes' if sens else 'no'} | {len(case.quantities)} | "
                  f"{off:.3f} | {on:.3f} | {on / off:.3f} |", flush=True)


if __name__ == "__main__":
    main()
