"""Constraint stabilization on the IFToMM simple pendulum: Baumgarte (α, β) against Δt, and projection.

The pendulum of cases/pendulum_projection.yaml (1 kg point mass, massless 1 m rod, g = 9.81,
released at rest with the rod horizontal) over 10 s at each Δt, without stabilization, with
Baumgarte α = β (critically damped constraint error: Φ̈ + 2αΦ̇ + α²Φ = 0) and with projection
(modes output and state).  Per run: the largest ‖Φ‖ (m) and the largest position error (m)
against the angle's equation integrated by DOP853 at rtol 1e-13.  Prints a Markdown table.

    python scripts/constraint_study.py [--dt 0.005,0.002] [--t-end 10] [--timing 3]

``--timing N`` adds wall times (median of N, primal / direct / adjoint, side by side in one run)
of the shipped case without and with projection.
"""
from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

import dynsens

CASE = Path(__file__).resolve().parent.parent / "cases" / "pendulum_projection.yaml"
G, L = 9.81, 1.0
POSITION = "responses=[{name: x_end, type: value, quantity: {body: bob, kind: position}, component: bob.x}]"
VARIANTS = [("none", ["model.projection.enabled=false"])] + [
    (f"Baumgarte α = β = {a:g}", ["model.projection.enabled=false", f"model.stabilization={{alpha: {a}, beta: {a}}}"])
    for a in (1.0, 10.0, 100.0, 1000.0, 10000.0)] + [
    ("projection, mode output", ["model.projection.mode=output"]),
    ("projection, mode state", ["model.projection.mode=state"])]


def reference(t: np.ndarray) -> np.ndarray:
    """(x, y) of the bob at the times t from θ̈ = −(g/L) sin θ, θ(0) = π/2 (from the vertical)."""
    sol = solve_ivp(lambda _, y: [y[1], -G / L * np.sin(y[0])], (0.0, t[-1]), [np.pi / 2, 0.0],
                    method="DOP853", rtol=1e-13, atol=1e-14, t_eval=t)
    return np.stack([L * np.sin(sol.y[0]), -L * np.cos(sol.y[0])], axis=1)


def accuracy(dts: list[float], t_end: float) -> None:
    print(f"| Δt (s) | stabilization | max ‖Φ‖ (m) | max position error (m), 0–{t_end:g} s |")
    print("|---|---|---|---|")
    for dt in dts:
        for label, sets in VARIANTS:
            case = dynsens.load_case(CASE, [f"integrator.dt={dt}", f"integrator.t_end={t_end}", POSITION, *sets])
            try:
                res = dynsens.run_case(case, sensitivities=False, history=("q",))
            except Exception as exc:            # a setting that fails is a result of the study
                print(f"| {dt:g} | {label} | failed: {type(exc).__name__} | |")
                continue
            err = np.linalg.norm(res.history["q"][:, :2] - reference(res.time), axis=1)
            print(f"| {dt:g} | {label} | {res.monitors['constraint_position'].max():.2e} | {err.max():.2e} |")


def timing(repeats: int) -> None:
    print("\n| run (cases/pendulum_projection.yaml, 2000 steps) | without projection (s) | with projection (s) |")
    print("|---|---|---|")
    for what in ("primal", "direct", "adjoint"):
        walls: dict[bool, list[float]] = {False: [], True: []}
        for _ in range(repeats):
            for on in (False, True):            # side by side
                case = dynsens.load_case(CASE, [f"model.projection.enabled={'true' if on else 'false'}",
                                               f"sensitivity.method={'direct' if what == 'primal' else what}"])
                t0 = time.perf_counter()
                dynsens.run_case(case, sensitivities=what != "primal")
                walls[on].append(time.perf_counter() - t0)
        print(f"| {what} | {statistics.median(walls[False]):.2f} | {statistics.median(walls[True]):.2f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dt", default="0.005,0.002", help="step sizes, comma-separated (s)")
    ap.add_argument("--t-end", type=float, default=10.0, help="horizon (s)")
    ap.add_argument("--timing", type=int, default=0, help="repeats of the timing table (0: none)")
    args = ap.parse_args()
    accuracy([float(v) for v in args.dt.split(",")], args.t_end)
    if args.timing:
        timing(args.timing)


if __name__ == "__main__":
    main()
