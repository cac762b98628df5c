"""Euclidean against mass-weighted projection (``model.projection.metric``) on the light cart
pole: cases/cart_pole.yaml with a 1e-6 kg cart and no spring (k = 0), so that the horizontal
momentum P = M ẋ_cart + m ẋ_pole is a constant of the motion, over 10 s with adaptive steps.

For each metric and rtol: the largest drift of P over the run (kg m/s; P(0) = 0.1 (M + m)), the
accepted steps, and the error of the pole angle θ(10) against the same system in minimal
coordinates (scripts/adaptive_report.py) integrated by DOP853 at rtol 1e-12.  Writes a Markdown
table:

    python scripts/projection_metric_report.py -o results/projection_metric
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

import dynsens
from adaptive_report import CASE, START, rhs

CART_MASS = 1e-6      # kg
POLE_MASS = 0.05      # kg
T_END = 10.0          # s
LIGHT = ["design.variables[2].lower=1e-7", f"design.variables[2].value={CART_MASS}",
         "design.variables[3].lower=0.0", "design.variables[3].value=0.0", f"integrator.t_end={T_END}"]


def overrides(metric: str, rtol: float) -> list[str]:
    """Case overrides of the light cart pole with the given projection metric and rtol."""
    return [*LIGHT, f"model.projection.metric={metric}", f"integrator.adaptive.rtol={rtol}",
            f"integrator.adaptive.atol={rtol * 1e-3}"]


def reference_theta(t_end: float = T_END) -> float:
    """θ(t_end) (rad, from hanging down) of the light cart pole in minimal coordinates."""
    sol = solve_ivp(lambda t, y: rhs(t, y, m=POLE_MASS, M=CART_MASS, k=0.0), (0.0, t_end), START,
                    method="DOP853", rtol=1e-12, atol=1e-13)
    return float(sol.y[1, -1])


def theta(q: np.ndarray) -> np.ndarray:
    """Pole angle θ (rad) from hanging down, unwrapped, from the pole's Euler parameters (rows of q)."""
    return np.unwrap(2.0 * np.arctan2(q[:, 13], q[:, 10]))


def measure(res: Any, th_ref: float) -> dict[str, float]:
    """Momentum drift (kg m/s), accepted steps and |θ(10) − θ_ref| (rad) of a run."""
    q, qd = np.real(res.history["q"]), np.real(res.history["qd"])
    P = CART_MASS * qd[:, 0] + POLE_MASS * qd[:, 7]
    th = theta(q)
    th_end = th[-1] + 2 * np.pi * np.round((th_ref - th[-1]) / (2 * np.pi))
    return {"drift": float(np.max(np.abs(P - P[0]))), "steps": float(len(res.time) - 1),
            "theta_error": float(abs(th_end - th_ref))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", default="results/projection_metric")
    ap.add_argument("--rtol", type=float, nargs="+", default=[1e-7, 1e-8, 1e-9])
    args = ap.parse_args()
    th_ref = reference_theta()
    rows = ["| metric | rtol | accepted steps | max momentum drift (kg m/s) | θ(10) error (rad) | wall (s) |",
            "|---|---|---|---|---|---|"]
    for metric in ("euclidean", "mass"):
        for rtol in args.rtol:
            t0 = time.perf_counter()
            res = dynsens.run_case(dynsens.load_case(CASE, overrides(metric, rtol)), sensitivities=False)
            wall = time.perf_counter() - t0
            if res.status != "completed":
                rows.append(f"| {metric} | {rtol:g} | {res.status}: {res.message} | | | {wall:.1f} |")
                continue
            m = measure(res, th_ref)
            rows.append(f"| {metric} | {rtol:g} | {int(m['steps'])} | {m['drift']:.2e} | "
                        f"{m['theta_error']:.2e} | {wall:.1f} |")
            print(rows[-1], flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tmp = out / "table.md.tmp"
    tmp.write_text("\n".join(rows) + "\n")
    tmp.replace(out / "table.md")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
