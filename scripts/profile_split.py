"""Where a run's time goes: Python (with numpy's calls), compiled code (numba) and LAPACK called
from Python — the per-step profile split of issue 35, for the P1 Duffing chain at N = 10 and
N = 1000 (2 000 steps, four design variables) and the shipped weir, primal and primal + gradient.

    python scripts/profile_split.py                 # the three models, median of 3 runs each
    PYTHONPATH=/path/to/other/tree python scripts/profile_split.py   # the same for another tree

How it splits: every call from Python into a numba-compiled function goes through its
dispatcher's ``__call__``; the script times those calls (outermost only).  The LAPACK routines
dynsens calls from Python (getrf/getrs, gbtrf/gbtrs, gttrf/gttrs through
``scipy.linalg.lapack.get_lapack_funcs``, and SuperLU's ``splu`` with its solves) are wrapped the
same way.  LAPACK called from inside compiled code (the compiled steps' dgesv, dgetrs) counts as
compiled.  Python is the rest of the run's wall time: the time loop, the model's Python, numpy's
small-array calls and their allocation.  The wrappers cost about a microsecond per call; the
table shows the run's time without them beside the instrumented one, so that cost is visible.

Each configuration runs once untimed first, so compilation is never in a reported time.
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Any, Callable

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))

import dynsens  # noqa: E402  (first: it sets BLAS single-threaded before numpy loads)
from bench_targets import p1_case  # noqa: E402

WEIR = ROOT / "cases" / "tyrolean_weir.yaml"


class Split:
    """Wall time spent in compiled calls and in LAPACK calls made from Python (s), and their counts."""

    def __init__(self) -> None:
        self.reset()
        self.active = False

    def reset(self) -> None:
        """Zero the times and counts (before a timed run)."""
        self.compiled = self.lapack = 0.0
        self.compiled_calls = self.lapack_calls = 0
        self.depth = 0          # > 0 inside a timed call: nested calls are not timed twice

    def timed(self, kind: str, call: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        """``call(*args, **kwargs)``, its wall time added to ``kind`` when outermost."""
        if not self.active or self.depth:
            return call(*args, **kwargs)
        self.depth += 1
        t0 = time.perf_counter()
        try:
            return call(*args, **kwargs)
        finally:
            dt = time.perf_counter() - t0
            self.depth -= 1
            if kind == "compiled":
                self.compiled += dt
                self.compiled_calls += 1
            else:
                self.lapack += dt
                self.lapack_calls += 1


SPLIT = Split()


class _TimedSuperLU:
    """SuperLU's factor, its solves timed as LAPACK (the sparse direct solver called from Python)."""

    def __init__(self, lu: Any) -> None:
        self._lu = lu

    def solve(self, rhs: Any, trans: str = "N") -> Any:
        return SPLIT.timed("lapack", self._lu.solve, rhs, trans)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._lu, name)


def instrument() -> None:
    """Wrap numba's dispatcher calls and the LAPACK entry points dynsens takes, before any run."""
    import scipy.linalg as sla
    import scipy.sparse.linalg as spla
    from numba.core.registry import CPUDispatcher

    base_call = CPUDispatcher.__call__

    def dispatcher_call(self: Any, *args: Any, **kwargs: Any) -> Any:
        return SPLIT.timed("compiled", base_call, self, *args, **kwargs)

    CPUDispatcher.__call__ = dispatcher_call  # type: ignore[method-assign]

    get_funcs = sla.lapack.get_lapack_funcs

    def wrap(f: Any) -> Any:
        def call(*args: Any, **kwargs: Any) -> Any:
            return SPLIT.timed("lapack", f, *args, **kwargs)
        call.typecode = getattr(f, "typecode", None)  # type: ignore[attr-defined]
        return call

    def timed_get_funcs(names: Any, arrays: Any = (), dtype: Any = None, **kw: Any) -> Any:
        funcs = get_funcs(names, arrays, dtype, **kw)
        return tuple(wrap(f) for f in funcs) if isinstance(funcs, (tuple, list)) else wrap(funcs)

    sla.lapack.get_lapack_funcs = timed_get_funcs
    splu = spla.splu
    spla.splu = lambda *a, **k: _TimedSuperLU(SPLIT.timed("lapack", splu, *a, **k))
    # the routines dynsens looked up before this point are looked up again, wrapped
    from dynsens.solver import banded, linalg
    banded._LAPACK.clear()
    linalg._LAPACK.clear()


