"""Wall time of a design study on 2 local worker processes and on a local Dask cluster.

Runs ``dynsens study`` (library call) on the Tyrolean weir: a Latin hypercube of its four
design variables with values and gradients, alternately with ``--workers 2`` (spawned local
processes) and ``--scheduler`` of a LocalCluster of 2 worker processes with 1 thread each,
``--repeats`` times; medians side by side.  The compiled kernel is compiled (and cached)
by one simulation before any timing; the cluster is started once, before timing (its
start-up is reported apart), as a user would keep a scheduler running.  Also checks that
both variants give the same rows, and keeps the last study file for the plots.

Usage: python scripts/bench_study.py [--n 24] [--repeats 2] [--out results/weir_study.h5]
"""
from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import numpy as np

import dynsens
from dynsens.study import read_study, run_study

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--case", default=str(ROOT / "cases" / "tyrolean_weir.yaml"))
    ap.add_argument("--n", type=int, default=24, help="designs in the Latin hypercube")
    ap.add_argument("--seed", type=int, default=18)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--out", default=str(ROOT / "results" / "weir_study.h5"))
    ap.add_argument("--set", dest="overrides", action="append", default=[],
                    help="case overrides, e.g. a tiny run (integrator.t_end=0.1) to measure the executors' overhead")
    args = ap.parse_args()
    from distributed import LocalCluster
    case = dynsens.load_case(args.case, ["output.history=none"] + args.overrides)
    t0 = time.perf_counter()
    dynsens.run_case(case, history=())            # compiles (or loads) the kernel: never timed
    print(f"warm-up simulation (compilation or cache load): {time.perf_counter() - t0:.1f} s", flush=True)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    t_cluster = time.perf_counter() - t0
    print(f"LocalCluster (2 processes x 1 thread) started in {t_cluster:.1f} s", flush=True)
    times: dict[str, list[float]] = {"2 local processes": [], "local Dask cluster": []}
    sim: dict[str, list[float]] = {k: [] for k in times}
    tables = {}
    try:
        for r in range(args.repeats):
            for variant in times:
                kw = {"workers": 2} if variant.startswith("2 local") else {"scheduler": cluster.scheduler_address}
                t0 = time.perf_counter()
                table = run_study(case, out, f"lhs:{args.n}", gradients=True, seed=args.seed, overwrite=True, **kw)
                wall = time.perf_counter() - t0
                times[variant].append(wall)
                sim[variant].append(float(np.sum(table.wall_time)))
                tables[variant] = table
                print(f"repeat {r}, {variant}: {wall:.1f} s wall, {np.sum(table.wall_time):.1f} s of simulations, "
                      f"{int(table.failed.sum())} failed, workers {sorted(set(table.worker))}", flush=True)
    finally:
        cluster.close()
    a, b = tables.values()
    same = (np.array_equal(a.index, b.index) and np.array_equal(a.values, b.values, equal_nan=True)
            and np.array_equal(a.gradients, b.gradients, equal_nan=True))
    print(f"\nrows identical between the variants: {same}")
    print(f"\n| {case.name}, lhs:{args.n} with gradients, seed {args.seed} | wall time, median of {args.repeats} [s] "
          "| sum of the simulations' wall times [s] | ratio (parallel efficiency x 2) |")
    print("|---|---|---|---|")
    for k in times:
        w, s = statistics.median(times[k]), statistics.median(sim[k])
        print(f"| {k} | {w:.1f} ({', '.join(f'{t:.1f}' for t in times[k])}) | {s:.1f} | {s / w:.2f} |")
    print(f"\nLocalCluster start-up (not in the times above): {t_cluster:.1f} s; CPUs: {os.cpu_count()}; "
          "the machine was shared with other jobs.")
    t = read_study(out)
    print(f"kept: {out} ({len(t.index)} rows, {int(t.failed.sum())} failed)")


if __name__ == "__main__":
    main()
