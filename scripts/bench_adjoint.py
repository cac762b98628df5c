"""Adjoint against direct differentiation, side by side (medians of --repeats, interleaved).

Every measurement is one fresh worker process: a short warm-up run (numba compilation and
first-call costs stay outside the timing), then the timed run; the worker reports its wall time,
its peak resident memory (ru_maxrss) and the run's counters.  Variants of one row are taken in
turn within each repeat, so a busy machine loads them alike.

Rows: the Duffing chain (scripts/bench_peers.py's ``chain_case``) with N = 10, 100, 1000 masses
and m = 4 shared or m = N per-element stiffnesses, responses tip_end, tip_ks, force_ks,
tip_integral (r = 4); the weir (its own responses).  Columns: primal, direct, adjoint, adjoint
under a tight memory budget (checkpointing), and what ``auto`` picks.  ``--src DIR`` adds the
primal and direct runs of another source tree (e.g. an export of the previous commit) to check
that the restructured time loop kept their cost.

Usage: python scripts/bench_adjoint.py [--quick] [--repeats 3] [--steps 500] [--src DIR]
       [--out results/bench_adjoint.json]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

WORKER = r"""
import copy, json, resource, sys, time
from dataclasses import replace
sys.path.insert(0, {scripts!r})
import dynsens
spec = json.loads(sys.argv[1])

def load(t_end):
    if spec["case"] == "weir":
        return dynsens.load_case({weir!r}, spec.get("set", []))
    from bench_peers import chain_case
    return dynsens.load_case_dict(chain_case(spec["n"], t_end, spec["per_element"]), overrides=spec.get("set", []))

def run(case, variant):
    c = copy.copy(case)
    if variant == "primal":
        return dynsens.run_case(c, sensitivities=False)
    if hasattr(c.plan, "method"):
        extra = {{"memory_budget": spec["budget"]}} if variant == "adjoint_tight" else {{}}
        c.plan = replace(c.plan, method="adjoint" if variant.startswith("adjoint") else variant, **extra)
    return dynsens.run_case(c)

warm = load(0.01) if spec["case"] != "weir" else load(None)
if spec["case"] != "weir":
    run(warm, spec["variant"])
case = load(spec["t_end"])
t0 = time.perf_counter()
res = run(case, spec["variant"])
wall = time.perf_counter() - t0
print(json.dumps({{"wall": wall, "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "method": getattr(res, "method", ""), "reason": getattr(res, "method_reason", ""),
                  "counters": res.counters,
                  "grads": {{k: (None if v.gradient is None else [float(g) for g in v.gradient[:8]])
                            for k, v in res.responses.items()}}}}))
"""


def measure(spec: dict, src: Path) -> dict:
    """One worker run of ``spec`` with the package at ``src``."""
    code = WORKER.format(scripts=str(ROOT / "scripts"), weir=str(ROOT / "cases" / "tyrolean_weir.yaml"))
    env = dict(os.environ, PYTHONPATH=str(src), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-c", code, json.dumps(spec)], capture_output=True, text=True,
                         env=env, cwd=str(src))
    if out.returncode:
        raise RuntimeError(f"worker failed for {spec}:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--steps", type=int, default=500, help="steps of the chain runs (dt = 1 ms)")
    ap.add_argument("--quick", action="store_true", help="N = 10 and 100 only, one repeat")
    ap.add_argument("--no-weir", action="store_true")
    ap.add_argument("--src", type=Path, help="another source tree: its primal and direct runs too")
    ap.add_argument("--checkpoint-steps", type=int, metavar="S",
                    help="only the memory row: chain N = 1000, m = N, S steps, adjoint with the default "
                         "budget and with 64 MiB (checkpointing), and the primal")
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "bench_adjoint.json")
    args = ap.parse_args()
    repeats = 1 if args.quick else args.repeats
    t_end = args.steps * 1e-3
    rows = []
    for n in (10, 100) if args.quick else (10, 100, 1000):
        for per in (False, True):
            variants = ["primal", "direct", "adjoint", "auto"]
            if n == 1000 and per:
                variants.insert(3, "adjoint_tight")
            rows.append(({"case": "chain", "n": n, "per_element": per, "t_end": t_end,
                          "budget": 64 * 2**20}, variants))
    if args.checkpoint_steps:
        rows = [({"case": "chain", "n": 1000, "per_element": True, "t_end": args.checkpoint_steps * 1e-3,
                  "budget": 64 * 2**20}, ["primal", "adjoint", "adjoint_tight"])]
    elif not args.quick and not args.no_weir:
        rows.append(({"case": "weir", "t_end": None}, ["primal", "direct", "adjoint"]))
    results = []
    for spec, variants in rows:
        label = "weir" if spec["case"] == "weir" else \
            f"chain N = {spec['n']}, m = {spec['n'] if spec['per_element'] else 4}"
        runs: dict[str, list[dict]] = {v: [] for v in variants}
        others: dict[str, list[dict]] = {v: [] for v in ("primal", "direct")} if args.src else {}
        for _ in range(repeats):
            for v in variants:
                runs[v].append(measure({**spec, "variant": v}, ROOT))
            for v in others:
                others[v].append(measure({**spec, "variant": v}, args.src))
        med = {v: statistics.median(r["wall"] for r in rs) for v, rs in runs.items()}
        rss = {v: max(r["rss_mb"] for r in rs) for v, rs in runs.items()}
        line = {"row": label, "median_s": med, "peak_rss_mb": rss,
                "auto": runs["auto"][0]["method"] if "auto" in runs else "",
                "auto_reason": runs["auto"][0]["reason"] if "auto" in runs else "",
                "adjoint_counters": runs["adjoint"][0]["counters"],
                "tight_counters": runs["adjoint_tight"][0]["counters"] if "adjoint_tight" in runs else None,
                "src_median_s": {v: statistics.median(r["wall"] for r in rs) for v, rs in others.items()}}
        results.append(line)
        p = med["primal"]
        print(f"{label}: primal {p:.2f} s | " + (f"direct {med['direct']:.2f} s ({med['direct'] / p:.1f}x) | "
                                                if "direct" in med else "") +
              f"adjoint {med['adjoint']:.2f} s ({med['adjoint'] / p:.1f}x, {rss['adjoint']:.0f} MB)"
              + (f" | adjoint, 64 MiB budget {med['adjoint_tight']:.2f} s ({rss['adjoint_tight']:.0f} MB, "
                 f"{line['tight_counters']['recomputed_steps']} recomputed steps)" if "adjoint_tight" in med else "")
              + (f" | auto: {line['auto']} ({line['auto_reason']})" if line["auto"] else "")
              + (" | other tree: " + ", ".join(f"{v} {t:.2f} s" for v, t in line["src_median_s"].items())
                 if others else ""), flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=1))
    print(f"written: {args.out}")


if __name__ == "__main__":
    main()
