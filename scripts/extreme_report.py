"""Table of the stiff and extreme structural checks (the figures tests/test_stiff_extreme.py asserts).

Usage: python scripts/extreme_report.py   (prints a markdown table)
"""
from __future__ import annotations

import numpy as np

import dynsens
from extreme_cases import exact_two_dof, hard_step_case, sdof_in_units, two_dof


def stiff_rows() -> list[str]:
    rows = ["| stiffness ratio | Δt·ω_max | Δt·ω_slow | scheme | max \\|q\\| | slow-mode error "
            "| stiff-mode amplitude at end | Newton it./step |",
            "|---|---|---|---|---|---|---|---|"]
    for ratio, omega_dt in ((1e6, 1e2), (1e8, 1e3), (1e8, 1e4)):
        dt = omega_dt / np.sqrt(2 * ratio)
        for name, kw in (("newmark", {}), ("hht", {"alpha": 1 / 3}), ("generalized_alpha", {"rho_inf": 0.0})):
            r = dynsens.run_case(two_dof(ratio, dt, 18.0, (name, kw)), sensitivities=False)
            q = r.history["q"]
            ex = exact_two_dof(ratio, r.time)
            slow_err = np.max(np.abs(0.5 * (q[:, 0] + q[:, 1]) - 0.5 * (ex[0] + ex[1])))
            stiff = np.max(np.abs((q[:, 1] - q[:, 0])[-20:]))
            label = name + "".join(f" ({k} = {v:.3g})" for k, v in kw.items())
            rows.append(f"| {ratio:.0e} | {omega_dt:.0e} | {dt * np.sqrt(0.5):.2g} | {label} | "
                        f"{np.max(np.abs(q)):.4f} | {slow_err:.1e} | {stiff:.1e} | "
                        f"{r.counters['newton_iterations'] / r.counters['steps']:.2f} |")
    return rows


def units_rows() -> list[str]:
    base = dynsens.run_case(sdof_in_units(1.0, 1.0, 1.0))
    rows = ["| length × | mass × | time × | value error (scaled) | gradient error (scaled) | Newton iterations |",
            "|---|---|---|---|---|---|",
            f"| 1 | 1 | 1 | – | – | {base.counters['newton_iterations']} |"]
    for L, M, T in ((1e3, 1e-3, 1.0), (1e-6, 1e9, 1.0), (1.0, 1e-6, 1e-3), (1e9, 1e6, 1e3)):
        r = dynsens.run_case(sdof_in_units(L, M, T))
        v = abs(r.responses["q_ks"].value / L - base.responses["q_ks"].value) / abs(base.responses["q_ks"].value)
        g = r.responses["q_ks"].gradient * (M / T ** 2) / L
        ge = np.linalg.norm(g - base.responses["q_ks"].gradient) / np.linalg.norm(base.responses["q_ks"].gradient)
        rows.append(f"| {L:g} | {M:g} | {T:g} | {v:.1e} | {ge:.1e} | {r.counters['newton_iterations']} |")
    return rows


def main() -> None:
    print("Stiff two-DOF system (18 s = two slow periods):\n")
    print("\n".join(stiff_rows()))
    print("\nThe same Duffing oscillator in other units (KS response and its gradient, complex-step partials):\n")
    print("\n".join(units_rows()))
    r = dynsens.run_case(hard_step_case(8))
    print(f"\nHardening spring under a 1e5 N step load with 4 Newton iterations allowed: "
          f"{r.counters['step_cuts']} step cuts, status {r.status}.")


if __name__ == "__main__":
    main()
