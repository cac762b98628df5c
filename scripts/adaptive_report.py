"""Work-precision of adaptive against fixed steps on the light pendulum on a cart
(cases/cart_pole.yaml): error against an independent reference versus run time.

The reference is the same system in minimal coordinates (cart position x, pole angle θ from
hanging down), integrated by scipy's DOP853 at rtol 1e-12 (tests/test_cart_pole.py checks it
against Radau):

    (M + m) ẍ + m a (θ̈ cos θ − θ̇² sin θ) + k x = 0
    m a ẍ cos θ + (I_c + m a²) θ̈ + m g a sin θ = 0,      a = l/2, I_c = m l²/12

Each setting is run ``--repeats`` times side by side (primal runs, no sensitivities); the wall
time is the median.  Writes a Markdown table and a plot:

    python scripts/adaptive_report.py -o results/convergence
"""
from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

import dynsens

CASE = Path(__file__).resolve().parent.parent / "cases" / "cart_pole.yaml"
G = 9.81
START = (0.0, 3.0, 0.1, 0.0)          # x (m), θ (rad), ẋ (m/s), θ̇ (rad/s) of the case at t = 0


def rhs(t: float, y: np.ndarray, m: float = 0.05, l: float = 0.5, M: float = 1.0, k: float = 1.0) -> list[float]:
    """Minimal-coordinate equations of motion of the cart pole, y = (x, θ, ẋ, θ̇)."""
    x, th, v, w = y
    a, ic = l / 2, m * l * l / 12
    A = np.array([[M + m, m * a * np.cos(th)], [m * a * np.cos(th), ic + m * a * a]])
    b = np.array([m * a * np.sin(th) * w * w - k * x, -m * G * a * np.sin(th)])
    return [v, w, *np.linalg.solve(A, b)]


def reference(t_end: float = 5.0, method: str = "DOP853", rtol: float = 1e-12) -> Any:
    """Dense solution (callable of t) of the minimal-coordinate equations."""
    return solve_ivp(rhs, (0.0, t_end), START, method=method, rtol=rtol, atol=rtol * 0.1, dense_output=True).sol


def errors(res: Any, sol: Any) -> tuple[float, float]:
    """Largest errors of the cart position (m) and the pole's angular velocity (rad/s) over a run."""
    y = sol(res.time)
    return (float(np.max(np.abs(res.quantities["cart_x"].value - y[0]))),
            float(np.max(np.abs(res.quantities["pole_rate"].value - y[3]))))


# the case continues from the projected state (mode state); the plain index-1 form for comparison
PROJECTION = {"": ["model.projection.enabled=false"], " + projection (output)": ["model.projection.mode=output"],
              " + projection (state)": ["model.projection.mode=state"]}
SETTINGS = [(f"adaptive{p}", f"rtol = {r:g}",
             [f"integrator.adaptive.rtol={r}", f"integrator.adaptive.atol={r * 1e-3}", *ov])
            for p, ov in PROJECTION.items() for r in (1e-6, 1e-7, 1e-8)] + \
           [(f"fixed{p}", f"dt = {dt:g} s", ["integrator.adaptive=null", f"integrator.dt={dt}", *ov])
            for p, ov in PROJECTION.items() for dt in (4e-3, 2e-3, 1e-3, 5e-4)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", default="results/convergence")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sol = reference()
    cases = [(kind, label, dynsens.load_case(CASE, ov)) for kind, label, ov in SETTINGS]
    walls: list[list[float]] = [[] for _ in cases]
    runs: list[Any] = [None] * len(cases)
    for _ in range(args.repeats):                      # side by side: one of each per round
        for k, (_, _, case) in enumerate(cases):
            t0 = time.perf_counter()
            try:
                runs[k] = dynsens.run_case(case, sensitivities=False)
            except dynsens.DynsensError as exc:
                runs[k] = exc
            walls[k].append(time.perf_counter() - t0)
    rows = ["| steps | setting | accepted steps | rejected | wall time [s] (median) | max error x [m] | "
            "max error θ̇ [rad/s] | max ‖Φ‖ reported | max ‖Φ‖ integrated |", "|---|---|---|---|---|---|---|---|---|"]
    points: dict[str, list[tuple[float, float]]] = {kind: [] for kind, _, _ in SETTINGS}
    for (kind, label, _), res, w in zip(cases, runs, walls):
        wall = statistics.median(w)
        if isinstance(res, Exception):
            rows.append(f"| {kind} | {label} | – | – | {wall:.2f} | failed: {str(res)[:80]} | | | |")
            continue
        ex, ew = errors(res, sol)
        # the projected (reported) state and the state the integration continues from
        drift = float(np.max(res.monitors.get("constraint_position", np.zeros(1))))
        solved = float(np.max(res.monitors.get("constraint_position_solved", res.monitors["constraint_position"])))
        rows.append(f"| {kind} | {label} | {len(res.time) - 1} | {res.counters.get('rejected_steps', '–')} | "
                    f"{wall:.2f} | {ex:.2e} | {ew:.2e} | {drift:.1e} | {solved:.1e} |")
        points[kind].append((wall, ex))
    text = "\n".join([f"# Work-precision: adaptive and fixed steps on `cart_pole` (t_end = 5 s, "
                      f"{args.repeats} runs each, side by side, medians)", "", *rows, ""])
    (out / "cart_pole_adaptive.md").write_text(text)
    print(text)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(5.5, 4))
    for kind, pts in points.items():
        if pts:
            ax.loglog(*zip(*pts), "o-" if kind.startswith("adaptive") else "s--", label=kind)
    ax.set_xlabel("wall time [s]")
    ax.set_ylabel("max error of the cart position [m]")
    ax.set_title("cart_pole: error vs run time")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "cart_pole_adaptive_work_precision.png", dpi=120)
    print(f"written: {out / 'cart_pole_adaptive.md'}, {out / 'cart_pole_adaptive_work_precision.png'}")


if __name__ == "__main__":
    main()
