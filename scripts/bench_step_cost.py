"""The cost of a step: dynsens beside the minimal loop of ``yardstick_chain.py``, in one run.

Duffing chain of BENCHMARKS.md (Newmark β = ¼, γ = ½, Δt = 1 ms, ``--steps`` steps) at
N = 10, 100, 1000: dynsens primal and primal + gradient (the case's forward partials, 4 design
variables, no histories) against the yardstick with SuperLU and with LAPACK's tridiagonal LU,
primal and primal + gradient.  CPU seconds (``time.process_time``; BLAS is single-threaded),
medians of ``--repeats`` interleaved repeats, every variant run once before timing (numba
compilation and first-call costs excluded).  Before timing, the yardstick's gradient is checked
against dynsens' (complex-step partials) at each N.
With ``--weir`` the shipped weir (cases/tyrolean_weir.yaml, its own settings and partials) is
timed in the same run, primal and primal + gradient (the issue's target: the latter under 2.5 s).
Usage: python scripts/bench_step_cost.py [--sizes 10 100 1000] [--steps 2000] [--repeats 5] [--weir]
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from typing import Any, Callable

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

import dynsens  # noqa: E402
import yardstick_chain as ys  # noqa: E402

GRADIENT_TOLERANCE = 1e-9   # relative to the largest gradient entry


def variants(n: int, steps: int) -> dict[str, Callable[[], Any]]:
    """The timed runs for one chain size, by label."""
    case = ys.dynsens_case(n, steps)
    return {
        "dynsens primal": lambda: dynsens.run_case(case, sensitivities=False, history=()),
        "dynsens + gradient": lambda: dynsens.run_case(case, sensitivities=True, history=()),
        "SuperLU primal": lambda: ys.run(n, steps, solver="superlu", gradient=False),
        "SuperLU + gradient": lambda: ys.run(n, steps, solver="superlu", gradient=True),
        "tridiagonal primal": lambda: ys.run(n, steps, solver="tridiagonal", gradient=False),
        "tridiagonal + gradient": lambda: ys.run(n, steps, solver="tridiagonal", gradient=True),
    }


def weir_variants() -> dict[str, Callable[[], Any]]:
    """The shipped weir, primal and primal + gradient (its own partials), by label."""
    case = dynsens.load_case(str(HERE.parent / "cases" / "tyrolean_weir.yaml"))
    return {
        "weir primal": lambda: dynsens.run_case(case, sensitivities=False, history=()),
        "weir + gradient": lambda: dynsens.run_case(case, sensitivities=True, history=()),
    }


def measure(runs: dict[str, Callable[[], Any]], repeats: int) -> dict[str, float]:
    """Median CPU seconds per variant, interleaved repeats after one untimed run of each."""
    for fn in runs.values():
        fn()
    times: dict[str, list[float]] = {k: [] for k in runs}
    for _ in range(repeats):
        for label, fn in runs.items():
            t0 = time.process_time()
            fn()
            times[label].append(time.process_time() - t0)
    return {k: statistics.median(v) for k, v in times.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[10, 100, 1000])
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--check-steps", type=int, default=200, help="steps of the gradient check")
    ap.add_argument("--weir", action="store_true", help="time the shipped weir too")
    args = ap.parse_args()
    rows = []
    for n in args.sizes:
        diffs = ys.compare_with_dynsens(n, args.check_steps)
        worst = max(v for k, v in diffs.items() if k.endswith("gradient"))
        if worst > GRADIENT_TOLERANCE:
            sys.exit(f"N = {n}: the yardstick's gradient differs from dynsens' by {worst:.1e}")
        t = measure(variants(n, args.steps), args.repeats)
        rows.append((n, t, worst))
        print(f"N = {n} done (gradient check {worst:.1e})", file=sys.stderr, flush=True)
    print(f"Duffing chain, {args.steps} steps of 1 ms, CPU seconds, medians of {args.repeats}\n")
    print("| N | dynsens primal / + gradient | SuperLU loop | tridiagonal loop | "
          "dynsens ÷ SuperLU | dynsens ÷ tridiagonal | yardstick gradient vs dynsens |")
    print("|---|---|---|---|---|---|---|")
    for n, t, worst in rows:
        print(f"| {n} | {_pair(t, 'dynsens')} | {_pair(t, 'SuperLU')} | {_pair(t, 'tridiagonal')} | "
              f"{_ratio(t, 'SuperLU')} | {_ratio(t, 'tridiagonal')} | {worst:.0e} |")
    if args.weir:
        w = measure(weir_variants(), args.repeats)
        print(f"\nTyrolean weir (cases/tyrolean_weir.yaml), CPU seconds, medians of {args.repeats}: "
              f"primal {w['weir primal']:.3f}, primal + gradient {w['weir + gradient']:.3f}")


def _pair(t: dict[str, float], name: str) -> str:
    return f"{t[name + ' primal']:.3f} / {t[name + ' + gradient']:.3f}"


def _ratio(t: dict[str, float], name: str) -> str:
    """dynsens ÷ the named yardstick, primal / primal + gradient."""
    return (f"{t['dynsens primal'] / t[name + ' primal']:.2f} / "
            f"{t['dynsens + gradient'] / t[name + ' + gradient']:.2f}")

if __name__ == "__main__":
    main()
