"""Break-even points of the factorizations dynsens chooses from (dynsens/solver/banded.py).

For band matrices of size n and half-bandwidth w (diagonally dominant, random values), the time
of one factorization plus one solve with 4 right-hand sides (a Newton step and a sensitivity
solve), each the best of ``--repeats`` timings of a loop, side by side:

* dense:   LAPACK getrf / getrs on the n × n array (what dense models did);
* band:    gbtrf / gbtrs through :class:`dynsens.solver.banded.BandPlan`, entries gathered
           from the dense array (dense models) or from the CSC data (sparse models);
* SuperLU: ``splu`` of the CSC matrix with its own ordering (what sparse models did), and with
           the ordering kept from the first factorization (:class:`SparsePlan`).

Prints, per w, the smallest n from which band beats dense, and where band beats SuperLU.
Usage: python scripts/bench_linalg.py [--repeats 5]
"""
from __future__ import annotations

import argparse
import time
from typing import Callable

import dynsens  # noqa: F401  (first: it keeps BLAS single-threaded, as in every run)
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.linalg import lapack

from dynsens.solver.banded import SparsePlan, dense_band_plan


def band_matrix(n: int, w: int, rng: np.random.Generator) -> sp.csc_matrix:
    """Diagonally dominant band matrix, half-bandwidth w."""
    diags = [rng.random(n - abs(d)) for d in range(-w, w + 1)]
    A = sp.diags(diags, list(range(-w, w + 1)), format="csc")
    return sp.csc_matrix(A + sp.identity(n) * (2 * w + 1))


def best(fn: Callable[[], object], repeats: int, loops: int) -> float:
    """Best per-call time (µs) of ``loops`` calls, over ``repeats`` timings."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(loops):
            fn()
        times.append((time.perf_counter() - t0) / loops)
    return 1e6 * min(times)


def measure(n: int, w: int, repeats: int) -> dict[str, float]:
    rng = np.random.default_rng(n * 100 + w)
    A = band_matrix(n, w, rng)
    D = A.toarray()
    b = rng.random((n, 4))
    loops = max(3, int(20000 / n))
    out: dict[str, float] = {}
    if n <= 1000:
        def dense() -> None:
            lu, piv, _ = lapack.dgetrf(D)
            lapack.dgetrs(lu, piv, b)
        out["dense"] = best(dense, repeats, max(1, loops // (1 + n // 100)))
        plan = dense_band_plan(D, {})
        if plan is not None:
            out["band (dense input)"] = best(lambda: plan.factor(plan.entries(D)).solve(b), repeats, loops)
    sp_plan = SparsePlan(A)
    band = sp_plan.band
    if band is not None:
        out["band (sparse input)"] = best(lambda: band.factor(band.entries(A.data)).solve(b), repeats, loops)
    out["SuperLU"] = best(lambda: spla.splu(A).solve(b), repeats, loops)
    sp_plan.superlu(A)
    out["SuperLU kept order"] = best(lambda: sp_plan.superlu(A).solve(b), repeats, loops)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--sizes", type=int, nargs="+", default=[16, 24, 32, 48, 64, 100, 200, 400, 1000, 10000])
    ap.add_argument("--half-bandwidths", type=int, nargs="+", default=[1, 2, 4, 8, 16, 32])
    args = ap.parse_args()
    cols = ["dense", "band (dense input)", "band (sparse input)", "SuperLU", "SuperLU kept order"]
    print("factorization + solve with 4 right-hand sides, µs (best of repeats)\n")
    print("| n | w | " + " | ".join(cols) + " |")
    print("|---" * (len(cols) + 2) + "|")
    for w in args.half_bandwidths:
        for n in args.sizes:
            if 2 * w + 1 > n:
                continue
            r = measure(n, w, args.repeats)
            print(f"| {n} | {w} | " + " | ".join(f"{r[c]:.0f}" if c in r else "–" for c in cols) + " |",
                  flush=True)


if __name__ == "__main__":
    main()
