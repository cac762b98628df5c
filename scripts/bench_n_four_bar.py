"""The N-four-bar (IFToMM A02) on the dense and the sparse multibody path, side by side.

Per-step cost: for each N, the same case with ``model.linear_algebra`` dense and sparse, primal
and with the two design sensitivities (crank mass m and initial speed v0, direct mode, complex
partials), run over two short horizons in alternation; the marginal cost per step is the
difference of the two run times over the difference of the step counts (the assembly and the
initial design derivative, paid once per run, drop out).  Medians over ``--repeats``.

``--projection MODE``: every run with ``model.projection`` in that mode (state or output), for
the cost of the projection and of its derivative map.

``--full``: the benchmark itself once, N = 40 over 20 s at Δt = 1 ms with both sensitivities,
on the sparse path (wall time, crossings of the singular configuration, energy drift).

Run: python scripts/bench_n_four_bar.py [--n 2 5 10 20 40] [--repeats 3] [--projection MODE] [--full]
(dynsens is imported before numpy, so that its single-threaded BLAS setting takes effect.)
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import dynsens  # first: it sets BLAS single-threaded before numpy loads  # noqa: I001
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from make_n_four_bar import n_four_bar  # noqa: E402


def _args() -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[2, 5, 10, 20, 40], help="numbers of loops")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--short", type=float, nargs=2, default=[0.05, 0.15], help="the two horizons, s")
    ap.add_argument("--full", action="store_true", help="also the 40-loop, 20 s benchmark (sparse)")
    ap.add_argument("--full-only", action="store_true", help="only the 40-loop, 20 s benchmark")
    ap.add_argument("--t-end", type=float, default=20.0, help="horizon of --full, s")
    ap.add_argument("--projection", choices=("state", "output"), help="run with model.projection in this mode")
    return ap.parse_args()


ARGS = _args()


def _case(n: int, t_end: float, la: str) -> "dynsens.Case":
    raw = n_four_bar(n, t_end=t_end)
    raw["model"]["linear_algebra"] = la
    if ARGS.projection:
        raw["model"]["projection"] = {"mode": ARGS.projection}
    return dynsens.load_case_dict(raw, source=f"n_four_bar_{n}.yaml")


def per_step(n: int, repeats: int, horizons: tuple[float, float]) -> dict[tuple[str, bool], float]:
    """Median marginal seconds per step for (linear algebra, sensitivities)."""
    cases = {(la, t): _case(n, t, la) for la in ("dense", "sparse") for t in horizons}
    steps = round((horizons[1] - horizons[0]) / 1e-3)
    for c in cases.values():                     # compile and warm every path once
        dynsens.run_case(c, sensitivities=True)
    out: dict[tuple[str, bool], list[float]] = {}
    for _ in range(repeats):
        for sens in (False, True):
            for la in ("dense", "sparse"):       # side by side, in alternation
                wall = []
                for t in horizons:
                    t0 = time.perf_counter()
                    res = dynsens.run_case(cases[(la, t)], sensitivities=sens)
                    wall.append(time.perf_counter() - t0)
                    assert res.status == "completed", res.message
                out.setdefault((la, sens), []).append((wall[1] - wall[0]) / steps)
    return {k: float(np.median(v)) for k, v in out.items()}


def full_run(t_end: float) -> None:
    """The 40-loop benchmark over t_end with both sensitivities on the sparse path."""
    case = _case(40, t_end, "sparse")
    t0 = time.perf_counter()
    res = dynsens.run_case(case, sensitivities=True, history=("q",))
    wall = time.perf_counter() - t0
    e = res.history["q"][:, 3:7]
    theta = np.unwrap(2.0 * np.arctan2(e[:, 3], e[:, 0]))
    crossings = int(np.count_nonzero(np.diff(np.sign(np.sin(theta)))))
    print(f"N = 40, {t_end:g} s, dt = 1 ms, 2 design sensitivities, sparse: {res.status} in {wall:.1f} s "
          f"({res.counters['steps']} steps, {res.counters['newton_iterations']} Newton iterations, "
          f"{res.counters['step_cuts']} step cuts, {crossings} crossings of the flat pose); "
          f"max ‖Φ‖ = {res.monitors['constraint_position'].max():.2e}")
    for name, r in res.responses.items():
        print(f"  {name} = {r.value:.10g}, gradient {np.array2string(np.asarray(r.gradient), precision=6)}")


def main() -> None:
    print(f"BLAS threads: {os.environ.get('OPENBLAS_NUM_THREADS', 'default')}; horizons {ARGS.short} s; "
          f"medians of {ARGS.repeats}; projection: {ARGS.projection or 'off'}; dynsens from "
          f"{Path(dynsens.__file__).parent}")
    if not ARGS.full_only:
        print("| N | n_z | dense primal | sparse primal | dense + sens. | sparse + sens. | (ms per step)")
        print("|---|---|---|---|---|---|")
        for n in ARGS.n:
            r = per_step(n, ARGS.repeats, tuple(ARGS.short))    # type: ignore[arg-type]
            n_z = 28 * n + 13
            print(f"| {n} | {n_z} | {1e3 * r[('dense', False)]:.2f} | {1e3 * r[('sparse', False)]:.2f} | "
                  f"{1e3 * r[('dense', True)]:.2f} | {1e3 * r[('sparse', True)]:.2f} |", flush=True)
    if ARGS.full or ARGS.full_only:
        full_run(ARGS.t_end)


if __name__ == "__main__":
    main()