def configurations(ns: list[int], steps: int, weir: bool) -> dict[str, Callable[[], Any]]:
    """The runs to split, by label."""
    runs: dict[str, Callable[[], Any]] = {}
    for n in ns:
        case = p1_case(n, steps)
        runs[f"P1 N = {n}, primal"] = lambda c=case: dynsens.run_case(c, sensitivities=False, history=())
        runs[f"P1 N = {n}, + gradient (direct)"] = lambda c=case: dynsens.run_case(c, sensitivities=True, history=())
    if weir:
        case = dynsens.load_case(WEIR, ["sensitivity.method=direct"])
        runs["weir, primal"] = lambda c=case: dynsens.run_case(c, sensitivities=False, history=())
        runs["weir, + gradient (direct)"] = lambda c=case: dynsens.run_case(c, sensitivities=True, history=())
    return runs


def split_of(run: Callable[[], Any], repeats: int) -> dict[str, float]:
    """Median wall times of ``run``: uninstrumented, instrumented, and its compiled / LAPACK /
    Python shares; calls into compiled code and LAPACK per run."""
    plain, total, comp, lap, ncomp, nlap = [], [], [], [], [], []
    for _ in range(repeats):
        SPLIT.active = False
        t0 = time.perf_counter()
        run()
        plain.append(time.perf_counter() - t0)
        SPLIT.reset()
        SPLIT.active = True
        t0 = time.perf_counter()
        run()
        total.append(time.perf_counter() - t0)
        SPLIT.active = False
        comp.append(SPLIT.compiled)
        lap.append(SPLIT.lapack)
        ncomp.append(SPLIT.compiled_calls)
        nlap.append(SPLIT.lapack_calls)
    med = statistics.median
    t, c, la = med(total), med(comp), med(lap)
    return {"plain": med(plain), "total": t, "compiled": c, "lapack": la, "python": t - c - la,
            "compiled_calls": med(ncomp), "lapack_calls": med(nlap)}


def cpu_model() -> str:
    """The processor's model name (Linux), else the platform's machine type."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.machine()


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, nargs="+", default=[10, 1000], help="chain sizes (default 10 1000)")
    ap.add_argument("--steps", type=int, default=2000, help="steps of the chain runs (default 2000, P1)")
    ap.add_argument("--no-weir", action="store_true", help="leave the weir out")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    instrument()
    runs = configurations(args.n, args.steps, not args.no_weir)
    for run in runs.values():       # compile (and fill every cache) outside the timed runs
        run()
    print(f"dynsens from {Path(dynsens.__file__).parent}, kernel {os.environ.get('DYNSENS_KERNEL', 'compiled')}")
    print(f"{cpu_model()}, {os.cpu_count()} cores, load "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())} at the start")
    print("\n| run | wall, plain [s] | wall, instrumented [s] | Python | compiled | LAPACK from Python "
          "| calls into compiled / LAPACK |")
    print("|---|---|---|---|---|---|---|")
    for label, run in runs.items():
        s = split_of(run, args.repeats)
        share = {k: 100 * s[k] / s["total"] for k in ("python", "compiled", "lapack")}
        print(f"| {label} | {s['plain']:.3f} | {s['total']:.3f} | {share['python']:.0f} % | "
              f"{share['compiled']:.0f} % | {share['lapack']:.0f} % | "
              f"{s['compiled_calls']:.0f} / {s['lapack_calls']:.0f} |", flush=True)
    print(f"\nload {' '.join(f'{x:.2f}' for x in os.getloadavg())} at the end; medians of {args.repeats}")


if __name__ == "__main__":
    main()
